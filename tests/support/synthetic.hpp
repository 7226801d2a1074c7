#pragma once

// Synthetic two-view scenes with known geometry: 3-D points seen by two pinhole cameras
// with known K, R, t, returned as Features + Matches so the real estimators run on them.

#include <vmap/core/features.hpp>

#include <opencv2/calib3d.hpp>
#include <opencv2/core.hpp>

#include <cmath>
#include <cstdint>
#include <vector>

namespace vmap::test {

struct TwoViewScene {
  Features a, b;
  Matches matches;
  std::vector<std::uint8_t> is_inlier;  ///< ground truth per match
  cv::Matx33d F_true;                   ///< the true fundamental matrix (x_b^T F x_a = 0)
  cv::Matx33d K;
};

enum class SceneKind { general, planar, pure_rotation };

struct SceneOptions {
  int points = 400;
  double outlier_fraction = 0.3;
  double noise_px = 0.3;
  SceneKind kind = SceneKind::general;
  std::uint64_t seed = 1;
};

inline cv::Matx33d skew(const cv::Vec3d& t) {
  return {0, -t[2], t[1], t[2], 0, -t[0], -t[1], t[0], 0};
}

/// Camera a at the origin; camera b rotated by R and displaced by t (x_b = R x_a + t).
/// General scenes have depths spread over 2..12 m; planar ones lie on a slanted plane;
/// a pure rotation has t = 0. Outliers are random pixel pairs inside both images.
inline TwoViewScene make_two_view_scene(const SceneOptions& o) {
  cv::RNG rng(o.seed);
  TwoViewScene s;
  s.K = cv::Matx33d(525, 0, 320, 0, 525, 240, 0, 0, 1);
  cv::Vec3d rvec(0.02, -0.08, 0.03);
  cv::Matx33d R;
  cv::Rodrigues(rvec, R);
  const cv::Vec3d t = o.kind == SceneKind::pure_rotation ? cv::Vec3d(0, 0, 0) : cv::Vec3d(0.5, 0.05, 0.1);
  const cv::Matx33d Kinv = s.K.inv();
  s.F_true = Kinv.t() * skew(t) * R * Kinv;
  s.a.image_size = s.b.image_size = cv::Size(640, 480);
  s.a.norm = s.b.norm = cv::NORM_HAMMING;
  auto project = [&](const cv::Vec3d& X) {
    const cv::Vec3d x = s.K * X;
    return cv::Point2f(static_cast<float>(x[0] / x[2]), static_cast<float>(x[1] / x[2]));
  };
  auto inside = [](const cv::Point2f& p) { return p.x >= 0 && p.x < 640 && p.y >= 0 && p.y < 480; };
  const int n_out = static_cast<int>(std::lround(o.points * o.outlier_fraction));
  const int n_in = o.points - n_out;
  int made = 0;
  while (made < n_in) {
    const double u = rng.uniform(0.0, 640.0), v = rng.uniform(0.0, 480.0);
    double depth = rng.uniform(2.0, 12.0);
    const cv::Vec3d ray = Kinv * cv::Vec3d(u, v, 1.0);
    if (o.kind == SceneKind::planar) {
      // Plane n.X = d with n = (0.2, -0.1, 1), d = 5: depth along the ray solves n.(z ray) = d.
      const cv::Vec3d n(0.2, -0.1, 1.0);
      depth = 5.0 / n.dot(ray);
    }
    const cv::Vec3d Xa = ray * depth;
    const cv::Vec3d Xb = R * Xa + t;
    if (Xb[2] <= 0.1) continue;
    cv::Point2f pa = project(Xa), pb = project(Xb);
    if (!inside(pb)) continue;
    pa += cv::Point2f(static_cast<float>(rng.gaussian(o.noise_px)), static_cast<float>(rng.gaussian(o.noise_px)));
    pb += cv::Point2f(static_cast<float>(rng.gaussian(o.noise_px)), static_cast<float>(rng.gaussian(o.noise_px)));
    s.a.keypoints.emplace_back(pa, 7.0f);
    s.b.keypoints.emplace_back(pb, 7.0f);
    s.is_inlier.push_back(1);
    ++made;
  }
  for (int k = 0; k < n_out; ++k) {
    s.a.keypoints.emplace_back(cv::Point2f(rng.uniform(0.f, 640.f), rng.uniform(0.f, 480.f)), 7.0f);
    s.b.keypoints.emplace_back(cv::Point2f(rng.uniform(0.f, 640.f), rng.uniform(0.f, 480.f)), 7.0f);
    s.is_inlier.push_back(0);
  }
  const int n = static_cast<int>(s.a.keypoints.size());
  s.a.descriptors = cv::Mat(n, 32, CV_8U);
  rng.fill(s.a.descriptors, cv::RNG::UNIFORM, 0, 256);
  s.b.descriptors = s.a.descriptors.clone();
  for (int i = 0; i < n; ++i) s.matches.emplace_back(i, i, 0.0f);
  return s;
}

/// Mean symmetric epipolar distance (pixels) of the true inlier correspondences under F.
inline double mean_epipolar_error(const TwoViewScene& s, const cv::Matx33d& F) {
  double sum = 0;
  int n = 0;
  for (std::size_t i = 0; i < s.matches.size(); ++i) {
    if (!s.is_inlier[i]) continue;
    const cv::Point2f& p = s.a.keypoints[i].pt;
    const cv::Point2f& q = s.b.keypoints[i].pt;
    const cv::Vec3d x(p.x, p.y, 1), y(q.x, q.y, 1);
    const cv::Vec3d l2 = F * x, l1 = F.t() * y;
    const double e = std::abs(y.dot(l2));
    sum += 0.5 * (e / std::hypot(l2[0], l2[1]) + e / std::hypot(l1[0], l1[1]));
    ++n;
  }
  return n ? sum / n : 0.0;
}

}  // namespace vmap::test
