#pragma once

// One image pair through a policy stack: features of both, matches, the F-matrix and
// eq. 5's similarity (García-Pintos et al. 2023), with the time of each step. The
// quickest way to see whether two views share enough for a fundamental matrix
// (`vmap match`).
//
//   const vmap::PairCheck c = vmap::check_pair(vmap::PolicyStack{}, image_a, image_b);
//   std::printf("%d inliers, S = %.3f\n", c.verification.inliers, c.similarity);
//
// The estimator runs the homography degeneracy test (its report is part of the answer).

#include <vmap/core/features.hpp>
#include <vmap/core/verification.hpp>
#include <vmap/geometry/fundamental.hpp>
#include <vmap/geometry/similarity.hpp>
#include <vmap/runtime/policies.hpp>
#include <vmap/runtime/stack.hpp>

#include <opencv2/core.hpp>

#include <chrono>
#include <string>

namespace vmap {

struct PairCheckOptions {
  /// The F-matrix's inlier threshold: the largest distance to the epipolar line, pixels.
  double epipolar_px = 1.0;
};

/// What check_pair found, with the time of each step.
struct PairCheck {
  Features a{}, b{};
  Matches matches{};          ///< mutual nearest neighbours (the stack's matcher)
  Verification verification{};  ///< the F-matrix (E with a camera), its inliers and degeneracy
  double similarity = 0.0;    ///< eq. 5: inliers / max(|D_a|, |D_b|)
  double extract_seconds = 0.0, match_seconds = 0.0, verify_seconds = 0.0;

  [[nodiscard]] double seconds() const noexcept { return extract_seconds + match_seconds + verify_seconds; }
};

namespace detail {

/// check_pair for one descriptor type D. Defined apart so that a program linking
/// vmap::stacks instantiates none of it itself (see the end of this file).
template <class D>
struct PairFactory {
  static PairCheck check(D descriptor, const PolicyStack& stack, const cv::Mat& image_a, const cv::Mat& image_b,
                         const FundamentalOptions& options, const std::string& camera_name);
};

template <class D>
PairCheck PairFactory<D>::check(D descriptor, const PolicyStack& stack, const cv::Mat& image_a,
                                const cv::Mat& image_b, const FundamentalOptions& options,
                                const std::string& camera_name) {
  using clock = std::chrono::steady_clock;
  const auto seconds = [](clock::duration d) { return std::chrono::duration<double>(d).count(); };
  const auto matcher = matcher_for(descriptor);
  const auto estimator = estimator_for<D>(stack, options, camera_name);
  PairCheck c;
  const auto t0 = clock::now();
  c.a = descriptor.extract(image_a);
  c.b = descriptor.extract(image_b);
  const auto t1 = clock::now();
  c.matches = matcher.match(c.a, c.b);
  const auto t2 = clock::now();
  c.verification = estimator.verify(c.a, c.b, c.matches);
  const auto t3 = clock::now();
  c.similarity = InlierRatio{}(c.a, c.b, c.verification);
  c.extract_seconds = seconds(t1 - t0);
  c.match_seconds = seconds(t2 - t1);
  c.verify_seconds = seconds(t3 - t2);
  return c;
}

}  // namespace detail

/// Images a and b through the stack (see the top of this file). `camera_name` names the
/// stack's camera in errors (runtime/stack_choice.hpp).
[[nodiscard]] inline PairCheck check_pair(const PolicyStack& stack, const cv::Mat& image_a, const cv::Mat& image_b,
                                          const PairCheckOptions& options = {},
                                          const std::string& camera_name = "camera") {
  FundamentalOptions fo = detail::stack_fundamental_options(stack.method, true);
  fo.threshold_px = options.epipolar_px;
  return with_descriptor(stack, [&](auto descriptor) {
    return detail::PairFactory<decltype(descriptor)>::check(std::move(descriptor), stack, image_a, image_b, fo,
                                                            camera_name);
  });
}

}  // namespace vmap

// A program that links vmap::stacks compiles check_pair for the shipped descriptors
// once, there (runtime/detail/compiled_stacks.hpp).
#ifdef VMAP_COMPILED_STACKS
namespace vmap::detail {
extern template struct PairFactory<OrbDescriptor>;
extern template struct PairFactory<AkazeDescriptor>;
extern template struct PairFactory<SiftDescriptor>;
extern template struct PairFactory<XFeatDescriptor>;
extern template struct PairFactory<XFeatDenseDescriptor>;
}  // namespace vmap::detail
#endif
