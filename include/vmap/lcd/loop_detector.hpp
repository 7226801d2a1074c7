#pragma once

// LFM-LCD loop closure detection (Zhu et al., Sensors 2021, sec. 3; DESIGN.md sec. 1.2):
// per key frame, detect objects -> binary label vector (eq. 3-4) -> candidates from the
// binary classified tree (sec. 3.3) -> feature matching and geometric verification of
// each candidate -> the best verified candidate is a loop when it passes the thresholds.

#include <vmap/core/concepts.hpp>
#include <vmap/core/error.hpp>
#include <vmap/geometry/similarity.hpp>
#include <vmap/hooks/detection.hpp>
#include <vmap/lcd/binary_tree.hpp>
#include <vmap/lcd/label_vector.hpp>

#include <opencv2/core.hpp>

#include <cmath>
#include <cstddef>
#include <cstdint>
#include <optional>
#include <string>
#include <string_view>
#include <utility>
#include <vector>

namespace vmap {

/// Where loop candidates come from.
enum class CandidateIndex : std::uint8_t {
  tree,         ///< the binary classified tree (LFM-LCD)
  brute_force,  ///< every frame older than the window (the reference the tree is measured against)
};

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
  /// And this eq. 5 similarity (inliers / max feature count); 0 leaves the inlier count alone.
  double min_similarity = 0.0;
  CandidateIndex index = CandidateIndex::tree;
};

/// Why a frame did or did not close a loop.
enum class LoopStatus : std::uint8_t {
  loop_found,       ///< the best verified candidate passed the thresholds
  no_candidates,    ///< the index returned no frame (too early, or an empty branch)
  none_verified,    ///< candidates were verified but none gave a geometric model
  below_threshold,  ///< the best verified candidate has too few inliers / too low similarity
};

[[nodiscard]] constexpr std::string_view to_string(LoopStatus s) noexcept {
  switch (s) {
    case LoopStatus::loop_found: return "loop found";
    case LoopStatus::no_candidates: return "no candidates";
    case LoopStatus::none_verified: return "candidates, none verified";
    case LoopStatus::below_threshold: return "candidates, too few inliers";
  }
  return "unknown";
}

/// The outcome for one frame, with enough to see why a loop was or was not found.
struct LoopResult {
  LoopStatus status = LoopStatus::no_candidates;
  std::size_t frame = 0;                 ///< index of the frame just pushed
  LabelVector labels;                    ///< its label vector (eq. 3-4)
  std::size_t candidates = 0;            ///< frames the index proposed
  std::size_t verifications = 0;         ///< match + verify runs spent on this frame
  std::optional<std::size_t> best;       ///< best verified candidate, if any
  int inliers = 0;                       ///< its inlier count (the loop score)
  double similarity = 0.0;               ///< its eq. 5 similarity
  int matches = 0;                       ///< its putative matches before verification

  [[nodiscard]] bool loop() const noexcept { return status == LoopStatus::loop_found; }
};

/// Streaming loop-closure detector over key frames pushed in order.
///
/// The tree holds exactly the frames older than the window: frame j is inserted when
/// frame j + window + 1 arrives, so every id the tree returns is a valid candidate and
/// the backtracking of sec. 3.3 counts only those. Features of every frame are kept for
/// verification. Not thread-safe: one detector per thread (the Descriptor and the
/// Detector keep state).
template <ObjectDetector Detector, Descriptor Desc, Matcher Match, Estimator Estim>
class LoopDetector {
 public:
  LoopDetector(LabelSchema schema, Detector detector, Desc descriptor, Match matcher, Estim estimator,
               const LoopDetectorOptions& options = {})
      : schema_(std::move(schema)),
        detector_(std::move(detector)),
        descriptor_(std::move(descriptor)),
        matcher_(std::move(matcher)),
        estimator_(std::move(estimator)),
        options_(options),
        tree_(schema_.size()) {
    detail::check_label_min_score(options_.labels.min_score);
    detail::check(options_.min_inliers >= 0, "LoopDetectorOptions.min_inliers must be >= 0, got " +
                                                 std::to_string(options_.min_inliers));
    detail::check(std::isfinite(options_.min_similarity) && options_.min_similarity >= 0 && options_.min_similarity <= 1,
                  "LoopDetectorOptions.min_similarity must be in [0, 1]");
  }

  /// Runs the detector on `image`, then `push(image, detections)`.
  LoopResult push(const cv::Mat& image) { return push(image, detector_.detect(image)); }

  /// One key frame whose detections are already known (the detector is not called).
  LoopResult push(const cv::Mat& image, const std::vector<Detection>& detections) {
    detail::check(!image.empty(), "LoopDetector::push: frame " + std::to_string(frames_.size()) + " is empty");
    LoopResult r;
    r.frame = frames_.size();
    r.labels = schema_.vector(detections, options_.labels);
    Features features = descriptor_.extract(image);
    // Frames that just left the window become candidates.
    while (next_to_index_ + options_.window < r.frame) {
      tree_.insert(frames_[next_to_index_].labels, next_to_index_);
      ++next_to_index_;
    }
    std::vector<std::size_t> candidates;
    if (options_.index == CandidateIndex::tree) {
      candidates = tree_.candidates(r.labels, options_.min_candidates);
    } else {
      for (std::size_t j = 0; j < next_to_index_; ++j) candidates.push_back(j);
    }
    r.candidates = candidates.size();
    for (std::size_t j : candidates) {
      const Features& old = frames_[j].features;
      const Matches matches = matcher_.match(features, old);
      const Verification v = estimator_.verify(features, old, matches);
      ++r.verifications;
      if (!v.ok()) continue;
      if (!r.best || v.inliers > r.inliers) {
        r.best = j;
        r.inliers = v.inliers;
        r.similarity = similarity_(features, old, v);
        r.matches = v.matches;
      }
    }
    if (candidates.empty())
      r.status = LoopStatus::no_candidates;
    else if (!r.best)
      r.status = LoopStatus::none_verified;
    else if (r.inliers >= options_.min_inliers && r.similarity >= options_.min_similarity)
      r.status = LoopStatus::loop_found;
    else
      r.status = LoopStatus::below_threshold;
    verifications_ += r.verifications;
    frames_.push_back({std::move(features), r.labels});
    return r;
  }

  [[nodiscard]] std::size_t frames() const noexcept { return frames_.size(); }
  /// Verifications spent over all frames so far.
  [[nodiscard]] std::size_t verifications() const noexcept { return verifications_; }
  [[nodiscard]] const LabelSchema& schema() const noexcept { return schema_; }
  [[nodiscard]] const BinaryClassifiedTree<std::size_t>& tree() const noexcept { return tree_; }
  [[nodiscard]] const LoopDetectorOptions& options() const noexcept { return options_; }
  [[nodiscard]] Detector& detector() noexcept { return detector_; }

 private:
  struct Stored {
    Features features;
    LabelVector labels;
  };

  LabelSchema schema_;
  Detector detector_;
  Desc descriptor_;
  Match matcher_;
  Estim estimator_;
  LoopDetectorOptions options_;
  InlierRatio similarity_;
  BinaryClassifiedTree<std::size_t> tree_;
  std::vector<Stored> frames_;
  std::size_t next_to_index_ = 0;
  std::size_t verifications_ = 0;
};

}  // namespace vmap
