#pragma once

#include <vmap/core/name_table.hpp>

#include <opencv2/core.hpp>

#include <algorithm>
#include <cmath>
#include <cstdint>
#include <optional>
#include <string_view>
#include <vector>

namespace vmap {

/// Why a verification did or did not produce a model. Verification failures are values,
/// not exceptions: "too few matches" is an everyday outcome of a fast-moving camera.
enum class VerificationStatus : std::uint8_t {
  verified,         ///< a model was estimated and at least `min_inliers` support it
  too_few_matches,  ///< fewer correspondences than the method's minimal sample
  no_model,         ///< the estimator found no model (e.g. all points identical)
  too_few_inliers,  ///< a model was found but fewer inliers than the configured floor
};

/// A configuration in which the epipolar geometry is not determined even though the
/// fundamental matrix fits: all points on one plane, or a camera that only rotated.
/// Both are explained by a single homography (Hartley & Zisserman, sec. 11.9).
enum class Degeneracy : std::uint8_t {
  none,
  homography,  ///< a homography explains (nearly) all model inliers
};

/// The statuses' names, in words (core/names.hpp).
[[nodiscard]] constexpr auto names_of(VerificationStatus) noexcept {
  using V = VerificationStatus;
  return detail::NameTable<VerificationStatus, 4>{{{{V::verified, "verified"},
                                                    {V::too_few_matches, "too few matches"},
                                                    {V::no_model, "no model"},
                                                    {V::too_few_inliers, "too few inliers"}}}};
}
[[nodiscard]] constexpr std::string_view to_string(VerificationStatus s) noexcept { return names_of(s).name(s); }

/// none, and the homography case in words (core/names.hpp).
[[nodiscard]] constexpr auto names_of(Degeneracy) noexcept {
  return detail::NameTable<Degeneracy, 2>{
      {{{Degeneracy::none, "none"}, {Degeneracy::homography, "homography (planar scene or pure rotation)"}}}};
}
[[nodiscard]] constexpr std::string_view to_string(Degeneracy d) noexcept { return names_of(d).name(d); }

/// The angle of a rotation matrix, degrees (from its trace).
[[nodiscard]] inline double rotation_angle_deg(const cv::Matx33d& r) {
  const double c = std::clamp((cv::trace(r) - 1.0) / 2.0, -1.0, 1.0);
  return std::acos(c) * 180.0 / CV_PI;
}

/// The motion between two calibrated views, from an essential matrix (cv::recoverPose):
/// a point X_a in camera a's coordinates is X_b = rotation * X_a + translation in camera
/// b's. Two views fix the translation only up to scale: |translation| = 1.
struct RelativePose {
  cv::Matx33d rotation = cv::Matx33d::eye();
  cv::Vec3d translation;
  int points_in_front = 0;  ///< inliers triangulated in front of both cameras (cheirality)

  /// The rotation's angle in degrees (from its trace).
  [[nodiscard]] double rotation_degrees() const { return rotation_angle_deg(rotation); }
};

/// The result of geometric verification of a set of matches.
struct Verification {
  VerificationStatus status = VerificationStatus::too_few_matches;
  cv::Matx33d model = cv::Matx33d::zeros();  ///< F (x2^T F x1 = 0), H (x2 ~ H x1) or E
  std::vector<std::uint8_t> inlier_mask;     ///< one entry per match, 1 = inlier
  int inliers = 0;                           ///< number of ones in inlier_mask
  int matches = 0;                           ///< correspondences that were given
  /// The correspondences the model was fitted to, when a stage before it dropped some of
  /// `matches` (XFeat*'s refinement keeps the matches it is confident in); unset: all of
  /// them. The place decision's chance model weighs the inliers against these.
  std::optional<int> fitted;
  Degeneracy degeneracy = Degeneracy::none;
  int homography_inliers = 0;  ///< model inliers a homography also explains (0 if unchecked)
  /// Set by estimators that know the camera (EssentialEstimator with recover_pose).
  std::optional<RelativePose> relative_pose;

  [[nodiscard]] bool ok() const noexcept { return status == VerificationStatus::verified; }
};

}  // namespace vmap
