#pragma once

// What the visual memory's tests share: the 60 sample frames (grey), the estimator they
// run with, small options under which so short a sequence learns a vocabulary and finds
// loops, and a memory of that stack.

#include "support/shared_data.hpp"

#include <vmap/io/frame_source.hpp>
#include <vmap/memory/visual_memory.hpp>

#include <filesystem>
#include <vector>

namespace vmap::test {

inline std::vector<Frame> read_grey_frames(const std::filesystem::path& input, FrameSourceOptions o = {}) {
  o.grey = true;
  auto src = FrameSource::open(input, o);
  std::vector<Frame> out;
  while (auto f = src.next()) out.push_back(std::move(*f));
  return out;
}

/// The repository's 60 sample frames (examples/data/tum_fr1_rpy_60), read once.
inline const std::vector<Frame>& sample_frames() {
  static const std::vector<Frame> frames = read_grey_frames(source_dir() / "examples/data/tum_fr1_rpy_60/rgb.txt");
  return frames;
}

/// The benchmark stack's estimator (degeneracy check off, as the selector tests run it).
inline FundamentalEstimator memory_estimator() { return FundamentalEstimator({.check_degeneracy = false}); }

/// tau 0.3, a vocabulary of 8^2 words learned after 3 key images, a loop window of 2 and
/// an inlier floor of 30: the sample frames learn a vocabulary and find loops.
inline MemoryOptions small_memory_options(ImageStorage images = ImageStorage::none) {
  MemoryOptions o;
  o.selector.tau = 0.3;
  o.images = images;
  o.vocabulary_after = 3;
  o.vocabulary = {.branching = 8, .depth = 2, .seed = 5};
  o.loops.window = 2;
  o.loops.decision.min_inliers = 30;
  return o;
}

inline OrbVisualMemory make_small_memory(const MemoryOptions& o) {
  return OrbVisualMemory(OrbDescriptor{}, BruteForceMatcher{}, memory_estimator(), InlierRatio{}, o);
}

}  // namespace vmap::test
