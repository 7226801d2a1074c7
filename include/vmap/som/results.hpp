#pragma once

// What GCS training and localization return (som/gcs.hpp, som/pose_map.hpp), in a header
// of their own: a program that reads them (a memory's answers, memory/types.hpp) need not
// compile the network.

#include <vmap/geometry/pose2.hpp>

#include <cstddef>
#include <vector>

namespace vmap {

/// What train() did: its passes and steps, the cells it inserted and removed, the
/// cells it ended with, and how well they quantize the data.
struct GcsTrainStats {
  std::size_t epochs = 0;
  std::size_t steps = 0;
  std::size_t insertions = 0;
  std::size_t removals = 0;
  std::size_t cells = 0;
  double mean_quantization_error = 0.0;  ///< mean distance of the data to their best matching cell
};

/// One query image's best matching neuron.
struct QueryMatch {
  std::size_t neuron = 0;    ///< the neuron whose pose is used
  double distance = 0.0;     ///< its distance to the query vector
  bool substituted = false;  ///< the winner had no pose: this is the nearest neuron that has one
  Pose2 pose;                ///< that neuron's mean pose
};

/// The estimate: the mean of the query images' neuron poses (Algorithm 5), with the
/// neurons and distances so a user can judge it.
struct Localization {
  Pose2 pose;
  std::vector<QueryMatch> matches;
};

}  // namespace vmap
