#pragma once

// Options shared by `vmap build` and `vmap sweep`: the policy stack (common/policies.hpp),
// the key-image rule and the frame range.

#include "common/bag_options.hpp"
#include "common/cli_support.hpp"
#include "common/policies.hpp"

#include <vmap/core/names.hpp>
#include <vmap/io/frame_source.hpp>
#include <vmap/keyframe/selector.hpp>
#include <vmap/runtime/frame_range.hpp>
#include <vmap/runtime/option_names.hpp>
#include <vmap/runtime/stack.hpp>

#include <CLI/CLI.hpp>

#include <unistd.h>

#include <cstddef>
#include <cstdio>
#include <optional>
#include <string>

namespace vmap::examples {

/// What both subcommands read from the command line.
struct KeyframeArgs {
  std::string input;
  std::string features = "orb";
  std::string model;
  std::string refine_model;
  int nfeatures = 1000;
  std::string estimator = "magsac";
  std::string rule = "previous";
  std::size_t start = 0;
  std::size_t end = 0;  // 0: to the end
  std::size_t stride = 1;
  std::string camera;  // calibration file; empty: raw pixels
  double time_offset = 0.0;
  std::string out;
  bool json = false;

  [[nodiscard]] DescriptorChoice descriptor() const { return {features, nfeatures, model, refine_model}; }
  /// The policy stack of the options, with the calibration --camera read.
  [[nodiscard]] PolicyStack stack(const std::optional<CameraOption>& calibration) const {
    return stack_of(descriptor(), estimator, calibration);
  }
};

/// --features/--model/--nfeatures, shared by every subcommand that extracts features.
inline void add_feature_options(CLI::App& app, std::string& features, std::string& model, int& nfeatures,
                                std::string& refine_model) {
  app.add_option("--features", features,
                 "Descriptor: orb, akaze, sift, xfeat, xfeat-dense or xfeat-star (the last three need --model; "
                 "xfeat-star also --refine-model)");
  app.add_option("--model", model, "Model file of a learned descriptor (xfeat, xfeat-dense, xfeat-star)");
  app.add_option("--refine-model", refine_model,
                 "xfeat-star: XFeat*'s refinement network (xfeat_fine.onnx), run once per matched pair");
  app.add_option("--nfeatures", nfeatures,
                 "Keypoint budget per image (ORB, SIFT; top-k for XFeat), at most " + std::to_string(max_nfeatures))
      ->check(count_in(1, max_nfeatures));
}

inline void add_keyframe_options(CLI::App& app, KeyframeArgs& a) {
  app.add_option("input", a.input, "Video file, image folder, list of image paths, TUM rgb.txt, or a bag")->required();
  add_bag_options(app);
  add_feature_options(app, a.features, a.model, a.nfeatures, a.refine_model);
  app.add_option("--estimator", a.estimator, "F-matrix estimation: magsac, ransac, lmeds or 8point");
  app.add_option("--rule", a.rule, "New key image: previous (eq. 6) or current (Algorithm 1) frame");
  app.add_option("--start", a.start, "First frame index to read")->check(count_in(0, max_frame_index));
  app.add_option("--end", a.end, "One past the last frame index to read (0: to the end)")
      ->check(count_in(0, max_frame_index));
  app.add_option("--stride", a.stride, "Read every stride-th frame")->check(count_in(1, max_frame_index));
  app.add_option("--camera", a.camera,
                 "Calibration (ORB-SLAM YAML, ROS camera_info, Kalibr camchain, EuRoC sensor.yaml, KITTI calib.txt): "
                 "undistort keypoints before the F-matrix");
  add_time_offset_option(app, a.time_offset);
  app.add_flag("--json", a.json, "Print one JSON object on stdout (the table goes to stderr)");
}

/// --rule: previous (eq. 6) or current (Algorithm 1).
inline KeyRule parse_rule(const std::string& name) {
  return as_usage([&] { return parse_option<KeyRule>(name, "rule", "rule", OptionNames::command_line()); });
}

/// --start, --end (0: to the end) and --stride.
inline FrameRange frame_range(const KeyframeArgs& a) {
  return {a.start, a.end > 0 ? std::optional<std::size_t>(a.end) : std::nullopt, a.stride};
}

/// Frame range and decoding; each skipped frame is reported on stderr (the count is in
/// the summary and the JSON, from FrameSource::skipped()).
inline FrameSourceOptions source_options(const KeyframeArgs& a, bool grey) {
  FrameSourceOptions o;
  o.grey = grey;
  o.time_offset = a.time_offset;
  return reporting_skips(as_usage([&] { return frame_range(a).apply(o, OptionNames::command_line()); }));
}

/// --end before --start is a usage error, found before any frame is read.
inline void check_range(const KeyframeArgs& a) {
  as_usage([&] { frame_range(a).validate(OptionNames::command_line()); });
}

}  // namespace vmap::examples
