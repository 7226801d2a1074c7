#pragma once

// A loop detector over one of the shipped policy stacks, chosen at run time: the
// LoopDetector (lcd/loop_detector.hpp) of the stack's descriptor, its matcher and its
// estimator (runtime/policies.hpp, for the offline loop run: no homography test), behind
// one type. The per-feature and per-match work stays statically dispatched inside; one
// virtual call is made per frame.
//
//   vmap::AnyLoopDetector detector(vmap::PolicyStack{}, vmap::LabelSchema{},
//                                  {.index = vmap::CandidateIndex::bow}, vocabulary);
//   for (const cv::Mat& image : images) {
//     const vmap::LoopResult r = detector.push(image, {});
//     if (r.loop()) std::printf("%zu closes a loop with %zu\n", r.frame, *r.best);
//   }
//
// Which candidate source a front end runs when its user names none, and whether the
// labels and the vocabulary it needs are there, are decided here too
// (default_candidate_index, check_candidate_source), so that every front end answers
// alike.

#include <vmap/core/error.hpp>
#include <vmap/core/features.hpp>
#include <vmap/hooks/detection.hpp>
#include <vmap/lcd/label_vector.hpp>
#include <vmap/lcd/loop_detector.hpp>
#include <vmap/lcd/loop_engine.hpp>
#include <vmap/lcd/place_ranking.hpp>
#include <vmap/place/vocabulary.hpp>
#include <vmap/runtime/option_names.hpp>
#include <vmap/runtime/policies.hpp>
#include <vmap/runtime/stack.hpp>

#include <opencv2/core.hpp>

#include <cstddef>
#include <memory>
#include <string>
#include <utility>
#include <vector>

namespace vmap {

/// The candidate source when the user names none: the label tree ranked by bag of words
/// with labels and a vocabulary (examples/methods.md, sec. 4), the whole database ranked
/// with a vocabulary alone, LFM-LCD's tree with labels alone, and every older frame with
/// neither.
[[nodiscard]] constexpr CandidateIndex default_candidate_index(bool labels, bool vocabulary) noexcept {
  if (labels) return vocabulary ? CandidateIndex::tree_ranked : CandidateIndex::tree;
  return vocabulary ? CandidateIndex::bow : CandidateIndex::brute_force;
}

/// An Error naming the inputs (as `names` spells "rank", "labels" and "vocabulary") when
/// the candidate source needs labels (tree, tree_ranked) or a vocabulary (tree_ranked,
/// bow) that were not given.
inline void check_candidate_source(CandidateIndex index, bool labels, bool vocabulary,
                                   const OptionNames& names = OptionNames::keywords()) {
  const std::string rank = names.with_value("rank", to_string(index));
  detail::check(labels || !uses_labels(index), [&] {
    return rank + " needs labels (" + names.with_value("rank", "bow") + " or all need none): give " +
           names("labels");
  });
  detail::check(vocabulary || !ranks(index),
                [&] { return rank + " ranks by bag of words: give " + names("vocabulary"); });
}

namespace detail {

/// The calls AnyLoopDetector makes, whatever the stack.
class LoopDetectorBase {
 public:
  LoopDetectorBase() = default;
  LoopDetectorBase(const LoopDetectorBase&) = delete;
  LoopDetectorBase& operator=(const LoopDetectorBase&) = delete;
  virtual ~LoopDetectorBase() = default;

  virtual LoopResult add(Features f, const std::vector<Detection>& detections) = 0;
  virtual LoopResult push(const cv::Mat& image, const std::vector<Detection>& detections) = 0;
  [[nodiscard]] virtual std::size_t frames() const = 0;
  [[nodiscard]] virtual std::size_t verifications() const = 0;
  [[nodiscard]] virtual bool stationary() const = 0;
  [[nodiscard]] virtual std::size_t memory_bytes() const = 0;
  [[nodiscard]] virtual const LoopOptions& options() const = 0;
  [[nodiscard]] virtual const LabelSchema& schema() const = 0;
};

template <class Detector>
class LoopDetectorModel final : public LoopDetectorBase {
 public:
  explicit LoopDetectorModel(Detector detector) : detector_(std::move(detector)) {}

  LoopResult add(Features f, const std::vector<Detection>& detections) override {
    return detector_.add(std::move(f), detections);
  }
  LoopResult push(const cv::Mat& image, const std::vector<Detection>& detections) override {
    return detector_.push(image, detections);
  }
  [[nodiscard]] std::size_t frames() const override { return detector_.frames(); }
  [[nodiscard]] std::size_t verifications() const override { return detector_.verifications(); }
  [[nodiscard]] bool stationary() const override { return detector_.stationary(); }
  [[nodiscard]] std::size_t memory_bytes() const override { return detector_.memory_bytes(); }
  [[nodiscard]] const LoopOptions& options() const override { return detector_.options(); }
  [[nodiscard]] const LabelSchema& schema() const override { return detector_.schema(); }

