#pragma once

// Points seen by two cameras whose poses are known (camera-to-world), triangulated by
// calib3d's linear method (cv::triangulatePoints: the DLT of Hartley & Zisserman, sec.
// 12.2) and kept only where the two views support them: in front of both cameras,
// reprojected within a threshold in both, and seen under a parallax angle that fixes
// their depth. A camera that turned on the spot sees every point under no parallax: no
// point, and the count of those refused for it says why.

#include <vmap/core/error.hpp>

#include <opencv2/calib3d.hpp>
#include <opencv2/core.hpp>
#include <opencv2/core/affine.hpp>

#include <algorithm>
#include <cmath>
#include <cstddef>
#include <cstdint>
#include <limits>
#include <numbers>
#include <vector>

namespace vmap {

struct TriangulationOptions {
  /// A point must reproject within this many pixels (ideal image) in both views.
  double max_reprojection_px = 2.0;
  /// The angle between the two viewing rays at the point, degrees: below it the depth is
  /// not fixed (a 1 px error moves a point at 1 degree of parallax by a tenth of its
  /// depth at a 500 px focal length).
  double min_parallax_deg = 1.0;
};

/// What became of one correspondence.
enum class PointStatus : std::uint8_t {
  triangulated,   ///< a point: in front of both, reprojected, enough parallax
  low_parallax,   ///< the rays are (nearly) parallel: no depth
  behind,         ///< behind one of the cameras
  off_the_rays,   ///< reprojects beyond the threshold in a view (a wrong match, or wrong poses)
};

struct TriangulatedPoint {
  PointStatus status = PointStatus::low_parallax;
  cv::Point3d world;            ///< valid when triangulated
  double parallax_deg = 0.0;    ///< angle between the two rays at the point
  double error_px = 0.0;        ///< the larger reprojection error of the two views
};

namespace detail {

inline void check_triangulation_options(const TriangulationOptions& o) {
  check(std::isfinite(o.max_reprojection_px) && o.max_reprojection_px > 0,
        "TriangulationOptions.max_reprojection_px must be > 0");
  check(std::isfinite(o.min_parallax_deg) && o.min_parallax_deg >= 0 && o.min_parallax_deg < 90,
        "TriangulationOptions.min_parallax_deg must be in [0, 90)");
}

/// The 3x4 world-to-camera projection of a camera-to-world pose (normalised image).
inline cv::Matx34d world_to_camera(const cv::Affine3d& camera_to_world) {
  const cv::Affine3d w = camera_to_world.inv();
  const cv::Matx33d R = w.rotation();
  const cv::Vec3d t = w.translation();
  return {R(0, 0), R(0, 1), R(0, 2), t[0], R(1, 0), R(1, 1), R(1, 2), t[1], R(2, 0), R(2, 1), R(2, 2), t[2]};
}

}  // namespace detail

/// The parallax of a correspondence: the angle, in degrees, between the viewing rays of
/// normalised image points `a` (camera `a_to_world`) and `b` (camera `b_to_world`) in the
/// world. For a correct match it is the angle at the point, and it does not depend on
/// where along the rays the point lies, so it is known before the point is triangulated.
[[nodiscard]] inline double parallax_deg(const cv::Affine3d& a_to_world, const cv::Point2d& a,
                                         const cv::Affine3d& b_to_world, const cv::Point2d& b) {
  const cv::Vec3d ra = a_to_world.rotation() * cv::Vec3d(a.x, a.y, 1.0);
  const cv::Vec3d rb = b_to_world.rotation() * cv::Vec3d(b.x, b.y, 1.0);
  const double cosine = std::clamp(ra.dot(rb) / std::sqrt(ra.dot(ra) * rb.dot(rb)), -1.0, 1.0);
  return std::acos(cosine) * 180.0 / std::numbers::pi;
}

/// Points seen at normalised image coordinates `a[i]` by camera `a_to_world` and `b[i]`
/// by camera `b_to_world` (geometry/camera.hpp's normalize_points), one outcome each.
/// `focal` (pixels) turns normalised errors into pixels.
[[nodiscard]] inline std::vector<TriangulatedPoint> triangulate_posed(const cv::Affine3d& a_to_world,
                                                                      const std::vector<cv::Point2d>& a,
                                                                      const cv::Affine3d& b_to_world,
                                                                      const std::vector<cv::Point2d>& b, double focal,
                                                                      const TriangulationOptions& options = {}) {
  detail::check_triangulation_options(options);
  detail::check(a.size() == b.size(), "triangulate_posed: one point of b per point of a");
  detail::check(std::isfinite(focal) && focal > 0, "triangulate_posed: the focal length must be > 0");
  std::vector<TriangulatedPoint> out(a.size());
  // The parallax first (parallax_deg): it tells a camera that only turned (parallel rays,
  // a point anywhere along them) from a wrong match (rays that miss each other), and only
  // the correspondences with enough of it are triangulated (calib3d's DLT solves an SVD
  // per point).
  std::vector<std::size_t> at;
  std::vector<cv::Point2d> ka, kb;
  for (std::size_t i = 0; i < a.size(); ++i) {
    out[i].parallax_deg = parallax_deg(a_to_world, a[i], b_to_world, b[i]);
    if (out[i].parallax_deg < options.min_parallax_deg) continue;  // low_parallax
    at.push_back(i);
    ka.push_back(a[i]);
    kb.push_back(b[i]);
  }
  if (at.empty()) return out;
  const cv::Matx34d Pa = detail::world_to_camera(a_to_world);
  const cv::Matx34d Pb = detail::world_to_camera(b_to_world);
  cv::Mat X;
  cv::triangulatePoints(cv::Mat(Pa), cv::Mat(Pb), ka, kb, X);  // 4 x N
  X.convertTo(X, CV_64F);
  const auto reprojection = [&](const cv::Matx34d& P, const cv::Vec3d& p, const cv::Point2d& seen, double& depth) {
    const cv::Vec3d c = P * cv::Vec4d(p[0], p[1], p[2], 1.0);
    depth = c[2];
    if (!(std::abs(c[2]) > 1e-12)) return std::numeric_limits<double>::infinity();
    const double dx = c[0] / c[2] - seen.x, dy = c[1] / c[2] - seen.y;
    return std::sqrt(dx * dx + dy * dy) * focal;
  };
  for (std::size_t j = 0; j < at.size(); ++j) {
    TriangulatedPoint& t = out[at[j]];
    const int col = static_cast<int>(j);
    const double w = X.at<double>(3, col);
    if (!(std::abs(w) > 1e-12)) continue;  // at infinity: low_parallax
    const cv::Vec3d p(X.at<double>(0, col) / w, X.at<double>(1, col) / w, X.at<double>(2, col) / w);
    double da = 0.0, db = 0.0;
    const double ea = reprojection(Pa, p, ka[j], da), eb = reprojection(Pb, p, kb[j], db);
    t.error_px = std::max(ea, eb);
    if (!(da > 0) || !(db > 0)) {
      t.status = PointStatus::behind;
    } else if (!(t.error_px <= options.max_reprojection_px)) {
      t.status = PointStatus::off_the_rays;
    } else {
      t.status = PointStatus::triangulated;
      t.world = cv::Point3d(p[0], p[1], p[2]);
    }
  }
  return out;
}

}  // namespace vmap
