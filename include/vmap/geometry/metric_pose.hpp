#pragma once

// A camera's metric pose in a memory's frame and why there is none (examples/memory.md,
// "Where am I, in metres"): the value types a localization answers with. The estimation
// is geometry/pnp.hpp and geometry/triangulation.hpp, composed by memory/metric_pose.hpp;
// this header holds no code that makes a pose, so that a program that passes answers
// around does not compile calib3d for them.
//
// Conventions: camera-to-world (a point p in camera coordinates is R p + t in the world,
// so t is the camera centre), positions in the units of the memory's poses (metres for
// TUM and KITTI trajectories), quaternions in TUM's order (qx, qy, qz, qw).

#include <vmap/core/name_table.hpp>
#include <vmap/core/verification.hpp>

#include <opencv2/core.hpp>
#include <opencv2/core/affine.hpp>

#include <algorithm>
#include <cmath>
#include <cstdint>
#include <numbers>
#include <optional>
#include <string>
#include <string_view>

namespace vmap {

/// Whether a query has a metric pose, and why not. A pose is answered only where the
/// geometry holds: a wrong pose is worse than none.
enum class PoseReason : std::uint8_t {
  posed,               ///< the geometry holds: a pose
  not_accepted,        ///< the place was not accepted: no key image to place it by
  no_camera,           ///< the memory has no camera: a metric pose needs its calibration
  no_key_pose,         ///< the key image has no SE(3) pose (the memory was built without poses)
  no_baseline,         ///< the posed key images beside the key image saw it from the same spot (a camera turning on the spot): no depth
  too_few_points,      ///< too few of the query's verified matches reach a triangulated point
  few_inliers,         ///< the PnP found too few inliers, or too small a share of the points
  rotation_disagrees,  ///< the PnP's rotation disagrees with the verified relative rotation to the key image
  uncertain,           ///< the pose's covariance is wider than the bound
  moved,               ///< a sequence placed the image at another key image than its own answer's (memory/sequence.hpp)
};

/// The reasons' names, in words (core/names.hpp).
[[nodiscard]] constexpr auto names_of(PoseReason) noexcept {
  using R = PoseReason;
  return detail::NameTable<PoseReason, 10>{{{{R::posed, "posed"},
                                             {R::not_accepted, "place not accepted"},
                                             {R::no_camera, "no camera"},
                                             {R::no_key_pose, "key image without a pose"},
                                             {R::no_baseline, "no baseline"},
                                             {R::too_few_points, "too few points"},
                                             {R::few_inliers, "few PnP inliers"},
                                             {R::rotation_disagrees, "rotation disagrees"},
                                             {R::uncertain, "uncertain"},
                                             {R::moved, "moved by the sequence"}}}};
}
[[nodiscard]] constexpr std::string_view to_string(PoseReason r) noexcept { return names_of(r).name(r); }

/// A camera's 6-DoF pose found by PnP against 3D points of posed key images.
struct MetricPose {
  /// Camera to world: p_world = rotation() * p_camera + position().
  cv::Affine3d camera_to_world = cv::Affine3d::Identity();
  /// Covariance of the pose, from the PnP refinement's Jacobian and the inliers' residuals
  /// (the 3D points taken as exact): rows and columns are the position x, y, z (in the
  /// poses' units, squared) and then a small rotation vector in the world frame
  /// (R = exp([w]x) R_estimated; radians squared).
  cv::Matx66d covariance = cv::Matx66d::zeros();
  std::uint32_t key = 0;   ///< the key image whose 3D points placed it
  int points = 0;          ///< 2D-3D correspondences the PnP was given
  int inliers = 0;         ///< of those, reprojected within the threshold by the pose
  double reprojection_px = 0.0;  ///< RMS reprojection error of the inliers, pixels of the ideal image
  /// The angle between the PnP's rotation relative to the key image and the one the
  /// verified two-view geometry recovered (Verification::relative_pose), degrees; unset
  /// when the two-view geometry recovered none (checked against the bound only where it
  /// was not degenerate: memory/metric_pose.hpp).
  std::optional<double> rotation_disagreement_deg;

  [[nodiscard]] cv::Vec3d position() const { return camera_to_world.translation(); }
  [[nodiscard]] cv::Matx33d rotation() const { return camera_to_world.rotation(); }
  /// Standard deviation of each position coordinate.
  [[nodiscard]] cv::Vec3d position_sigma() const {
    return {std::sqrt(std::max(0.0, covariance(0, 0))), std::sqrt(std::max(0.0, covariance(1, 1))),
            std::sqrt(std::max(0.0, covariance(2, 2)))};
  }
  /// Standard deviation of the rotation about its least certain axis, degrees (the
  /// largest eigenvalue of the rotation block).
  [[nodiscard]] double rotation_sigma_deg() const {
    cv::Matx33d r;
    for (int i = 0; i < 3; ++i)
      for (int j = 0; j < 3; ++j) r(i, j) = covariance(3 + i, 3 + j);
    cv::Vec3d eig;
    cv::eigen(r, eig);
    return std::sqrt(std::max(0.0, eig[0])) * 180.0 / std::numbers::pi;
  }
  /// Standard deviation of the position along its least certain direction (the
  /// largest eigenvalue of the position block).
  [[nodiscard]] double position_sigma_max() const {
    cv::Matx33d p;
    for (int i = 0; i < 3; ++i)
      for (int j = 0; j < 3; ++j) p(i, j) = covariance(i, j);
    cv::Vec3d eig;
    cv::eigen(p, eig);
    return std::sqrt(std::max(0.0, eig[0]));
  }
};

/// A metric pose, or why there is none.
struct PoseAnswer {
  std::optional<MetricPose> pose;
  PoseReason reason_code = PoseReason::not_accepted;
  std::string reason = "the place was not accepted";  ///< why, in words with the numbers

  [[nodiscard]] bool ok() const noexcept { return pose.has_value(); }
};

}  // namespace vmap
