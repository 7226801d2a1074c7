#pragma once

#include <vmap/core/concepts.hpp>
#include <vmap/core/error.hpp>
#include <vmap/core/names.hpp>
#include <vmap/core/numeric.hpp>
#include <vmap/geometry/detail/robust.hpp>
#include <vmap/geometry/robust_method.hpp>

#include <opencv2/calib3d.hpp>
#include <opencv2/core.hpp>

#include <cmath>
#include <cstdint>
#include <string>
#include <string_view>
#include <vector>

namespace vmap {

struct FundamentalOptions {
  RobustMethod method = RobustMethod::magsac;
  double threshold_px = 1.0;  ///< max. distance to the epipolar line, pixels (RANSAC/MAGSAC)
  double confidence = 0.99;   ///< desired probability of an all-inlier sample, in (0, 1)
  int max_iterations = 1000;  ///< OpenCV's default for findFundamentalMat
  int min_inliers = 8;        ///< floor below which the model is not trusted
  /// Fit a homography to the inliers and report Degeneracy::homography when it explains
  /// at least `degeneracy_ratio` of them (planar scene or pure rotation). Costs one
  /// homography RANSAC on the inliers (which, being mostly consistent, ends early).
  bool check_degeneracy = true;
  double degeneracy_ratio = 0.9;
  std::uint64_t seed = 0;  ///< 0: matches in the given order; otherwise a seeded shuffle
};

/// Fundamental-matrix verification: x_b^T F x_a = 0 for every inlier correspondence.
/// Fewer than 8 matches yields `too_few_matches` for every method: OpenCV 4.6's USAC
/// throws below 7 points and returns stacked 7-point solutions at exactly 7, so 8 is the
/// smallest count at which all methods return one model. Const and thread-safe.
class FundamentalEstimator {
 public:
  static constexpr int minimal_matches = 8;

  /// The name and every option (core/concepts.hpp, DescribesItself).
  [[nodiscard]] std::string describe() const {
    const FundamentalOptions& o = options_;
    return "FundamentalEstimator method=" + std::to_string(static_cast<int>(o.method)) + " threshold_px=" +
           exact_text(o.threshold_px) + " confidence=" + exact_text(o.confidence) + " max_iterations=" +
           std::to_string(o.max_iterations) + " min_inliers=" + std::to_string(o.min_inliers) +
           " check_degeneracy=" + (o.check_degeneracy ? "1" : "0") + " degeneracy_ratio=" +
           exact_text(o.degeneracy_ratio) + " seed=" + std::to_string(o.seed);
  }

  explicit FundamentalEstimator(const FundamentalOptions& options = {}) : options_(options) {
    detail::check_threshold_options(options_.threshold_px, options_.confidence, options_.max_iterations,
                                    options_.min_inliers, "FundamentalOptions");
    detail::check(
        std::isfinite(options_.degeneracy_ratio) && options_.degeneracy_ratio > 0 && options_.degeneracy_ratio <= 1,
        [&] {
          return "FundamentalOptions.degeneracy_ratio must be in (0, 1], got " +
                 std::to_string(options_.degeneracy_ratio);
        });
  }

  /// Buffers `verify_into` reuses between calls, so that verifying a stream of pairs
  /// does not allocate in vmap's own code once warm (OpenCV's estimators still
  /// allocate internally). One per thread.
  struct Scratch {
    std::vector<cv::Point2f> pa, pb, ia, ib;
    std::vector<int> order;
    cv::Mat mask, hmask;
  };

  [[nodiscard]] Verification verify(const Features& a, const Features& b, const Matches& matches) const {
    Verification v;
    Scratch scratch;
    verify_into(a, b, matches, v, scratch, false);
    return v;
  }

