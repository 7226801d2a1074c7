#pragma once

// Essential-matrix verification for a calibrated camera: x_b^T E x_a = 0 on normalised
// image coordinates (Hartley & Zisserman, sec. 9.6), estimated by the five-point
// algorithm inside RANSAC or MAGSAC++ (cv::findEssentialMat), and optionally the
// relative pose (R, t) it implies (cv::recoverPose, cheirality check).

#include <vmap/core/concepts.hpp>
#include <vmap/core/error.hpp>
#include <vmap/core/numeric.hpp>
#include <vmap/geometry/camera.hpp>
#include <vmap/geometry/detail/robust.hpp>
#include <vmap/geometry/fundamental.hpp>

#include <opencv2/calib3d.hpp>
#include <opencv2/core.hpp>

#include <cmath>
#include <cstddef>
#include <cstdint>
#include <string>
#include <vector>

namespace vmap {

struct EssentialOptions {
  RobustMethod method = RobustMethod::magsac;  ///< magsac, ransac or lmeds (eight_point is F-only)
  /// Max. distance to the epipolar line in pixels of the image; divided by the mean
  /// focal length to become a threshold on normalised coordinates.
  double threshold_px = 1.0;
  double confidence = 0.999;  ///< OpenCV's default for findEssentialMat
  int max_iterations = 1000;
  int min_inliers = 8;        ///< floor below which the model is not trusted
  bool recover_pose = true;   ///< also fill Verification::relative_pose (R, t)
  std::uint64_t seed = 0;     ///< 0: matches in the given order; otherwise a seeded shuffle
};

/// Essential-matrix verification; needs the camera that took both images. Keypoints
/// are normalised through the camera model (undistorted, K removed), so it serves
/// pinhole, radial-tangential and fisheye cameras alike. The Verification's model is E;
/// with recover_pose, relative_pose holds R and the unit t (camera a to camera b).
/// Fewer than 6 matches: too_few_matches (at 5 the five-point solver returns up to 10
/// solutions the data cannot choose between). Const and thread-safe.
class EssentialEstimator {
 public:
  static constexpr int minimal_matches = 6;

  explicit EssentialEstimator(Camera camera, const EssentialOptions& options = {})
      : camera_(std::move(camera)), options_(options) {
    camera_.validate("EssentialEstimator: camera");
    detail::check_threshold_options(options_.threshold_px, options_.confidence, options_.max_iterations,
                                    options_.min_inliers, "EssentialOptions");
    detail::check(options_.method != RobustMethod::eight_point,
                  "EssentialOptions.method: eight_point is a fundamental-matrix method; use magsac, ransac or lmeds");
  }

  [[nodiscard]] Verification verify(const Features& a, const Features& b, const Matches& matches) const {
    Verification v;
    v.matches = static_cast<int>(matches.size());
    if (v.matches < minimal_matches) return v;
    std::vector<cv::Point2f> pa, pb;
    std::vector<int> order;
    detail::gather_points(a, b, matches, options_.seed, pa, pb, order);
    const std::vector<cv::Point2f> na = normalize_points(camera_, pa);
    const std::vector<cv::Point2f> nb = normalize_points(camera_, pb);
    // Points the lens model cannot normalise (beyond its field of view) are left out.
    std::vector<cv::Point2f> ka, kb, ra, rb;  // kept points: normalised, and real pixels
    std::vector<int> kept_order;
    ka.reserve(na.size());
    kb.reserve(nb.size());
    kept_order.reserve(order.size());
    for (std::size_t k = 0; k < order.size(); ++k)
      if (std::isfinite(na[k].x) && std::isfinite(na[k].y) && std::isfinite(nb[k].x) && std::isfinite(nb[k].y)) {
        ka.push_back(na[k]);
        kb.push_back(nb[k]);
        ra.push_back(pa[k]);
        rb.push_back(pb[k]);
        kept_order.push_back(order[k]);
      }
    if (static_cast<int>(ka.size()) < minimal_matches) return v;  // too_few_matches
    const int method = options_.method == RobustMethod::magsac   ? cv::USAC_MAGSAC
                       : options_.method == RobustMethod::ransac ? cv::RANSAC
                                                                 : cv::LMEDS;
    cv::Mat mask;
    cv::Mat E;
    try {
      E = cv::findEssentialMat(ka, kb, cv::Mat::eye(3, 3, CV_64F), method, options_.confidence,
                               options_.threshold_px / camera_.focal(), options_.max_iterations, mask);
    } catch (const cv::Exception&) {
      v.status = VerificationStatus::no_model;
      return v;
    }
    // The estimate's mask is over the kept points; spread it back over all matches.
    std::vector<int> positions(kept_order.size());
    for (std::size_t k = 0; k < positions.size(); ++k) positions[k] = static_cast<int>(k);
    detail::fill_from_estimate(E, mask, positions, options_.min_inliers, v);
    if (v.status == VerificationStatus::verified || v.status == VerificationStatus::too_few_inliers)
      rescore_in_image_pixels(ra, rb, ka, kb, v);
    if (!v.inlier_mask.empty()) {
      std::vector<std::uint8_t> full(matches.size(), 0);
      for (std::size_t k = 0; k < kept_order.size(); ++k)
        full[static_cast<std::size_t>(kept_order[k])] = v.inlier_mask[k];
      v.inlier_mask = std::move(full);
    }
    if (v.ok() && options_.recover_pose) {
      cv::Mat R, t;
      cv::Mat pose_mask(static_cast<int>(kept_order.size()), 1, CV_8U);
      for (std::size_t k = 0; k < kept_order.size(); ++k)
        pose_mask.at<std::uint8_t>(static_cast<int>(k)) = v.inlier_mask[static_cast<std::size_t>(kept_order[k])];
      try {
        const int front = cv::recoverPose(E, ka, kb, cv::Mat::eye(3, 3, CV_64F), R, t, pose_mask);
        v.relative_pose = detail::relative_pose_of(R, t, front);
      } catch (const cv::Exception&) {
        // No pose is an expected outcome (e.g. no inlier in front of both cameras).
      }
    }
    return v;
  }