 private:
  Detector detector_;
};

/// The loop detectors of one descriptor type D, with the stack's matcher and estimator
/// for loops. Defined apart from AnyLoopDetector so that a program linking vmap::stacks
/// instantiates none of them itself (see the end of this file).
template <class D>
struct LoopDetectorFactory {
  static std::unique_ptr<LoopDetectorBase> create(D descriptor, const PolicyStack& stack, LabelSchema schema,
                                                  const LoopOptions& options,
                                                  const std::shared_ptr<const AnyVocabulary>& vocabulary,
                                                  const std::string& camera_name);
};

template <class D>
std::unique_ptr<LoopDetectorBase> LoopDetectorFactory<D>::create(D descriptor, const PolicyStack& stack,
                                                                 LabelSchema schema, const LoopOptions& options,
                                                                 const std::shared_ptr<const AnyVocabulary>& vocabulary,
                                                                 const std::string& camera_name) {
  auto matcher = matcher_for(descriptor);
  auto estimator = estimator_for<D>(stack, StackUse::loops, camera_name);
  using Detector = LoopDetector<D, decltype(matcher), decltype(estimator)>;
  return std::make_unique<LoopDetectorModel<Detector>>(
      Detector(std::move(schema), std::move(descriptor), std::move(matcher), std::move(estimator), options,
               PlaceRanker(vocabulary, vocabulary ? vocabulary->scoring() : BowScoring::l1)));
}

}  // namespace detail

/// A LoopDetector of a PolicyStack (see the top of this file).
///
/// Lifetime: it owns its descriptor, matcher, estimator and the features of every frame
/// added (copied in); the vocabulary is shared (kept alive by the detector). Moving it
/// moves the detector; it is not copyable.
///
/// Thread safety: as LoopDetector, not thread-safe. add() and push() change it and must
/// not run concurrently with any other call; the const members may run concurrently with
/// each other. One detector per thread, or a lock held around every call.
class AnyLoopDetector {
 public:
  /// The detector of `stack` (validated; a model file is loaded here) with the label tree
  /// of `schema` (the label sources need one) and the bag-of-words ranking of `vocabulary`
  /// (the ranked sources need one: an Error otherwise), scored as the vocabulary's
  /// weighting asks (an FBoW file: L2). `options` are checked by the loop engine.
  /// `camera_name` names the stack's camera in errors (runtime/stack_choice.hpp).
  AnyLoopDetector(const PolicyStack& stack, LabelSchema schema, const LoopOptions& options = {},
                  std::shared_ptr<const AnyVocabulary> vocabulary = nullptr, const std::string& camera_name = "camera")
      : stack_(stack),
        vocabulary_(std::move(vocabulary)),
        detector_(with_descriptor(stack, [&](auto descriptor) {
          return detail::LoopDetectorFactory<decltype(descriptor)>::create(std::move(descriptor), stack,
                                                                           std::move(schema), options, vocabulary_,
                                                                           camera_name);
        })) {}

  /// One frame whose features are already extracted by the stack's descriptor, with its
  /// detections (for the label tree): its decision, then the frame is indexed.
  LoopResult add(Features features, const std::vector<Detection>& detections) {
    return detector_->add(std::move(features), detections);
  }
  /// One image: its features by the stack's descriptor, then add().
  LoopResult push(const cv::Mat& image, const std::vector<Detection>& detections) {
    return detector_->push(image, detections);
  }

  [[nodiscard]] std::size_t frames() const { return detector_->frames(); }
  /// Verifications spent over all frames so far.
  [[nodiscard]] std::size_t verifications() const { return detector_->verifications(); }
  /// The camera never left its place (lcd/loop_engine.hpp, stationary()).
  [[nodiscard]] bool stationary() const { return detector_->stationary(); }
  /// Bytes held for the frames: keypoints, descriptors, label vectors, the ranker's index.
  [[nodiscard]] std::size_t memory_bytes() const { return detector_->memory_bytes(); }
  [[nodiscard]] const LoopOptions& options() const { return detector_->options(); }
  [[nodiscard]] const LabelSchema& schema() const { return detector_->schema(); }
  [[nodiscard]] const PolicyStack& stack() const noexcept { return stack_; }
  [[nodiscard]] const std::shared_ptr<const AnyVocabulary>& vocabulary() const noexcept { return vocabulary_; }

 private:
  PolicyStack stack_;
  std::shared_ptr<const AnyVocabulary> vocabulary_;
  std::unique_ptr<detail::LoopDetectorBase> detector_;
};

}  // namespace vmap

// A program that links vmap::stacks compiles the loop detectors of the shipped
// descriptors once, there (runtime/detail/compiled_stacks.hpp).
#ifdef VMAP_COMPILED_STACKS
namespace vmap::detail {
extern template struct LoopDetectorFactory<OrbDescriptor>;
extern template struct LoopDetectorFactory<AkazeDescriptor>;
extern template struct LoopDetectorFactory<SiftDescriptor>;
extern template struct LoopDetectorFactory<XFeatDescriptor>;
extern template struct LoopDetectorFactory<XFeatDenseDescriptor>;
}  // namespace vmap::detail
#endif
