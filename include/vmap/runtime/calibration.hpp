#pragma once

// The chance rate of a policy stack measured on places the user holds
// (lcd/calibration.hpp explains the rate): the features of each place extracted by the
// stack's descriptor (runtime/loops.hpp, extract_features), seeded pairs of images of
// two different places verified with the stack's matcher and estimator. `vmap
// calibrate` prints it; a memory made with it keeps it.
//
//   std::vector<vmap::SequenceFeatures> places;
//   for (const auto& folder : {"corridor/", "office/"}) places.push_back(vmap::extract_features(folder, stack));
//   const vmap::ChanceCalibration c = vmap::calibrate_chance_rate(stack, std::move(places));
//   options.loops.decision.chance_inlier_rate = c.rate;

#include <vmap/lcd/calibration.hpp>
#include <vmap/runtime/loops.hpp>
#include <vmap/runtime/policies.hpp>

#include <string>
#include <utility>
#include <vector>

namespace vmap {

/// The chance rate of `stack` from pairs of `places` (at least two, each with an image;
/// their features by the stack's descriptor). The estimator is the one a memory of the
/// stack verifies with (StackUse::memory); `camera_name` names its camera in errors.
[[nodiscard]] inline ChanceCalibration calibrate_chance_rate(const PolicyStack& stack, std::vector<SequenceFeatures> places,
                                                             const ChancePairs& draw = {},
                                                             const ChanceCalibrationOptions& options = {},
                                                             const std::string& camera_name = "camera") {
  std::vector<std::vector<Features>> features;
  features.reserve(places.size());
  for (SequenceFeatures& p : places) features.push_back(std::move(p.frames));
  // The descriptor with_policies builds is not used: the places hold its features.
  return with_policies(
      stack, StackUse::memory,
      [&](auto, auto matcher, auto estimator) {
        return vmap::calibrate_chance_rate(matcher, estimator, features, draw, options);
      },
      camera_name);
}

}  // namespace vmap
