#pragma once

// The policies of a PolicyStack (runtime/stack.hpp), built at run time: with_policies
// calls a generic function with the descriptor, matcher and estimator the stack names,
// one instantiation of that function per descriptor type, so the per-feature work is
// statically dispatched (no virtual call per feature or match).
//
//   vmap::with_policies(stack, vmap::StackUse::selection, [&](auto descriptor, auto matcher, auto estimator) {
//     vmap::KeyframeSelector selector(std::move(descriptor), std::move(matcher), std::move(estimator),
//                                     vmap::InlierRatio{});
//     ...
//   });
//
// The matcher follows from the descriptor: mutual nearest neighbours by brute force, or
// for XFeat's dense grid the same by blocked matrix products on unit copies of a
// refinable grid's raw descriptors. The estimator is the F-matrix (the stack's method,
// 1 px, 0.99) on the camera's undistorted keypoints when the stack has one
// (Calibrated, which passes through without one), wrapped for the dense grid by
// XFeatRefined (XFeat*'s refinement when the stack names its network, else a pass
// through), so xfeat-dense and xfeat-star share one instantiation.

#include <vmap/core/error.hpp>
#include <vmap/features/akaze.hpp>
#include <vmap/features/orb.hpp>
#include <vmap/features/sift.hpp>
#include <vmap/geometry/calibrated.hpp>
#include <vmap/geometry/fundamental.hpp>
#include <vmap/geometry/similarity.hpp>
#include <vmap/hooks/xfeat.hpp>
#include <vmap/hooks/xfeat_dense.hpp>
#include <vmap/hooks/xfeat_fine.hpp>
#include <vmap/matching/brute_force.hpp>
#include <vmap/runtime/stack.hpp>

#include <optional>
#include <string>
#include <type_traits>
#include <utility>

namespace vmap {

/// What the policies are for: the estimator's homography degeneracy test runs only
/// where something reads it (a memory's place decision); key-image selection and the
/// offline loop run skip it, as the papers' baselines do.
enum class StackUse : std::uint8_t { memory, selection, loops };

/// The matcher that goes with a descriptor (see the top of this file).
template <class D>
[[nodiscard]] auto matcher_for(const D& d) {
  if constexpr (std::is_same_v<D, XFeatDenseDescriptor>)
    return DenseMutualMatcher({.normalise = d.options().grid == XFeatGrid::refinable});
  else
    return BruteForceMatcher({.mode = MatchMode::mutual});
}

/// `estimator` as a descriptor of type D verifies with it: XFeat's dense grid wraps it in
/// XFeatRefined (XFeat*'s refinement when the stack names its network, else a pass
/// through); every other descriptor takes it as it is.
template <class D, class E>
[[nodiscard]] auto verifier_for(const PolicyStack& s, E estimator) {
  if constexpr (std::is_same_v<D, XFeatDenseDescriptor>)
    return XFeatRefined<E>(s.descriptor == DescriptorKind::xfeat_star
                               ? std::optional<XFeatFineOptions>(XFeatFineOptions{.model = s.refine_model})
                               : std::nullopt,
                           std::move(estimator));
  else
    return estimator;
}

/// The stack's estimator for a descriptor of type D with these F-matrix options (a
/// caller's own threshold): the F-matrix on the stack's camera (Calibrated), behind
/// verifier_for. `camera_name` names the camera in errors (e.g. its calibration file).
template <class D>
[[nodiscard]] auto estimator_for(const PolicyStack& s, const FundamentalOptions& options, const std::string& camera_name) {
  return verifier_for<D>(s, Calibrated<FundamentalEstimator>(s.camera, FundamentalEstimator(options), camera_name));
}

/// The stack's estimator for a descriptor of type D, for `use`.
template <class D>
[[nodiscard]] auto estimator_for(const PolicyStack& s, StackUse use, const std::string& camera_name) {
  return estimator_for<D>(s, detail::stack_fundamental_options(s.method, use == StackUse::memory), camera_name);
}

/// Calls f(descriptor) with the Descriptor the stack names (validated first; a model
/// file is loaded here).
template <class F>
decltype(auto) with_descriptor(const PolicyStack& s, F&& f) {
  s.validate();
  switch (s.descriptor) {
    case DescriptorKind::orb:
      return std::forward<F>(f)(OrbDescriptor({.features = s.features}));
    case DescriptorKind::akaze:
      return std::forward<F>(f)(AkazeDescriptor{});
    case DescriptorKind::sift:
      return std::forward<F>(f)(SiftDescriptor({.features = s.features}));
    case DescriptorKind::xfeat:
      return std::forward<F>(f)(XFeatDescriptor({.model = s.model, .top_k = s.features}));
    case DescriptorKind::xfeat_dense:
      return std::forward<F>(f)(XFeatDenseDescriptor({.model = s.model}));
    case DescriptorKind::xfeat_star:
      return std::forward<F>(f)(XFeatDenseDescriptor({.model = s.model, .grid = XFeatGrid::refinable}));
  }
  detail::fail("with_descriptor: unknown descriptor");
}

/// Calls f(descriptor, matcher, estimator) with the stack's policies for `use`.
template <class F>
decltype(auto) with_policies(const PolicyStack& s, StackUse use, F&& f, const std::string& camera_name = "camera") {
  return with_descriptor(s, [&](auto descriptor) -> decltype(auto) {
    using D = decltype(descriptor);
    auto matcher = matcher_for(descriptor);
    auto estimator = estimator_for<D>(s, use, camera_name);
    return std::forward<F>(f)(std::move(descriptor), std::move(matcher), std::move(estimator));
  });
}

}  // namespace vmap