  /// `verify` into `v` (its inlier mask's capacity is kept), with the caller's buffers.
  /// With `defer_degeneracy`, the homography check of a verified pair is left out
  /// (v.degeneracy none, v.homography_inliers 0) and true is returned: the caller runs
  /// `complete_degeneracy` on the same inputs when it reads those two fields, and gets
  /// what `verify` would have reported. The key-image selector scores every frame but
  /// reads the degeneracy only when its state is saved.
  bool verify_into(const Features& a, const Features& b, const Matches& matches, Verification& v,
                   Scratch& scratch, bool defer_degeneracy) const {
    reset(v);
    v.matches = static_cast<int>(matches.size());
    if (v.matches < minimal_matches) return false;  // status: too_few_matches
    detail::gather_points(a, b, matches, options_.seed, scratch.pa, scratch.pb, scratch.order);
    cv::Mat F;
    try {
      F = cv::findFundamentalMat(scratch.pa, scratch.pb, opencv_method(), options_.threshold_px,
                                 options_.confidence, options_.max_iterations, scratch.mask);
    } catch (const cv::Exception&) {
      // OpenCV throws on inputs it cannot fit at all (e.g. every point identical):
      // an expected outcome for a verifier, reported as "no model".
      v.status = VerificationStatus::no_model;
      return false;
    }
    detail::fill_from_estimate(F, scratch.mask, scratch.order, options_.min_inliers, v);
    if (!v.ok() || !options_.check_degeneracy) return false;
    if (defer_degeneracy) return true;
    check_degeneracy(scratch, v);
    return false;
  }

  /// The homography check `verify_into(..., defer_degeneracy = true)` left out, on the
  /// same (a, b, matches) and its result `v`: sets v.degeneracy and v.homography_inliers
  /// exactly as `verify` does (same points in the same order, same seeded RANSAC).
  void complete_degeneracy(const Features& a, const Features& b, const Matches& matches, Verification& v) const {
    v.degeneracy = Degeneracy::none;
    v.homography_inliers = 0;
    if (!v.ok() || !options_.check_degeneracy) return;
    Scratch scratch;
    detail::gather_points(a, b, matches, options_.seed, scratch.pa, scratch.pb, scratch.order);
    check_degeneracy(scratch, v);
  }

  [[nodiscard]] const FundamentalOptions& options() const noexcept { return options_; }

 private:
  [[nodiscard]] int opencv_method() const noexcept {
    switch (options_.method) {
      case RobustMethod::magsac: return cv::USAC_MAGSAC;
      case RobustMethod::ransac: return cv::FM_RANSAC;
      case RobustMethod::lmeds: return cv::FM_LMEDS;
      case RobustMethod::eight_point: return cv::FM_8POINT;
    }
    return cv::USAC_MAGSAC;
  }

  static void reset(Verification& v) {
    v.status = VerificationStatus::too_few_matches;
    v.model = cv::Matx33d::zeros();
    v.inlier_mask.clear();
    v.inliers = 0;
    v.matches = 0;
    v.degeneracy = Degeneracy::none;
    v.homography_inliers = 0;
    v.relative_pose.reset();
  }

  /// Fits a homography to the model's inliers (scratch.pa/pb in scratch.order).
  void check_degeneracy(Scratch& scratch, Verification& v) const {
    const std::vector<cv::Point2f>& pa = scratch.pa;
    const std::vector<cv::Point2f>& pb = scratch.pb;
    const std::vector<int>& order = scratch.order;
    std::vector<cv::Point2f>& ia = scratch.ia;
    std::vector<cv::Point2f>& ib = scratch.ib;
    ia.clear();
    ib.clear();
    ia.reserve(static_cast<std::size_t>(v.inliers));
    ib.reserve(static_cast<std::size_t>(v.inliers));
    for (std::size_t k = 0; k < order.size(); ++k)
      if (v.inlier_mask[static_cast<std::size_t>(order[k])] != 0) {
        ia.push_back(pa[k]);
        ib.push_back(pb[k]);
      }
    if (ia.size() < 4) return;
    cv::Mat& hmask = scratch.hmask;
    cv::Mat H;
    try {
      // The homography's error is a 2-D transfer distance where F's is a 1-D distance to
      // a line: twice the threshold keeps the same share of noisy inliers (chi-square
      // 95 % bounds 5.99 vs 3.84 at unit noise, as ORB-SLAM's initializer uses).
      H = cv::findHomography(ia, ib, cv::RANSAC, 2.0 * options_.threshold_px, hmask, 2000, options_.confidence);
    } catch (const cv::Exception&) {
      return;  // no homography fits: certainly not degenerate
    }
    if (H.empty()) return;
    v.homography_inliers = cv::countNonZero(hmask);
    if (v.homography_inliers >= options_.degeneracy_ratio * v.inliers) v.degeneracy = Degeneracy::homography;
  }

  FundamentalOptions options_;
};

static_assert(Estimator<FundamentalEstimator>);

}  // namespace vmap
