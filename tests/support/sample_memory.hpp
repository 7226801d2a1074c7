#pragma once

// What the visual memory's tests share: the 60 sample frames (grey), the estimator they
// run with, small options under which so short a sequence learns a vocabulary and finds
// loops, a memory of that stack (new or from a store), and the comparison of two such
// memories.

#include "support/shared_data.hpp"

#include <vmap/io/frame_source.hpp>
#include <vmap/memory/stacks.hpp>
#include <vmap/memory/store.hpp>
#include <vmap/memory/visual_memory.hpp>

#include <doctest/doctest.h>

#include <opencv2/core.hpp>

#include <cstddef>
#include <cstdint>
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
  static const std::vector<Frame> frames = read_grey_frames(sample_list());
  return frames;
}

/// The images of the first `n` sample frames (grey).
inline std::vector<cv::Mat> sample_images(std::size_t n) {
  const auto& frames = sample_frames();
  REQUIRE(n <= frames.size());
  std::vector<cv::Mat> out;
  for (std::size_t i = 0; i < n; ++i) out.push_back(frames[i].image);
  return out;
}

/// The benchmark stack's estimator (degeneracy check off, as the selector tests run it);
/// `seed` as FundamentalOptions::seed.
inline FundamentalEstimator memory_estimator(std::uint64_t seed = 0) {
  return FundamentalEstimator({.check_degeneracy = false, .seed = seed});
}

/// tau 0.3, a vocabulary of 8^2 words learned after 3 key images, a loop window of 2 and
/// an inlier floor of 30: the sample frames learn a vocabulary and find loops.
inline MemoryOptions small_memory_options(ImageStorage images = ImageStorage::none) {
  MemoryOptions o;
  o.selector.tau = 0.3;
  o.images = images;
  o.vocabulary_after = 3;
  o.vocabulary = {.branching = 8, .depth = 2, .seed = 5};
  o.loops.window = 2;
  // The camera swings back and forth within a few key images: a candidate counts as left
  // when any key image between saw it less than the query does.
  o.loops.left_ratio = 1.0;
  o.loops.decision.min_inliers = 30;
  return o;
}

inline OrbVisualMemory make_small_memory(const MemoryOptions& o) {
  return OrbVisualMemory(OrbDescriptor{}, BruteForceMatcher{}, memory_estimator(), InlierRatio{}, o);
}

/// The memory of that stack in `store`.
inline OrbVisualMemory load_small_memory(MemoryStore& store) {
  return store.load<OrbVisualMemory>(OrbDescriptor{}, BruteForceMatcher{}, memory_estimator(), InlierRatio{});
}

/// Two memories hold the same frames, key images, links, loops, place database and
/// labels (what a save and load, or a resumed run, must keep).
inline void check_same_memory(const OrbVisualMemory& a, const OrbVisualMemory& b) {
  CHECK(a.frames() == b.frames());
  CHECK(a.last_frame_index() == b.last_frame_index());
  CHECK(a.map().key_indices() == b.map().key_indices());
  REQUIRE(a.map().pairs.size() == b.map().pairs.size());
  for (std::size_t i = 0; i < a.map().pairs.size(); ++i) {
    CHECK(a.map().pairs[i].inliers == b.map().pairs[i].inliers);
    CHECK(a.map().pairs[i].similarity == b.map().pairs[i].similarity);
  }
  REQUIRE(a.loops().size() == b.loops().size());
  for (std::size_t i = 0; i < a.loops().size(); ++i) {
    CHECK(a.loops()[i].from == b.loops()[i].from);
    CHECK(a.loops()[i].link.key == b.loops()[i].link.key);
    CHECK(a.loops()[i].link.inliers == b.loops()[i].link.inliers);
    CHECK(a.loops()[i].link.bow_score == b.loops()[i].link.bow_score);
  }
  CHECK(a.database().ids() == b.database().ids());
  CHECK(a.labelled() == b.labelled());
  REQUIRE(a.label_schema().has_value() == b.label_schema().has_value());
  if (a.label_schema()) CHECK(a.label_schema()->labels() == b.label_schema()->labels());
  CHECK(a.label_tree().size() == b.label_tree().size());
  REQUIRE(a.key_detections().size() == b.key_detections().size());
  for (std::size_t k = 0; k < a.key_detections().size(); ++k) {
    REQUIRE(a.key_detections()[k].size() == b.key_detections()[k].size());
    for (std::size_t j = 0; j < a.key_detections()[k].size(); ++j) {
      CHECK(a.key_detections()[k][j].label == b.key_detections()[k][j].label);
      CHECK(a.key_detections()[k][j].score == b.key_detections()[k][j].score);
    }
  }
}

}  // namespace vmap::test
