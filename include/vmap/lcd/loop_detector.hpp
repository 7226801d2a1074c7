#pragma once

// Loop closure detection over key frames (DESIGN.md sec. 1.2). Per key frame: its label
// vector (LFM-LCD, Zhu et al., Sensors 2021, eq. 3-4) and its bag of words -> loop
// candidates from one of four sources -> feature matching and geometric verification of
// each candidate -> the best verified candidate is a loop when it passes the thresholds
// (and, optionally, when the previous queries agree on the place: temporal consistency).
//
// Candidate sources:
//   tree         every frame of the query's leaf of the binary classified tree, after
//                backtracking to m frames (the paper, sec. 3.3);
//   tree_ranked  the same frames ranked by bag-of-words score, the top k verified;
//   bow          every indexed frame ranked by bag-of-words score (no labels), the top k
//                verified (DBoW2's query; iBoW-LCD and ORB-SLAM3 verify a handful too);
//   brute_force  every frame older than the window (the reference).

#include <vmap/core/concepts.hpp>
#include <vmap/core/error.hpp>
#include <vmap/geometry/similarity.hpp>
#include <vmap/hooks/detection.hpp>
#include <vmap/lcd/binary_tree.hpp>
#include <vmap/lcd/label_vector.hpp>
#include <vmap/lcd/place_ranking.hpp>
#include <vmap/place/consistency.hpp>

#include <opencv2/core.hpp>

#include <chrono>
#include <cmath>
#include <concepts>
#include <cstddef>
#include <cstdint>
#include <optional>
#include <string>
#include <string_view>
#include <utility>
#include <vector>