  [[nodiscard]] const Camera& camera() const noexcept { return camera_; }
  [[nodiscard]] const EssentialOptions& options() const noexcept { return options_; }

  /// The camera and every option (core/concepts.hpp, DescribesItself).
  [[nodiscard]] std::string describe() const {
    const EssentialOptions& o = options_;
    return "EssentialEstimator camera=(" + camera_.describe() + ") method=" + std::to_string(static_cast<int>(o.method)) +
           " threshold_px=" + exact_text(o.threshold_px) + " confidence=" + exact_text(o.confidence) +
           " max_iterations=" + std::to_string(o.max_iterations) + " min_inliers=" + std::to_string(o.min_inliers) +
           " recover_pose=" + (o.recover_pose ? "1" : "0") + " seed=" + std::to_string(o.seed);
  }

 private:
  /// Final inliers by the Sampson distance in pixels of the real images
  /// (detail::sampson_in_image_pixels) against threshold_px: the robust search ran on
  /// normalised coordinates, where a fixed threshold is too tight toward the edge of a
  /// strong lens. All vectors and `v.inlier_mask` are over the kept points.
  void rescore_in_image_pixels(const std::vector<cv::Point2f>& ra, const std::vector<cv::Point2f>& rb,
                               const std::vector<cv::Point2f>& ka, const std::vector<cv::Point2f>& kb,
                               Verification& v) const {
    const cv::Matx33d K = camera_.K();
    auto to_ideal = [&](const cv::Point2f& n) {
      return cv::Point2f(static_cast<float>(K(0, 0) * n.x + K(0, 2)), static_cast<float>(K(1, 1) * n.y + K(1, 2)));
    };
    std::vector<cv::Point2f> ia, ib;
    ia.reserve(ka.size());
    ib.reserve(kb.size());
    for (std::size_t k = 0; k < ka.size(); ++k) {
      ia.push_back(to_ideal(ka[k]));
      ib.push_back(to_ideal(kb[k]));
    }
    const cv::Matx33d Kinv = K.inv();
    const cv::Matx33d F = Kinv.t() * v.model * Kinv;
    const auto d = detail::sampson_in_image_pixels(F, ia, ib, detail::undistortion_jacobians(camera_, ra),
                                                   detail::undistortion_jacobians(camera_, rb));
    v.inlier_mask.assign(d.size(), 0);
    v.inliers = 0;
    for (std::size_t k = 0; k < d.size(); ++k)
      if (d[k] <= options_.threshold_px) {
        v.inlier_mask[k] = 1;
        ++v.inliers;
      }
    v.status = v.inliers >= options_.min_inliers ? VerificationStatus::verified : VerificationStatus::too_few_inliers;
  }

  Camera camera_;
  EssentialOptions options_;
};

static_assert(Estimator<EssentialEstimator>);

}  // namespace vmap
