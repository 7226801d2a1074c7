#pragma once

// The loop engine's options and those it holds (labels, influence, candidate source, the
// place decision), alone: a program that only configures loop detection (or a memory,
// memory/options.hpp) includes this instead of lcd/loop_engine.hpp.

#include <vmap/core/name_table.hpp>

#include <cstddef>
#include <cstdint>
#include <string_view>

namespace vmap {

/// Which detections count (eq. 3: "keep labels with score >= 0.5").
struct LabelVectorOptions {
  float min_score = 0.5f;  ///< detections below this score are ignored, in [0, 1]
};

/// The band of eq. 5 influence a label must fall in to become a tree level.
struct InfluenceOptions {
  /// Labels present in fewer than this share of the sample are dropped. 0.05: a label
  /// must be seen in at least one frame in twenty, so one-off (often false) detections
  /// never shape the tree.
  double min_influence = 0.05;
  /// Labels present in more than this share are dropped. 0.95: a label in (nearly)
  /// every frame puts every frame on the same side, so its level is wasted depth.
  double max_influence = 0.95;
};

/// When the place decision (lcd/place_decision.hpp) accepts a place.
struct PlaceDecisionOptions {
  /// A place is accepted at this confidence or above (0.5: a significance of
  /// half_significance with the inliers spread over the image). Chosen from the evidence
  /// of true and false candidates on every shared sequence (examples/loops.md, "The
  /// place decision"; the figures in examples/results/loops.md).
  double min_confidence = 0.5;
  /// Below this many inliers a model is not weighed at all (too little evidence).
  int min_inliers = 12;
  /// The probability that one tentative match fits the model by chance. 0.1: the rate
  /// at which mutual ORB matches of unrelated image pairs fit a fundamental matrix at
  /// 1 px beyond the minimal sample (examples/results/loops.md, "How the decision's
  /// defaults were chosen").
  double chance_inlier_rate = 0.1;
  /// The significance at which the confidence is 0.5: a chance alignment of 1 in 10^12,
  /// above the strongest unrelated pair of the shared sequences (the same page).
  double half_significance = 12.0;
  /// Grid (cells per side) for the spread of the inliers.
  int spread_grid = 4;
  /// A spread at or above this fraction of cells leaves the confidence as it is; below,
  /// the confidence is scaled down in proportion (inliers bunched in one patch). 0.35:
  /// the only false loop above the confidence threshold on the shared sequences (its
  /// inliers on a quarter of the cells, on tum_fr3_cabinet_kf) falls below it while
  /// rtabmap_loop keeps its recall at precision 1.0 (the same page).
  double full_spread = 0.35;
  /// Two places are ambiguous when the second's confidence is at least this fraction of
  /// the best's and both reach min_confidence.
  double ambiguity_ratio = 0.9;
};

/// Where loop candidates come from (lcd/loop_engine.hpp says how each is searched).
enum class CandidateIndex : std::uint8_t {
  tree,         ///< every frame of the leaf after backtracking (LFM-LCD)
  tree_ranked,  ///< the leaf's frames ranked by bag-of-words score, top k verified
  bow,          ///< every indexed frame ranked by bag-of-words score, top k verified
  brute_force,  ///< every frame older than the window
};

/// tree, tree_ranked, bow, brute_force (core/names.hpp): the enumerators' own names, which
/// `vmap loops --rank` and the Python module take. `all`, brute_force's old name, still
/// reads back (no file stores these names: the formats keep the enumerator's number) until
/// the next release; the front ends say so when it is given.
[[nodiscard]] constexpr auto names_of(CandidateIndex) noexcept {
  return detail::NameTable<CandidateIndex, 5>{{{{CandidateIndex::tree, "tree"},
                                                {CandidateIndex::tree_ranked, "tree_ranked"},
                                                {CandidateIndex::bow, "bow"},
                                                {CandidateIndex::brute_force, "brute_force"},
                                                {CandidateIndex::brute_force, "all"}}}};
}
[[nodiscard]] constexpr std::string_view to_string(CandidateIndex c) noexcept { return names_of(c).name(c); }

/// The candidate sources that rank by bag-of-words score (and so need a ranker).
[[nodiscard]] constexpr bool ranks(CandidateIndex c) noexcept {
  return c == CandidateIndex::tree_ranked || c == CandidateIndex::bow;
}

/// The candidate sources that need label vectors.
[[nodiscard]] constexpr bool uses_labels(CandidateIndex c) noexcept {
  return c == CandidateIndex::tree || c == CandidateIndex::tree_ranked;
}

/// The most previous queries temporal consistency may ask for (LoopOptions).
inline constexpr std::size_t max_temporal_consistency = 1000;

/// Whether a frame added to the loop engine starts a new view of the chain (the revisit
/// rule, lcd/loop_engine.hpp) or stays in the last frame's.
enum class ViewStep : std::uint8_t {
  same_view,  ///< the frame still sees its view's first frame
  new_view,   ///< the view changed (a key image; a frame below the selector's tau)
};

/// The options of the loop engine, the same names for LoopDetector, VisualMemory and the
/// command line.
struct LoopOptions {
  LabelVectorOptions labels{};  ///< score threshold of eq. 3 (0.5)
  /// Frames j with j + window >= i are never candidates of frame i: consecutive frames
  /// are trivially similar. 10 as in the rtabmap_loop baseline. The revisit rule (the
  /// chain of views), not the window, decides whether an older frame is a revisit.
  std::size_t window = 10;
  /// m of sec. 3.3: backtrack up the tree until at least this many candidates. 5: a
  /// leaf of a handful of frames is one place seen from a few positions.
  std::size_t min_candidates = 5;
  /// tree_ranked: the paper's tree with bag-of-words ranking (needs labels and a
  /// vocabulary); VisualMemory uses bow for frames without detections.
  CandidateIndex index = CandidateIndex::tree_ranked;
  /// Ranked sources: how many of the best-scored candidates are verified. 2: the top k
  /// at which bow keeps brute force's recall on rtabmap_loop (see
  /// examples/bench/bench_loops.cpp; results in examples/results/loops.md). ORB-SLAM3
  /// verifies 3.
  std::size_t top_k = 2;
  /// Ranked sources: candidates scoring below this bag-of-words score are not verified.
  /// 0: none is dropped for its score.
  double min_bow_score = 0.0;
  /// A loop stands when the previous `temporal_consistency` queries also matched places
  /// within `temporal_tolerance` frames of the next one's (DBoW2's islands). 0 (off) by
  /// default: one confirmation costs true loops while the decision alone keeps precision
  /// 1.0 on the shared sequences (see examples/loops.md, "The place decision"; results in
  /// examples/results/loops.md).
  std::size_t temporal_consistency = 0;
  std::size_t temporal_tolerance = 3;
  /// The revisit rule (lcd/loop_engine.hpp): candidate j was left when a view of the
  /// chain between j and the query began with a frame whose eq. 5 similarity to j
  /// (verified matches over the larger feature count) is below `left_ratio` times the
  /// query's. 0.5: a car driving on sees j less with every frame, so no frame in between
  /// falls below half the query's similarity (kitti07_160 closes no loop), while a
  /// camera that went elsewhere shares nothing with j there (similarity 0); see
  /// examples/loops.md, "The place decision", and examples/results/loops.md.
  double left_ratio = 0.5;
  /// The decision (confidence threshold, evidence).
  PlaceDecisionOptions decision{};
};

}  // namespace vmap