namespace vmap {

/// Where loop candidates come from (see the file comment).
enum class CandidateIndex : std::uint8_t {
  tree,         ///< every frame of the leaf after backtracking (LFM-LCD)
  tree_ranked,  ///< the leaf's frames ranked by bag-of-words score, top k verified
  bow,          ///< every indexed frame ranked by bag-of-words score, top k verified
  brute_force,  ///< every frame older than the window
};

[[nodiscard]] constexpr std::string_view to_string(CandidateIndex c) noexcept {
  switch (c) {
    case CandidateIndex::tree: return "tree";
    case CandidateIndex::tree_ranked: return "tree_ranked";
    case CandidateIndex::bow: return "bow";
    case CandidateIndex::brute_force: return "brute_force";
  }
  return "unknown";
}

/// The candidate sources that rank by bag-of-words score (and so need a ranker).
[[nodiscard]] constexpr bool ranks(CandidateIndex c) noexcept {
  return c == CandidateIndex::tree_ranked || c == CandidateIndex::bow;
}

struct LoopDetectorOptions {
  LabelVectorOptions labels{};  ///< score threshold of eq. 3 (0.5)
  /// Frames j with j + window >= i are never candidates of frame i: consecutive frames
  /// are trivially similar. 10 as in the rtabmap_loop baseline.
  std::size_t window = 10;
  /// m of sec. 3.3: backtrack up the tree until at least this many candidates. 5: a
  /// leaf of a handful of frames is one place seen from a few positions; fewer than
  /// that and the revisit may sit in the sibling leaf of a missed detection.
  std::size_t min_candidates = 5;
  /// A loop needs this many inliers of the fundamental matrix. 50: with ORB(1000) and
  /// MAGSAC at 1 px, the strongest false loop on rtabmap_loop had 43 inliers (brute
  /// force, examples/loops.md); a margin above it, since a false loop corrupts a map.
  int min_inliers = 50;
  /// And this similarity (the detector's Similarity policy, eq. 5 by default); 0 leaves
  /// the inlier count alone.
  double min_similarity = 0.0;
  /// tree_ranked by default: on rtabmap_loop it keeps brute force's recall with a tenth
  /// of the tree's verifications (vocabulary learned on the sequence; examples/loops.md).
  /// Needs a ranker.
  CandidateIndex index = CandidateIndex::tree_ranked;
  /// Ranked sources: how many of the best-scored candidates are verified. 2: on
  /// rtabmap_loop (ORB) bow keeps brute force's recall@100%P with 19x fewer verifications
  /// (top 1 and 3 as well), and on tum_fr3_cabinet_kf (SIFT) top 2 is the largest k that
  /// still verifies 10x fewer than brute force (examples/loops.md). ORB-SLAM3 verifies 3.
  std::size_t top_k = 2;
  /// Ranked sources: candidates scoring below this bag-of-words score are not verified.
  /// 0: none is dropped for its score (TF-IDF scores depend on the vocabulary, so a
  /// useful floor is measured per setup).
  double min_bow_score = 0.0;
  /// A loop is accepted only when the previous `temporal_consistency` frames also
  /// matched places, each within `temporal_tolerance` frames of the next one's (DBoW2's
  /// temporal consistency; place/consistency.hpp). 0: off.
  std::size_t temporal_consistency = 0;
  /// How far (in frame indices) the matched places of consecutive queries may drift and
  /// still count as the same place. 3: a revisit advances by about one frame per frame.
  std::size_t temporal_tolerance = 3;
};

/// Why a frame did or did not close a loop: the stage that stopped it.
enum class LoopStatus : std::uint8_t {
  loop_found,        ///< the best verified candidate passed every stage
  no_candidates,     ///< the source proposed no frame (too early, or an empty leaf)
  below_bow_score,   ///< ranked sources: every candidate scored below min_bow_score
  none_verified,     ///< candidates were verified but none gave a geometric model
  below_threshold,   ///< the best verified candidate has too few inliers / too low similarity
  not_consistent,    ///< it passed the thresholds but the previous queries disagree on the place
};

[[nodiscard]] constexpr std::string_view to_string(LoopStatus s) noexcept {
  switch (s) {
    case LoopStatus::loop_found: return "loop found";
    case LoopStatus::no_candidates: return "no candidates";
    case LoopStatus::below_bow_score: return "candidates, all below the bag-of-words score";
    case LoopStatus::none_verified: return "candidates, none verified";
    case LoopStatus::below_threshold: return "candidates, too few inliers";
    case LoopStatus::not_consistent: return "loop, not temporally consistent";
  }
  return "unknown";
}

/// Why one candidate frame was not the loop.
enum class CandidateStage : std::uint8_t {
  chosen,               ///< the best verified candidate (the loop when the frame's status is loop_found)
  not_in_top_k,         ///< ranked below the top k
  below_bow_score,      ///< its bag-of-words score is below min_bow_score
  verification_failed,  ///< no geometric model
  weaker,               ///< verified, but another candidate had more inliers
};

[[nodiscard]] constexpr std::string_view to_string(CandidateStage s) noexcept {
  switch (s) {
    case CandidateStage::chosen: return "chosen";
    case CandidateStage::not_in_top_k: return "not in top k";
    case CandidateStage::below_bow_score: return "below bag-of-words score";
    case CandidateStage::verification_failed: return "verification failed";
    case CandidateStage::weaker: return "fewer inliers than the chosen one";
  }
  return "unknown";
}

/// The outcome for one frame, with enough to see which stage stopped which candidate.
struct LoopResult {
  LoopStatus status = LoopStatus::no_candidates;
  std::size_t frame = 0;                 ///< index of the frame just pushed
  LabelVector labels;                    ///< its label vector (eq. 3-4)
  std::size_t candidates = 0;            ///< frames the source proposed (the leaf; every indexed frame for bow)
  std::size_t not_in_top_k = 0;          ///< ranked sources: candidates ranked below the top k
  std::size_t below_bow_score = 0;       ///< ranked sources: top-k candidates under min_bow_score
  std::size_t verifications = 0;         ///< match + verify runs spent on this frame
  std::size_t failed_verifications = 0;  ///< of which gave no geometric model
  std::optional<std::size_t> best;       ///< best verified candidate, if any
  int inliers = 0;                       ///< its inlier count (the loop score)
  double similarity = 0.0;               ///< its similarity (the detector's Similarity policy)
  int matches = 0;                       ///< its putative matches before verification
  double bow_score = 0.0;                ///< its bag-of-words score (ranked sources)
  /// Temporal consistency: how many consecutive earlier frames matched a place near
  /// `best` (the island so far). Only counted when temporal consistency is on.
  std::size_t consistent_queries = 0;
  /// Milliseconds spent on this frame's bag of words, the index update and the ranking
  /// (ranked sources; 0 otherwise): the part of the cost that grows with the database.
  double rank_ms = 0.0;
  /// The candidates that reached the ranking or verification stage, each with the stage
  /// that decided it (for `tree` and `brute_force` every candidate is verified).
  struct Candidate {
    std::size_t frame = 0;
    double bow_score = 0.0;  ///< 0 for unranked sources
    int inliers = 0;         ///< 0 unless verified
    CandidateStage stage = CandidateStage::not_in_top_k;
  };
  std::vector<Candidate> considered;

