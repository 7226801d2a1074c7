#pragma once

// Synthetic two-view scenes seen through a real lens: 3-D points with a known relative
// pose projected through a radial-tangential or fisheye camera (cv::projectPoints /
// cv::fisheye::projectPoints), and the same correspondences as an ideal pinhole with
// the same K would have seen them. Shared by tests/unit/geometry and
// examples/bench/bench_camera.cpp.

#include <vmap/core/features.hpp>
#include <vmap/core/verification.hpp>
#include <vmap/geometry/camera.hpp>

#include <opencv2/calib3d.hpp>
#include <opencv2/core.hpp>

#include <algorithm>
#include <cmath>
#include <cstdint>
#include <vector>

namespace vmap::test {

/// A 640 x 480 equidistant fisheye with about 160 degrees across the image width
/// (r = f * theta: 320 px at 80 degrees), like the IMX219 160-degree lens of small robots.
inline Camera wide_fisheye_camera() {
  return {.lens = LensModel::fisheye,
          .fx = 230.0,
          .fy = 230.0,
          .cx = 320.0,
          .cy = 240.0,
          .distortion = {-0.02, 0.004, -0.001, 0.0002},
          .image_size = {640, 480}};
}

/// A 640 x 480 wide-angle pinhole with strong barrel distortion (about 110 degrees
/// across), monotonic over the whole image.
inline Camera wide_radtan_camera() {
  return {.lens = LensModel::pinhole,
          .fx = 300.0,
          .fy = 300.0,
          .cx = 320.0,
          .cy = 240.0,
          .distortion = {-0.30, 0.10, 0.001, -0.0005, 0.0},
          .image_size = {640, 480}};
}

struct LensSceneOptions {
  int points = 600;                ///< attempted 3-D points (those outside either image are dropped)
  double outlier_fraction = 0.25;  ///< extra random pixel pairs, as a share of the visible points
  double noise_px = 0.3;           ///< Gaussian noise on every inlier pixel (both images)
  double max_angle_deg = 75.0;     ///< points up to this angle from either optical axis
  bool planar = false;             ///< all points on one slanted plane (a homography explains them)
  std::uint64_t seed = 1;
};

struct LensScene {
  Features a, b;
  Matches matches;
  std::vector<std::uint8_t> is_inlier;  ///< ground truth per match
  cv::Matx33d R;                        ///< x_b = R x_a + t
  cv::Vec3d t;
  int true_inliers = 0;
};

/// Camera a at the origin, camera b rotated by 10 degrees (mostly about y) and moved
/// 0.4 m. With `ideal` the same points and outliers are given as the ideal pinhole with
/// the camera's K sees them (no distortion, unbounded image): the reference that a
/// perfect undistortion would reach.
inline LensScene make_lens_scene(const Camera& cam, const LensSceneOptions& o, bool ideal = false) {
  cv::RNG rng(o.seed);
  LensScene s;
  const cv::Vec3d rvec(0.03, -0.17, 0.02);
  cv::Rodrigues(rvec, s.R);
  s.t = cv::Vec3d(0.35, 0.05, 0.15);
  const double max_angle = o.max_angle_deg * CV_PI / 180.0;
  const cv::Mat K(cam.K());
  const cv::Mat D = detail::distortion_mat(cam);
  auto project = [&](const std::vector<cv::Point3d>& X, const cv::Vec3d& r, const cv::Vec3d& t, bool undistorted) {
    std::vector<cv::Point2d> px;
    if (X.empty()) return px;
    if (undistorted)
      cv::projectPoints(X, r, t, K, cv::noArray(), px);
    else if (cam.lens == LensModel::fisheye)
      cv::fisheye::projectPoints(X, px, r, t, K, D);
    else
      cv::projectPoints(X, r, t, K, D, px);
    return px;
  };
  // Rays spread over the field of view (uniform in angle and azimuth), depths 2..8 m.
  std::vector<cv::Point3d> X;
  for (int i = 0; i < o.points; ++i) {
    const double theta = rng.uniform(0.0, max_angle);
    const double phi = rng.uniform(0.0, 2 * CV_PI);
    double depth = rng.uniform(2.0, 8.0);
    const cv::Vec3d ray(std::sin(theta) * std::cos(phi), std::sin(theta) * std::sin(phi), std::cos(theta));
    if (o.planar) {
      // The plane n.X = 3 with n = (0.1, -0.1, 1): rays that miss it in front are skipped.
      const double along = ray.dot(cv::Vec3d(0.1, -0.1, 1.0));
      if (along < 0.2) continue;
      depth = 3.0 / along;
    }
    X.emplace_back(ray * depth);
  }
  const auto real_a = project(X, cv::Vec3d(0, 0, 0), cv::Vec3d(0, 0, 0), false);
  const auto real_b = project(X, rvec, s.t, false);
  const auto ideal_a = project(X, cv::Vec3d(0, 0, 0), cv::Vec3d(0, 0, 0), true);
  const auto ideal_b = project(X, rvec, s.t, true);
  const cv::Rect2d image(0, 0, cam.image_size.width, cam.image_size.height);
  auto add = [&](cv::Point2d pa, cv::Point2d pb, bool inlier) {
    const int i = static_cast<int>(s.a.keypoints.size());
    s.a.keypoints.emplace_back(cv::Point2f(static_cast<float>(pa.x), static_cast<float>(pa.y)), 7.f);
    s.b.keypoints.emplace_back(cv::Point2f(static_cast<float>(pb.x), static_cast<float>(pb.y)), 7.f);
    s.matches.emplace_back(i, i, 0.f);
    s.is_inlier.push_back(inlier ? 1 : 0);
    s.true_inliers += inlier ? 1 : 0;
  };
  for (std::size_t i = 0; i < X.size(); ++i) {
    const cv::Vec3d xa(X[i].x, X[i].y, X[i].z);
    const cv::Vec3d xb = s.R * xa + s.t;
    const double angle_b = std::acos(xb[2] / cv::norm(xb));
    // Noise is drawn for every point so that both variants consume the same numbers.
    const cv::Point2d na(rng.gaussian(o.noise_px), rng.gaussian(o.noise_px));
    const cv::Point2d nb(rng.gaussian(o.noise_px), rng.gaussian(o.noise_px));
    if (xb[2] <= 0 || angle_b > max_angle || !image.contains(real_a[i]) || !image.contains(real_b[i])) continue;
    if (ideal)
      add(ideal_a[i] + na, ideal_b[i] + nb, true);
    else
      add(real_a[i] + na, real_b[i] + nb, true);
  }
  // Outliers: random pixel pairs of the real image; the ideal variant gets the same
  // pixels undistorted, so both variants hold the same wrong correspondences.
  const int n_out = static_cast<int>(std::lround(s.true_inliers * o.outlier_fraction));
  std::vector<cv::Point2f> oa, ob;
  for (int k = 0; k < n_out; ++k) {
    oa.emplace_back(rng.uniform(0.f, static_cast<float>(image.width)), rng.uniform(0.f, static_cast<float>(image.height)));
    ob.emplace_back(rng.uniform(0.f, static_cast<float>(image.width)), rng.uniform(0.f, static_cast<float>(image.height)));
  }
  if (ideal) {
    oa = undistort_points(cam, oa);
    ob = undistort_points(cam, ob);
  }
  for (int k = 0; k < n_out; ++k) add(oa[static_cast<std::size_t>(k)], ob[static_cast<std::size_t>(k)], false);
  s.a.image_size = s.b.image_size = cam.image_size;
  return s;
}

/// Angle of the rotation R_est^T R_true, degrees.
inline double rotation_error_deg(const cv::Matx33d& R_est, const cv::Matx33d& R_true) {
  const double c = std::clamp((cv::trace(R_est.t() * R_true) - 1.0) / 2.0, -1.0, 1.0);
  return std::acos(c) * 180.0 / CV_PI;
}

/// Angle between two translation directions, degrees (sign included: t and -t are 180).
inline double direction_error_deg(const cv::Vec3d& t_est, const cv::Vec3d& t_true) {
  const double c = std::clamp(t_est.dot(t_true) / (cv::norm(t_est) * cv::norm(t_true)), -1.0, 1.0);
  return std::acos(c) * 180.0 / CV_PI;
}

/// The pose implied by an F of ideal pixels: E = K^T F K, recoverPose on the inliers.
inline RelativePose pose_from_f(const LensScene& s, const Camera& cam, const Verification& v, bool points_are_ideal) {
  std::vector<cv::Point2f> pa, pb;
  for (std::size_t k = 0; k < s.matches.size(); ++k)
    if (v.inlier_mask[k]) {
      pa.push_back(s.a.keypoints[k].pt);
      pb.push_back(s.b.keypoints[k].pt);
    }
  Camera pin = cam;
  if (points_are_ideal) {
    pin.lens = LensModel::pinhole;
    pin.distortion.clear();
  }
  const auto na = normalize_points(pin, pa);
  const auto nb = normalize_points(pin, pb);
  cv::Mat R, t;
  cv::recoverPose(cv::Mat(cam.K().t() * v.model * cam.K()), na, nb, cv::Mat::eye(3, 3, CV_64F), R, t);
  RelativePose p;
  for (int r = 0; r < 3; ++r) {
    for (int c = 0; c < 3; ++c) p.rotation(r, c) = R.at<double>(r, c);
    p.translation[r] = t.at<double>(r, 0);
  }
  return p;
}

}  // namespace vmap::test
