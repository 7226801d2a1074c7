#pragma once

// Key-image selection over one of the shipped policy stacks, chosen at run time: the
// KeyframeSelector (keyframe/selector.hpp, García-Pintos et al. 2023, Algorithm 1 /
// eq. 6) of the stack's descriptor, matcher and estimator (runtime/policies.hpp, for
// selection: no homography test) and eq. 5's inlier ratio, behind one type. The work per
// feature and per match stays statically dispatched inside; one virtual call is made per
// frame.
//
//   vmap::AnySelector selector(vmap::PolicyStack{}, {.tau = 0.3});
//   auto frames = vmap::FrameSource::open("rgb.txt", {.grey = true});
//   selector.run(frames, {.pipelined = true});
//   std::printf("%zu key images\n", selector.map().keys.size());
//
// The threshold sweep of the same stack (keyframe/sweep.hpp) is sweep_thresholds(source,
// stack, options).

#include <vmap/core/error.hpp>
#include <vmap/core/features.hpp>
#include <vmap/geometry/similarity.hpp>
#include <vmap/io/frame_source.hpp>
#include <vmap/keyframe/front_end.hpp>
#include <vmap/keyframe/pipeline.hpp>
#include <vmap/keyframe/selector.hpp>
#include <vmap/keyframe/sweep.hpp>
#include <vmap/keyframe/visual_map.hpp>
#include <vmap/runtime/policies.hpp>
#include <vmap/runtime/stack.hpp>

#include <functional>
#include <memory>
#include <string>
#include <utility>

namespace vmap {

/// Two images' features matched and verified as a selector scores a pair (for pictures of
/// a map's links): the matches, and the score with the verification.
struct VerifiedPair {
  Matches matches{};
  PairScore score{};
};

/// The pair (a, b) as `selector` scores it, the estimator always run.
template <class D, class M, class E, class S>
[[nodiscard]] VerifiedPair verify_pair(const BasicKeyframeSelector<FeatureFrontEnd<D, M, E, S>>& selector,
                                       const Features& a, const Features& b) {
  const auto& front = selector.front_end();
  VerifiedPair p;
  p.matches = front.match(a, b);
  p.score = front.bound(a, b, p.matches);
  front.verify(a, b, p.matches, p.score);
  return p;
}

namespace detail {

/// The calls AnySelector makes, whatever the stack.
class SelectorBase {
 public:
  SelectorBase() = default;
  SelectorBase(const SelectorBase&) = delete;
  SelectorBase& operator=(const SelectorBase&) = delete;
  virtual ~SelectorBase() = default;

  virtual FrameResult push(const Frame& frame) = 0;
  virtual void run(FrameSource& source, const RunOptions& options,
                   const std::function<void(const FrameResult&)>& on_frame) = 0;
  [[nodiscard]] virtual const VisualMap& map() const = 0;
  [[nodiscard]] virtual const SelectorOptions& options() const = 0;
  virtual void reset() = 0;
  [[nodiscard]] virtual VerifiedPair verify_pair(const Features& a, const Features& b) const = 0;
};

template <class Selector>
class SelectorModel final : public SelectorBase {
 public:
  template <class... Args>
  explicit SelectorModel(Args&&... args) : selector_(std::forward<Args>(args)...) {}

  FrameResult push(const Frame& frame) override { return selector_.push(frame); }
  void run(FrameSource& source, const RunOptions& options,
           const std::function<void(const FrameResult&)>& on_frame) override {
    run_selector(source, selector_, options, [&](const FrameResult& r) {
      if (on_frame) on_frame(r);
    });
  }
  [[nodiscard]] const VisualMap& map() const override { return selector_.map(); }
  [[nodiscard]] const SelectorOptions& options() const override { return selector_.options(); }
  void reset() override { selector_.reset(); }
  [[nodiscard]] VerifiedPair verify_pair(const Features& a, const Features& b) const override {
    return vmap::verify_pair(selector_, a, b);
  }