  [[nodiscard]] bool loop() const noexcept { return status == LoopStatus::loop_found; }
};

/// Streaming loop-closure detector over key frames pushed in order.
///
/// The tree and the ranker's index hold exactly the frames older than the window: frame
/// j is inserted when frame j + window + 1 arrives, so every id they return is a valid
/// candidate and the backtracking of sec. 3.3 counts only those. Per frame the detector
/// keeps what verification needs (keypoints and descriptors, no image) and its label
/// vector; the ranker keeps the bag of words. Detections come from the caller (already
/// known, or `push(image, detector)` runs any ObjectDetector). Not thread-safe: one
/// detector per thread (the Descriptor keeps state).
template <Descriptor Desc, Matcher Match, Estimator Estim, PlaceRanking Rank = PlaceRanker,
          Similarity Sim = InlierRatio>
class LoopDetector {
 public:
  /// `ranker` may be left without a vocabulary for the tree and brute_force sources.
  LoopDetector(LabelSchema schema, Desc descriptor, Match matcher, Estim estimator,
               const LoopDetectorOptions& options = {}, Rank ranker = {}, Sim similarity = {})
      : schema_(std::move(schema)),
        descriptor_(std::move(descriptor)),
        matcher_(std::move(matcher)),
        estimator_(std::move(estimator)),
        ranker_(std::move(ranker)),
        options_(options),
        similarity_(std::move(similarity)),
        tree_(schema_.size()),
        consistency_({.required = static_cast<int>(options_.temporal_consistency) + 1,
                      .tolerance = options_.temporal_tolerance}) {
    detail::check_label_min_score(options_.labels.min_score);
    detail::check(options_.min_inliers >= 0, "LoopDetectorOptions.min_inliers must be >= 0, got " +
                                                 std::to_string(options_.min_inliers));
    detail::check(std::isfinite(options_.min_similarity) && options_.min_similarity >= 0 && options_.min_similarity <= 1,
                  "LoopDetectorOptions.min_similarity must be in [0, 1]");
    detail::check(std::isfinite(options_.min_bow_score) && options_.min_bow_score >= 0,
                  "LoopDetectorOptions.min_bow_score must be finite and >= 0");
    if (ranks(options_.index)) {
      detail::check(options_.top_k >= 1, "LoopDetectorOptions.top_k must be >= 1 for the " +
                                             std::string(to_string(options_.index)) + " candidate source");
      detail::check(static_cast<bool>(ranker_.ready()),
                    "LoopDetectorOptions.index " + std::string(to_string(options_.index)) +
                        " ranks by bag of words and needs a vocabulary; give the detector a ranker with one, "
                        "or choose the tree or brute_force source");
    }
  }

  /// Extracts the features of `image`, then `add(features, detections)`.
  LoopResult push(const cv::Mat& image, const std::vector<Detection>& detections) {
    detail::check(!image.empty(),
                  [&] { return "LoopDetector::push: frame " + std::to_string(frames_.size()) + " is empty"; });
    return add(descriptor_.extract(image), detections);
  }

  /// Runs `detector` on `image`, then `push(image, detections)`.
  template <ObjectDetector Detector>
  LoopResult push(const cv::Mat& image, Detector& detector) {
    detail::check(!image.empty(),
                  [&] { return "LoopDetector::push: frame " + std::to_string(frames_.size()) + " is empty"; });
    return push(image, detector.detect(image));
  }

