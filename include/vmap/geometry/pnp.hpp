#pragma once

// A camera's pose from 2D-3D correspondences (the perspective-n-point problem): calib3d's
// robust PnP with its USAC framework (cv::solvePnPRansac with UsacParams: P3P minimal
// samples scored by MAGSAC++, Barath et al., CVPR 2020), then Levenberg-Marquardt on the
// inliers (cv::solvePnPRefineLM), and the covariance of the refined pose from the
// refinement's Jacobian (Hartley & Zisserman, sec. 5.2.3: Sigma = sigma^2 (J^T J)^-1, with
// sigma^2 the inliers' residual variance). The points are given in ideal pixels
// (undistorted, geometry/camera.hpp's undistort_points), so the camera is its K alone.

#include <vmap/core/error.hpp>
#include <vmap/geometry/metric_pose.hpp>

#include <opencv2/calib3d.hpp>
#include <opencv2/core.hpp>
#include <opencv2/core/affine.hpp>

#include <cmath>
#include <cstddef>
#include <cstdint>
#include <limits>
#include <optional>
#include <utility>
#include <vector>

namespace vmap {

struct PnpOptions {
  double threshold_px = 2.0;  ///< an inlier reprojects within this many pixels (ideal image)
  double confidence = 0.999;  ///< of the robust search
  int max_iterations = 1000;  ///< of the robust search
  std::uint64_t seed = 0;     ///< the robust search's random state
};

/// What solve_pnp found: a pose or nothing (fewer than 4 points, or no model).
struct PnpResult {
  bool found = false;
  cv::Affine3d camera_to_world = cv::Affine3d::Identity();
  std::vector<std::uint8_t> inlier_mask;  ///< one entry per correspondence, 1 = inlier
  int inliers = 0;
  double rms_px = 0.0;  ///< over the inliers
  /// Position and world-frame rotation vector (MetricPose::covariance); zeros with fewer
  /// than 4 inliers (no residual degree of freedom left).
  cv::Matx66d covariance = cv::Matx66d::zeros();
};

namespace detail {

inline void check_pnp_options(const PnpOptions& o) {
  check(std::isfinite(o.threshold_px) && o.threshold_px > 0, "PnpOptions.threshold_px must be > 0");
  check(std::isfinite(o.confidence) && o.confidence > 0 && o.confidence < 1, "PnpOptions.confidence must be in (0, 1)");
  check(o.max_iterations >= 1, "PnpOptions.max_iterations must be >= 1");
}

/// Camera-to-world of a calib3d pose (rvec, tvec: world to camera).
inline cv::Affine3d camera_to_world_of(const cv::Vec3d& rvec, const cv::Vec3d& tvec) {
  return cv::Affine3d(rvec, tvec).inv();
}

/// The pose's position and world-frame rotation vector as functions of (rvec, tvec),
/// differentiated numerically (central differences) at the estimate: the Jacobian that
/// carries the refinement's covariance over to MetricPose::covariance.
inline cv::Matx66d pose_jacobian(const cv::Vec3d& rvec, const cv::Vec3d& tvec) {
  const cv::Affine3d at = camera_to_world_of(rvec, tvec);
  const cv::Matx33d r0t = at.rotation().t();
  const auto value = [&](const cv::Vec3d& r, const cv::Vec3d& t) {
    const cv::Affine3d p = camera_to_world_of(r, t);
    // The rotation vector of the small rotation between the two (its skew part: exact to
    // third order; cv::Rodrigues rounds rotations below 1e-5 rad to none).
    const cv::Matx33d d = p.rotation() * r0t;
    const cv::Vec3d w(0.5 * (d(2, 1) - d(1, 2)), 0.5 * (d(0, 2) - d(2, 0)), 0.5 * (d(1, 0) - d(0, 1)));
    const cv::Vec3d c = p.translation();
    return cv::Vec<double, 6>(c[0], c[1], c[2], w[0], w[1], w[2]);
  };
  cv::Matx66d J;
  constexpr double h = 1e-6;
  for (int k = 0; k < 6; ++k) {
    cv::Vec3d r1 = rvec, r2 = rvec, t1 = tvec, t2 = tvec;
    if (k < 3) {
      r1[k] += h;
      r2[k] -= h;
    } else {
      t1[k - 3] += h;
      t2[k - 3] -= h;
    }
    const cv::Vec<double, 6> d = (value(r1, t1) - value(r2, t2)) * (1.0 / (2 * h));
    for (int i = 0; i < 6; ++i) J(i, k) = d[i];
  }
  return J;
}

/// Residual of each correspondence under (rvec, tvec), pixels.
inline std::vector<double> pnp_residuals(const std::vector<cv::Point3d>& world, const std::vector<cv::Point2d>& pixels,
                                         const cv::Matx33d& K, const cv::Vec3d& rvec, const cv::Vec3d& tvec) {
  std::vector<cv::Point2d> projected;
  cv::projectPoints(world, rvec, tvec, cv::Mat(K), cv::noArray(), projected);
  std::vector<double> r(world.size());
  for (std::size_t i = 0; i < r.size(); ++i) {
    const cv::Point2d d = projected[i] - pixels[i];
    r[i] = std::sqrt(d.dot(d));
  }
  return r;
}

}  // namespace detail

/// The pose of the camera that sees `world[i]` at `pixels[i]` (ideal pixels of camera
/// matrix K). Deterministic for the same input and seed.
[[nodiscard]] inline PnpResult solve_pnp(const std::vector<cv::Point3d>& world, const std::vector<cv::Point2d>& pixels,
                                         const cv::Matx33d& K, const PnpOptions& options = {}) {
  detail::check_pnp_options(options);
  detail::check(world.size() == pixels.size(), "solve_pnp: one pixel per 3D point");
  PnpResult out;
  const std::size_t n = world.size();
  if (n < 4) return out;
  cv::UsacParams p;
  p.threshold = options.threshold_px;
  p.confidence = options.confidence;
  p.maxIterations = options.max_iterations;
  p.randomGeneratorState = static_cast<int>(options.seed & 0x7fffffff);
  p.score = cv::SCORE_METHOD_MAGSAC;
  p.sampler = cv::SAMPLING_UNIFORM;
  p.loMethod = cv::LOCAL_OPTIM_INNER_AND_ITER_LO;
  p.isParallel = false;
  cv::Mat Kmat(K);
  cv::Vec3d rvec, tvec;
  std::vector<int> found;
  try {
    if (!cv::solvePnPRansac(world, pixels, Kmat, cv::noArray(), rvec, tvec, found, p)) return out;
  } catch (const cv::Exception&) {
    return out;  // degenerate points: no model, an expected outcome
  }
  if (found.size() < 4) return out;
  // Levenberg-Marquardt on the inliers, then the inliers of the refined pose, refined once
  // more when they changed.
  std::vector<std::uint8_t> mask(n, 0);
  for (int i : found)
    if (i >= 0 && static_cast<std::size_t>(i) < n) mask[static_cast<std::size_t>(i)] = 1;
  const auto subset = [&](const std::vector<std::uint8_t>& m, std::vector<cv::Point3d>& w, std::vector<cv::Point2d>& x) {
    w.clear();
    x.clear();
    for (std::size_t i = 0; i < n; ++i)
      if (m[i]) {
        w.push_back(world[i]);
        x.push_back(pixels[i]);
      }
  };
  std::vector<cv::Point3d> w;
  std::vector<cv::Point2d> x;
  for (int round = 0; round < 2; ++round) {
    subset(mask, w, x);
    if (w.size() < 4) return out;
    try {
      cv::solvePnPRefineLM(w, x, Kmat, cv::noArray(), rvec, tvec);
    } catch (const cv::Exception&) {
      return out;
    }
    const std::vector<double> r = detail::pnp_residuals(world, pixels, K, rvec, tvec);
    std::vector<std::uint8_t> next(n, 0);
    for (std::size_t i = 0; i < n; ++i) next[i] = std::isfinite(r[i]) && r[i] <= options.threshold_px ? 1 : 0;
    if (next == mask) break;
    mask = std::move(next);
  }
  subset(mask, w, x);
  if (w.size() < 4 || !std::isfinite(rvec[0] + rvec[1] + rvec[2] + tvec[0] + tvec[1] + tvec[2])) return out;
  out.found = true;
  out.camera_to_world = detail::camera_to_world_of(rvec, tvec);
  out.inlier_mask = mask;
  out.inliers = static_cast<int>(w.size());
  const std::vector<double> r = detail::pnp_residuals(w, x, K, rvec, tvec);
  double ss = 0.0;
  for (double v : r) ss += v * v;
  out.rms_px = std::sqrt(ss / static_cast<double>(r.size()));
  // sigma^2 (J^T J)^-1 over (rvec, tvec): 2N residuals, 6 parameters.
  cv::Mat projected, jacobian;
  cv::projectPoints(w, rvec, tvec, Kmat, cv::noArray(), projected, jacobian);
  const cv::Mat J = jacobian.colRange(0, 6);
  const double dof = 2.0 * static_cast<double>(w.size()) - 6.0;
  const double sigma2 = ss / dof;
  cv::Mat JtJ = J.t() * J, inv;
  if (cv::invert(JtJ, inv, cv::DECOMP_CHOLESKY) == 0) cv::invert(JtJ, inv, cv::DECOMP_SVD);
  cv::Matx66d cov_rt;
  for (int i = 0; i < 6; ++i)
    for (int j = 0; j < 6; ++j) cov_rt(i, j) = sigma2 * inv.at<double>(i, j);
  const cv::Matx66d G = detail::pose_jacobian(rvec, tvec);
  out.covariance = G * cov_rt * G.t();
  return out;
}

}  // namespace vmap
