#pragma once

// Label sources for LFM-LCD (Zhu et al., Sensors 2021, sec. 3.2; examples/methods.md, sec. 2):
// the union of several detectors' detections, and what a set of label vectors can give
// the binary classified tree on a sequence with known loops.
//
// Union: eq. 3 asks only whether label l_i is present in a frame. Detectors that share
// one label space (COCO-80 for YOLOX, NanoDet and FastestDet) can be pooled: a label is
// present when any of them found it with a score >= the threshold. A label vector of the
// union has at least the ones of each detector's vector.
//
// Agreement: the tree proposes, for a query, the older frames with the same vector (its
// leaf), and more only when the leaf holds fewer than m frames (sec. 3.3). Hence, for
// every m, the verifications are at least the leaf sizes summed over the queries, and
// with m = 0 a revisit can only be found when a true loop frame has the query's vector.
// `label_vector_agreement` counts both against ground truth: it bounds what any tree
// parameter can achieve with these labels, before a single frame is matched.

#include <vmap/core/error.hpp>
#include <vmap/hooks/detection.hpp>
#include <vmap/hooks/precomputed_detections.hpp>
#include <vmap/lcd/evaluation.hpp>
#include <vmap/lcd/label_vector.hpp>

#include <algorithm>
#include <cstddef>
#include <limits>
#include <set>
#include <string>
#include <vector>

namespace vmap {

/// The union of several detectors' detections of one sequence: frame k holds the
/// detections of every source for frame k (source order, then each source's order).
/// The sources must use the same label ids. Sources that declare their length must
/// agree on it, and no source may list a frame beyond it; the result declares the
/// sequence's length (the declared one, else one past the last frame listed).
[[nodiscard]] inline PrecomputedDetections merge_detections(const std::vector<PrecomputedDetections>& sources) {
  std::size_t frames = 0;
  bool declared = false;
  for (std::size_t s = 0; s < sources.size(); ++s) {
    if (!sources[s].frames_declared()) continue;
    if (declared && sources[s].frames() != frames)
      detail::fail("merge_detections: source " + std::to_string(s) + " covers " + std::to_string(sources[s].frames()) +
                   " frames, an earlier one " + std::to_string(frames) + " (not the same sequence?)");
    frames = sources[s].frames();
    declared = true;
  }
  for (std::size_t s = 0; s < sources.size(); ++s) {
    if (sources[s].frames_declared()) continue;
    if (declared && sources[s].frames() > frames)
      detail::fail("merge_detections: source " + std::to_string(s) + " lists frame " +
                   std::to_string(sources[s].frames() - 1) + ", but the sequence has " + std::to_string(frames) +
                   " frames");
    frames = std::max(frames, sources[s].frames());
  }
  std::vector<std::vector<Detection>> per_frame(frames);
  for (const PrecomputedDetections& source : sources)
    for (std::size_t k = 0; k < source.frames(); ++k) {
      const std::vector<Detection> d = source.at(k);
      per_frame[k].insert(per_frame[k].end(), d.begin(), d.end());
    }
  return PrecomputedDetections(per_frame);
}

/// What a sequence's label vectors allow the tree, against ground truth (see the top
/// of this file). Pairs are (query q, older frame j) with j + window < q, as the
/// LoopDetector sees them.
struct LabelVectorAgreement {
  std::size_t distinct_vectors = 0;    ///< distinct label vectors among the frames
  std::size_t pairs = 0;               ///< all pairs: the verifications of brute force
  std::size_t leaf_pairs = 0;          ///< pairs with equal vectors: a lower bound on the tree's verifications
  std::size_t loop_queries = 0;        ///< queries with a ground-truth loop among their pairs
  std::size_t reachable_queries = 0;   ///< of those, queries with a true loop frame of the same vector
  std::size_t loop_pairs = 0;          ///< ground-truth loop pairs
  std::size_t agreeing_loop_pairs = 0; ///< of those, pairs whose two frames have the same vector

  /// Brute force's verifications over the least the tree can spend (infinite when no
  /// pair has equal vectors).
  [[nodiscard]] double max_reduction() const noexcept {
    return leaf_pairs == 0 ? std::numeric_limits<double>::infinity()
                           : static_cast<double>(pairs) / static_cast<double>(leaf_pairs);
  }
};

/// Counts `LabelVectorAgreement` for the vectors of frames 0..n-1 (`vectors[k]` is
/// frame k's). The vectors must have one length and the ground truth n frames.
[[nodiscard]] inline LabelVectorAgreement label_vector_agreement(const std::vector<LabelVector>& vectors,
                                                                 const LoopGroundTruth& gt, std::size_t window) {
  detail::check(gt.frames() == vectors.size(), [&] {
    return "label_vector_agreement: the ground truth covers " + std::to_string(gt.frames()) + " frames, the vectors " +
           std::to_string(vectors.size());
  });
  for (std::size_t k = 0; k < vectors.size(); ++k)
    detail::check(vectors[k].size() == vectors.front().size(), [&] {
      return "label_vector_agreement: vector " + std::to_string(k) + " has length " +
             std::to_string(vectors[k].size()) + ", the first has " + std::to_string(vectors.front().size());
    });
  LabelVectorAgreement a;
  // Keyed by the bytes as a string: GCC 12 at -O3 warns falsely (stringop-overread)
  // inside std::vector's <=> that a std::map<LabelVector, ...> would use.
  std::set<std::string> distinct;
  for (const LabelVector& v : vectors) distinct.emplace(v.begin(), v.end());
  a.distinct_vectors = distinct.size();
  for (std::size_t q = 0; q < vectors.size(); ++q) {
    bool loop = false, reachable = false;
    for (std::size_t j = 0; j + window < q; ++j) {
      const bool same = vectors[j] == vectors[q];
      ++a.pairs;
      a.leaf_pairs += same ? 1 : 0;
      if (!gt(q, j)) continue;
      loop = true;
      ++a.loop_pairs;
      if (same) {
        reachable = true;
        ++a.agreeing_loop_pairs;
      }
    }
    a.loop_queries += loop ? 1 : 0;
    a.reachable_queries += reachable ? 1 : 0;
  }
  return a;
}

}  // namespace vmap