  /// One key frame whose features are already extracted (by the same kind of Descriptor
  /// as the frames before it: the key-image selector has them) and whose detections are
  /// known. Neither the descriptor nor any detector is called.
  LoopResult add(Features features, const std::vector<Detection>& detections) {
    LoopResult r;
    r.frame = frames_.size();
    r.labels = schema_.vector(detections, options_.labels);
    std::optional<typename Rank::Bow> bow;
    const auto t0 = std::chrono::steady_clock::now();
    if (ranks(options_.index)) bow = ranker_.describe(features);
    // Frames that just left the window become candidates.
    while (next_to_index_ + options_.window < r.frame) {
      Stored& s = frames_[next_to_index_];
      tree_.insert(s.labels, next_to_index_);
      if (s.bow) {
        ranker_.add(next_to_index_, *s.bow);
        s.bow.reset();  // the ranker's inverted file holds it now
      }
      ++next_to_index_;
    }

    std::vector<std::size_t> to_verify;
    std::vector<double> scores;
    switch (options_.index) {
      case CandidateIndex::tree:
        to_verify = tree_.candidates(r.labels, options_.min_candidates);
        r.candidates = to_verify.size();
        break;
      case CandidateIndex::brute_force:
        for (std::size_t j = 0; j < next_to_index_; ++j) to_verify.push_back(j);
        r.candidates = to_verify.size();
        break;
      case CandidateIndex::tree_ranked:
      case CandidateIndex::bow: {
        std::vector<std::size_t> leaf;
        if (options_.index == CandidateIndex::tree_ranked) {
          leaf = tree_.candidates(r.labels, options_.min_candidates);
          r.candidates = leaf.size();
        } else {
          r.candidates = next_to_index_;
        }
        if (r.candidates == 0) break;
        const std::vector<RankedFrame> ranked = ranker_.rank(
            *bow, options_.top_k, options_.index == CandidateIndex::tree_ranked ? &leaf : nullptr);
        r.not_in_top_k = r.candidates - std::min(r.candidates, ranked.size());
        r.rank_ms = std::chrono::duration<double, std::milli>(std::chrono::steady_clock::now() - t0).count();
        for (const RankedFrame& f : ranked) {
          if (f.score < options_.min_bow_score) {
            ++r.below_bow_score;
            r.considered.push_back({f.frame, f.score, 0, CandidateStage::below_bow_score});
            continue;
          }
          to_verify.push_back(f.frame);
          scores.push_back(f.score);
        }
        break;
      }
    }

    std::optional<std::size_t> chosen;  // index into r.considered
    for (std::size_t c = 0; c < to_verify.size(); ++c) {
      const std::size_t j = to_verify[c];
      const Features& old = frames_[j].features;
      const Matches matches = matcher_.match(features, old);
      const Verification v = estimator_.verify(features, old, matches);
      ++r.verifications;
      const double score = scores.empty() ? 0.0 : scores[c];
      if (!v.ok()) {
        ++r.failed_verifications;
        r.considered.push_back({j, score, 0, CandidateStage::verification_failed});
        continue;
      }
      r.considered.push_back({j, score, v.inliers, CandidateStage::weaker});
      if (!r.best || v.inliers > r.inliers) {
        r.best = j;
        r.inliers = v.inliers;
        r.similarity = similarity_(features, old, v);
        r.matches = v.matches;
        r.bow_score = score;
        chosen = r.considered.size() - 1;
      }
    }
    if (chosen) r.considered[*chosen].stage = CandidateStage::chosen;

    if (r.candidates == 0)
      r.status = LoopStatus::no_candidates;
    else if (to_verify.empty())
      r.status = r.below_bow_score > 0 ? LoopStatus::below_bow_score : LoopStatus::no_candidates;
    else if (!r.best)
      r.status = LoopStatus::none_verified;
    else if (r.inliers >= options_.min_inliers && r.similarity >= options_.min_similarity)
      r.status = LoopStatus::loop_found;
    else
      r.status = LoopStatus::below_threshold;
    apply_temporal_consistency(r);

    verifications_ += r.verifications;
    frames_.push_back({std::move(features), r.labels, std::move(bow)});
    return r;
  }

  [[nodiscard]] std::size_t frames() const noexcept { return frames_.size(); }
  /// Verifications spent over all frames so far.
  [[nodiscard]] std::size_t verifications() const noexcept { return verifications_; }
  [[nodiscard]] const LabelSchema& schema() const noexcept { return schema_; }
  [[nodiscard]] const BinaryClassifiedTree<std::size_t>& tree() const noexcept { return tree_; }
  [[nodiscard]] const Rank& ranker() const noexcept { return ranker_; }
  [[nodiscard]] const LoopDetectorOptions& options() const noexcept { return options_; }

  /// Bytes held for the frames: keypoints, descriptors, label vectors, bags of words of
  /// the frames in the window, and the ranker's index (not the tree's nodes).
  [[nodiscard]] std::size_t memory_bytes() const {
    std::size_t bytes = frames_.capacity() * sizeof(Stored) + static_cast<std::size_t>(ranker_.memory_bytes());
    for (const Stored& s : frames_) {
      bytes += s.features.keypoints.capacity() * sizeof(cv::KeyPoint);
      bytes += s.features.descriptors.total() * s.features.descriptors.elemSize();
      bytes += s.labels.capacity() / 8;
    }
    return bytes;
  }

 private:
  struct Stored {
    Features features;
    LabelVector labels;
    std::optional<typename Rank::Bow> bow;  ///< until the frame leaves the window
  };

  /// Temporal consistency (place/consistency.hpp: DBoW2's islands): the frame's place is
  /// its best candidate when that passed the thresholds, none otherwise; the loop stands
  /// when this frame and the k before it matched places within the tolerance.
  void apply_temporal_consistency(LoopResult& r) {
    if (options_.temporal_consistency == 0) return;
    const bool candidate = r.status == LoopStatus::loop_found;
    const ConsistencyState<std::size_t> state = consistency_.update(candidate ? r.best : std::nullopt);
    r.consistent_queries = state.consecutive > 0 ? static_cast<std::size_t>(state.consecutive - 1) : 0;
    if (candidate && !state.accepted) r.status = LoopStatus::not_consistent;
  }

  LabelSchema schema_;
  Desc descriptor_;
  Match matcher_;
  Estim estimator_;
  Rank ranker_;
  LoopDetectorOptions options_;
  Sim similarity_;
  BinaryClassifiedTree<std::size_t> tree_;
  std::vector<Stored> frames_;
  TemporalConsistency<std::size_t> consistency_;
  std::size_t next_to_index_ = 0;
  std::size_t verifications_ = 0;
};

}  // namespace vmap
