#pragma once

// Run-time choice of the compile-time policies for the command line and benchmarks:
// the name of a descriptor or estimator picks the concrete type once, and the work
// runs inside a generic lambda instantiated for each type (no virtual call per feature).

#include "common/cli_support.hpp"

#include <vmap/core/error.hpp>
#include <vmap/features/akaze.hpp>
#include <vmap/features/orb.hpp>
#include <vmap/features/sift.hpp>
#include <vmap/geometry/fundamental.hpp>
#include <vmap/hooks/xfeat.hpp>
#include <vmap/hooks/xfeat_dense.hpp>
#include <vmap/hooks/xfeat_fine.hpp>
#include <vmap/matching/brute_force.hpp>

#include <optional>
#include <string>
#include <type_traits>
#include <utility>

namespace vmap::examples {

inline RobustMethod parse_method(const std::string& name) {
  if (name == "magsac") return RobustMethod::magsac;
  if (name == "ransac") return RobustMethod::ransac;
  if (name == "lmeds") return RobustMethod::lmeds;
  if (name == "8point") return RobustMethod::eight_point;
  usage_error("--estimator: unknown method '" + name + "' (choose magsac, ransac, lmeds or 8point)");
}

/// What the command line says about the descriptor to use.
struct DescriptorChoice {
  std::string name = "orb";  ///< orb, akaze, sift, xfeat, xfeat-dense, xfeat-star
  int features = 1000;       ///< keypoint budget (ORB, SIFT; XFeat's top-k)
  std::string model;         ///< model file, for learned descriptors
  std::string refine_model;  ///< XFeat*'s refinement network (xfeat-star)
};

/// Calls f(descriptor) with the Descriptor the choice names; every branch instantiates
/// f for one concrete type, so the per-feature work is statically dispatched.
template <class F>
decltype(auto) with_descriptor(const DescriptorChoice& c, F&& f) {
  if (c.name == "orb") return std::forward<F>(f)(OrbDescriptor({.features = c.features}));
  if (c.name == "akaze") return std::forward<F>(f)(AkazeDescriptor{});
  if (c.name == "sift") return std::forward<F>(f)(SiftDescriptor({.features = c.features}));
  if (c.name == "xfeat") {
    // A learned model is never looked up or downloaded: the user names the file.
    if (c.model.empty())
      usage_error("--features xfeat needs --model PATH (an XFeat ONNX export such as xfeat_320x224.onnx)");
    return std::forward<F>(f)(XFeatDescriptor({.model = c.model, .top_k = c.features}));
  }
  if (c.name == "xfeat-dense") {
    // Detector-free: every 1/8 cell of the image is a candidate (--nfeatures unused).
    if (c.model.empty())
      usage_error("--features xfeat-dense needs --model PATH (an XFeat ONNX export such as xfeat_anysize.onnx)");
    return std::forward<F>(f)(XFeatDenseDescriptor({.model = c.model}));
  }
  if (c.name == "xfeat-star") {
    // XFeat*: the dense grid, refined per pair by XFeat's fine network (estimator_for).
    if (c.model.empty())
      usage_error("--features xfeat-star needs --model PATH (an XFeat ONNX export such as xfeat_anysize.onnx)");
    if (c.refine_model.empty())
      usage_error("--features xfeat-star needs --refine-model PATH (XFeat*'s refinement network, xfeat_fine.onnx)");
    return std::forward<F>(f)(XFeatDenseDescriptor({.model = c.model, .grid = XFeatGrid::refinable}));
  }
  usage_error("--features: unknown descriptor '" + c.name +
              "' (choose orb, akaze, sift, xfeat, xfeat-dense or xfeat-star)");
}

/// The matcher that goes with a descriptor: mutual NN by brute force, or for XFeat's
/// dense grid the same mutual NN by blocked matrix products (thousands of candidates),
/// on unit copies of a refinable grid's raw descriptors.
template <class D>
auto matcher_for(const D& d) {
  if constexpr (std::is_same_v<D, XFeatDenseDescriptor>)
    return DenseMutualMatcher({.normalise = d.options().grid == XFeatGrid::refinable});
  else
    return BruteForceMatcher({.mode = MatchMode::mutual});
}

/// The estimator that goes with a descriptor: for XFeat's dense grid the estimator
/// behind XFeat*'s refinement (XFeatRefined, which passes straight through without a
/// refinement model, so xfeat-dense and xfeat-star share one instantiation), else the
/// estimator itself.
template <class D, class E>
auto estimator_for(const D&, const DescriptorChoice& c, const E& estimator) {
  if constexpr (std::is_same_v<D, XFeatDenseDescriptor>)
    return XFeatRefined<E>(c.name == "xfeat-star" ? std::optional<XFeatFineOptions>(XFeatFineOptions{.model = c.refine_model})
                                                  : std::nullopt,
                           estimator);
  else
    return estimator;
}

}  // namespace vmap::examples