 private:
  Selector selector_;
};

/// The selectors and sweeps of one descriptor type D, with the stack's matcher and
/// estimator for selection. Defined apart from AnySelector so that a program linking
/// vmap::stacks instantiates none of them itself (see the end of this file).
template <class D>
struct SelectorFactory {
  static std::unique_ptr<SelectorBase> create(D descriptor, const PolicyStack& stack, const SelectorOptions& options,
                                              const std::string& camera_name);
  static SweepResult sweep(D descriptor, FrameSource& source, const PolicyStack& stack, const SweepOptions& options,
                           const std::string& camera_name);
};

template <class D>
std::unique_ptr<SelectorBase> SelectorFactory<D>::create(D descriptor, const PolicyStack& stack,
                                                         const SelectorOptions& options,
                                                         const std::string& camera_name) {
  auto matcher = matcher_for(descriptor);
  auto estimator = estimator_for<D>(stack, StackUse::selection, camera_name);
  using Selector = KeyframeSelector<D, decltype(matcher), decltype(estimator), InlierRatio>;
  return std::make_unique<SelectorModel<Selector>>(std::move(descriptor), std::move(matcher), std::move(estimator),
                                                   InlierRatio{}, options);
}

template <class D>
SweepResult SelectorFactory<D>::sweep(D descriptor, FrameSource& source, const PolicyStack& stack,
                                      const SweepOptions& options, const std::string& camera_name) {
  auto matcher = matcher_for(descriptor);
  auto estimator = estimator_for<D>(stack, StackUse::selection, camera_name);
  return sweep_thresholds(source, std::move(descriptor), std::move(matcher), std::move(estimator), InlierRatio{},
                          options);
}

}  // namespace detail

/// A KeyframeSelector of a PolicyStack (see the top of this file).
///
/// Lifetime: it owns its policies and its map (the key images' features, and their
/// pixels with SelectorOptions::keep_images: push() keeps a reference to the frame's
/// image then, so a caller whose buffer changes passes a copy). Moving it moves the
/// selector; it is not copyable.
///
/// Thread safety: as KeyframeSelector, single-threaded. push(), run() and reset() change
/// it and must not overlap any other call; map() and options() may be read while no such
/// call runs. run() itself uses other threads for decoding and extraction (RunOptions),
/// and calls on_frame on the calling thread between two frames, where map() may be read.
class AnySelector {
 public:
  /// The selector of `stack` (validated; a model file is loaded here) with `options`
  /// (tau checked by the selector). `camera_name` names the stack's camera in errors
  /// (runtime/stack_choice.hpp).
  explicit AnySelector(const PolicyStack& stack, const SelectorOptions& options = {},
                       const std::string& camera_name = "camera")
      : stack_(stack),
        selector_(with_descriptor(stack, [&](auto descriptor) {
          return detail::SelectorFactory<decltype(descriptor)>::create(std::move(descriptor), stack, options,
                                                                       camera_name);
        })) {}

  /// One frame (Algorithm 1's step j): whether it made a key image, and why.
  FrameResult push(const Frame& frame) { return selector_->push(frame); }

  /// Every frame of `source` (run_selector: decoding and extraction on other threads when
  /// pipelined), on_frame (optional) after each.
  void run(FrameSource& source, const RunOptions& options = {},
           const std::function<void(const FrameResult&)>& on_frame = {}) {
    selector_->run(source, options, on_frame);
  }

  /// The map so far: key images, F-matrices, similarities (eq. 7's quality).
  [[nodiscard]] const VisualMap& map() const { return selector_->map(); }
  [[nodiscard]] const SelectorOptions& options() const { return selector_->options(); }
  [[nodiscard]] const PolicyStack& stack() const noexcept { return stack_; }
  /// A new sequence: an empty map, the next frame is K_1.
  void reset() { selector_->reset(); }
  /// Two key images' features matched and verified as this selector scores them.
  [[nodiscard]] VerifiedPair verify_pair(const Features& a, const Features& b) const {
    return selector_->verify_pair(a, b);
  }

 private:
  PolicyStack stack_;
  std::unique_ptr<detail::SelectorBase> selector_;
};

/// The pair (a, b) as `selector` scores it (the free form, as for a typed selector).
[[nodiscard]] inline VerifiedPair verify_pair(const AnySelector& selector, const Features& a, const Features& b) {
  return selector.verify_pair(a, b);
}

/// The threshold sweep (keyframe/sweep.hpp) of the stack's selection policies over
/// `source`: every tau in one pass, features extracted once.
[[nodiscard]] inline SweepResult sweep_thresholds(FrameSource& source, const PolicyStack& stack,
                                                  const SweepOptions& options = {},
                                                  const std::string& camera_name = "camera") {
  return with_descriptor(stack, [&](auto descriptor) {
    return detail::SelectorFactory<decltype(descriptor)>::sweep(std::move(descriptor), source, stack, options,
                                                                camera_name);
  });
}

}  // namespace vmap

// A program that links vmap::stacks compiles the selectors of the shipped descriptors
// once, there (runtime/detail/compiled_stacks.hpp).
#ifdef VMAP_COMPILED_STACKS
namespace vmap::detail {
extern template struct SelectorFactory<OrbDescriptor>;
extern template struct SelectorFactory<AkazeDescriptor>;
extern template struct SelectorFactory<SiftDescriptor>;
extern template struct SelectorFactory<XFeatDescriptor>;
extern template struct SelectorFactory<XFeatDenseDescriptor>;
}  // namespace vmap::detail
#endif
