#pragma once

// Shared plumbing of the two-view estimators: point gathering, seeded ordering, and
// turning an OpenCV estimate into a Verification value.

#include <vmap/core/error.hpp>
#include <vmap/core/features.hpp>
#include <vmap/core/verification.hpp>

#include <opencv2/calib3d.hpp>
#include <opencv2/core.hpp>

#include <cmath>
#include <cstdint>
#include <string>
#include <vector>

namespace vmap::detail {

/// Points of the matches, optionally visited in a seeded random order. OpenCV's robust
/// estimators draw their samples from a generator with a fixed state, so they are
/// deterministic but give every caller the same draws; permuting the input by a seed
/// gives independent, still reproducible, runs (seed 0 keeps the given order).
inline void gather_points(const Features& a, const Features& b, const Matches& m, std::uint64_t seed,
                          std::vector<cv::Point2f>& pa, std::vector<cv::Point2f>& pb,
                          std::vector<int>& order) {
  const auto n = m.size();
  order.resize(n);
  for (std::size_t i = 0; i < n; ++i) order[i] = static_cast<int>(i);
  if (seed != 0) {
    cv::RNG rng(seed);
    for (std::size_t i = n; i > 1; --i) std::swap(order[i - 1], order[rng.uniform(0, static_cast<int>(i))]);
  }
  pa.resize(n);
  pb.resize(n);
  const auto na = a.keypoints.size();
  const auto nb = b.keypoints.size();
  for (std::size_t k = 0; k < n; ++k) {
    const cv::DMatch& d = m[static_cast<std::size_t>(order[k])];
    if (d.queryIdx < 0 || static_cast<std::size_t>(d.queryIdx) >= na || d.trainIdx < 0 ||
        static_cast<std::size_t>(d.trainIdx) >= nb)
      fail("geometric verification: match " + std::to_string(order[k]) + " refers to keypoint (" +
           std::to_string(d.queryIdx) + ", " + std::to_string(d.trainIdx) + ") outside the Features (" +
           std::to_string(na) + ", " + std::to_string(nb) + " keypoints)");
    pa[k] = a.keypoints[static_cast<std::size_t>(d.queryIdx)].pt;
    pb[k] = b.keypoints[static_cast<std::size_t>(d.trainIdx)].pt;
  }
}

inline void check_threshold_options(double threshold_px, double confidence, int max_iterations,
                                     int min_inliers, const char* who) {
  const std::string w(who);
  check(std::isfinite(threshold_px) && threshold_px > 0,
        [&] { return w + ".threshold_px must be a finite number > 0, got " + std::to_string(threshold_px); });
  check(std::isfinite(confidence) && confidence > 0 && confidence < 1,
        [&] { return w + ".confidence must be in (0, 1), got " + std::to_string(confidence); });
  check(max_iterations > 0, [&] { return w + ".max_iterations must be > 0, got " + std::to_string(max_iterations); });
  check(min_inliers >= 0, [&] { return w + ".min_inliers must be >= 0, got " + std::to_string(min_inliers); });
}

/// Fills `v` from an OpenCV model and mask computed on permuted points.
inline void fill_from_estimate(const cv::Mat& model, const cv::Mat& mask, const std::vector<int>& order,
                               int min_inliers, Verification& v) {
  if (model.rows != 3 || model.cols != 3) {
    // Empty: no model. More rows: several 7-point solutions, which only happens at the
    // minimal sample and means the data did not decide between them.
    v.status = VerificationStatus::no_model;
    return;
  }
  // OpenCV's estimators return CV_64F: read it in place (no conversion buffer per call).
  if (model.type() == CV_64FC1) {
    for (int r = 0; r < 3; ++r)
      for (int c = 0; c < 3; ++c) v.model(r, c) = model.at<double>(r, c);
  } else {
    cv::Mat m64;
    model.convertTo(m64, CV_64F);
    for (int r = 0; r < 3; ++r)
      for (int c = 0; c < 3; ++c) v.model(r, c) = m64.at<double>(r, c);
  }
  if (!std::isfinite(cv::norm(v.model))) {
    v.status = VerificationStatus::no_model;
    v.model = cv::Matx33d::zeros();
    return;
  }
  v.inlier_mask.assign(order.size(), 0);
  v.inliers = 0;
  const bool have_mask = !mask.empty() && mask.total() == order.size();
  for (std::size_t k = 0; k < order.size(); ++k) {
    const bool in = have_mask ? mask.ptr<std::uint8_t>()[k] != 0 : true;
    if (in) {
      v.inlier_mask[static_cast<std::size_t>(order[k])] = 1;
      ++v.inliers;
    }
  }
  v.status = v.inliers >= min_inliers ? VerificationStatus::verified : VerificationStatus::too_few_inliers;
}

/// cv::recoverPose's R (3x3) and t (3x1), both CV_64F, as a RelativePose.
inline RelativePose relative_pose_of(const cv::Mat& R, const cv::Mat& t, int points_in_front) {
  RelativePose p;
  for (int r = 0; r < 3; ++r) {
    for (int c = 0; c < 3; ++c) p.rotation(r, c) = R.at<double>(r, c);
    p.translation[r] = t.at<double>(r, 0);
  }
  p.points_in_front = points_in_front;
  return p;
}

}  // namespace vmap::detail
