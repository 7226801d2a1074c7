#pragma once

// Loop closure detection over key frames (examples/methods.md, sec. 2). Per key frame: its label
// vector (LFM-LCD, Zhu et al., Sensors 2021, eq. 3-4) and its features -> the loop
// engine (lcd/loop_engine.hpp: candidates from the tree, the bag-of-words ranking or
// brute force, verification, the evidence and the place decision with the revisit rule
// and temporal consistency). LoopDetector keeps the frames' features and lends them to
// the engine.

#include <vmap/core/concepts.hpp>
#include <vmap/core/error.hpp>
#include <vmap/geometry/similarity.hpp>
#include <vmap/hooks/detection.hpp>
#include <vmap/keyframe/front_end.hpp>
#include <vmap/keyframe/options.hpp>
#include <vmap/lcd/label_vector.hpp>
#include <vmap/lcd/loop_engine.hpp>
#include <vmap/lcd/place_ranking.hpp>

#include <opencv2/core.hpp>

#include <cstddef>
#include <optional>
#include <string>
#include <utility>
#include <vector>

namespace vmap {

/// LoopDetector's options are the loop engine's.
using LoopDetectorOptions = LoopOptions;

/// The outcome for one frame: the engine's decision, the frame and its label vector.
struct LoopResult : PlaceDecision {
  std::size_t frame = 0;  ///< index of the frame just pushed
  LabelVector labels;     ///< its label vector (eq. 3-4)

  [[nodiscard]] bool loop() const noexcept { return accepted(); }
};

/// Streaming loop-closure detector over key frames pushed in order.
///
/// The tree holds exactly the frames older than the window: frame j is inserted when
/// frame j + window + 1 arrives, so every id it returns is a valid candidate and the
/// backtracking of sec. 3.3 counts only those. Per frame the detector keeps what
/// verification needs (keypoints and descriptors, no image); the engine keeps its label
/// vector and the ranker its bag of words. Detections come from the caller (already
/// known, or `push(image, detector)` runs any ObjectDetector). Not thread-safe: one
/// detector per thread (the Descriptor keeps state).
template <Descriptor Desc, Matcher Match, Estimator Estim, PlaceRanking Rank = PlaceRanker>
class LoopDetector {
 public:
  /// `ranker` may be left without a vocabulary for the tree and brute_force sources;
  /// `model` says which geometric model the estimator fits (its minimal sample enters the
  /// evidence's significance); by default the engine's inference from the estimator's
  /// type (place_model_of), so a detector and an engine given one estimator weigh alike.
  LoopDetector(LabelSchema schema, Desc descriptor, Match matcher, Estim estimator,
               const LoopDetectorOptions& options = {}, Rank ranker = {}, PlaceModel model = place_model_of<Estim>())
      : descriptor_(std::move(descriptor)),
        engine_(std::move(matcher), std::move(estimator), options, std::move(ranker), std::move(schema), model) {}

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
  /// known. Neither the descriptor nor any detector is called. `view`: whether it starts
  /// a new view of the revisit rule's chain, where the caller knows (the key images of a
  /// selector each do, as in a visual memory); by default the detector tests it.
  LoopResult add(Features features, const std::vector<Detection>& detections,
                 std::optional<ViewStep> view = std::nullopt) {
    LoopResult r;
    r.frame = frames_.size();
    r.labels = engine_.schema().vector(detections, engine_.options().labels);
    const ViewStep step = view ? *view : view_step(features);
    static_cast<PlaceDecision&>(r) = engine_.add(
        features, r.labels, [this](std::size_t j) -> const Features& { return frames_[j]; }, step);
    if (step == ViewStep::new_view) view_start_ = r.frame;
    frames_.push_back(std::move(features));
    return r;
  }

  /// The first frame of the current view of the chain (the revisit rule).
  [[nodiscard]] std::size_t view_start() const noexcept { return view_start_; }

  [[nodiscard]] std::size_t frames() const noexcept { return frames_.size(); }
  /// Verifications spent over all frames so far.
  [[nodiscard]] std::size_t verifications() const noexcept { return engine_.verifications(); }
  [[nodiscard]] const LabelSchema& schema() const noexcept { return engine_.schema(); }
  [[nodiscard]] const BinaryClassifiedTree<std::size_t>& tree() const noexcept { return engine_.tree(); }
  [[nodiscard]] const Rank& ranker() const noexcept { return engine_.ranker(); }
  [[nodiscard]] const LoopDetectorOptions& options() const noexcept { return engine_.options(); }
  [[nodiscard]] const LoopEngine<Match, Estim, Rank>& engine() const noexcept { return engine_; }
  /// Whether the camera never left its place (lcd/loop_engine.hpp, stationary()).
  [[nodiscard]] bool stationary() const noexcept { return engine_.stationary(); }

  /// Bytes held for the frames: keypoints, descriptors, label vectors and the ranker's
  /// index (not the tree's nodes).
  [[nodiscard]] std::size_t memory_bytes() const {
    std::size_t bytes = frames_.capacity() * sizeof(Features) + engine_.memory_bytes();
    for (const Features& f : frames_) {
      bytes += f.keypoints.capacity() * sizeof(cv::KeyPoint);
      bytes += f.descriptors.total() * f.descriptors.elemSize();
    }
    return bytes;
  }

 private:
  /// Whether `f` starts a new view: the key-image selector's test (Algorithm 1, eq. 5,
  /// its default tau, with its fast path) against the first frame of the current view, so
  /// a stream of frames has the views a visual memory's key images would give it.
  [[nodiscard]] ViewStep view_step(const Features& f) const {
    if (frames_.empty()) return ViewStep::new_view;
    const double tau = SelectorOptions{}.tau;
    const PairScore s = score_pair(engine_.matcher(), engine_.estimator(), InlierRatio{}, frames_[view_start_], f, tau);
    return key_reason(s, tau) == KeyReason::none ? ViewStep::same_view : ViewStep::new_view;
  }

  Desc descriptor_;
  LoopEngine<Match, Estim, Rank> engine_;
  std::vector<Features> frames_;
  std::size_t view_start_ = 0;
};

}  // namespace vmap
