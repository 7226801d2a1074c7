#pragma once

// Calibrated<E>: any Estimator run on undistorted keypoints. The keypoints of the
// matches are re-projected to the ideal pinhole image with the camera's own K
// (geometry/camera.hpp), so an F-matrix fits again where a wide-angle or fisheye lens
// bends the epipolar lines, and the wrapped estimator's pixel threshold keeps its
// meaning (exactly at the image centre; toward the edge of a strong lens an ideal pixel
// covers less of the real image).

#include <vmap/core/concepts.hpp>
#include <vmap/core/error.hpp>
#include <vmap/geometry/camera.hpp>
#include <vmap/geometry/detail/robust.hpp>
#include <vmap/geometry/fundamental.hpp>
#include <vmap/geometry/homography.hpp>

#include <opencv2/calib3d.hpp>
#include <opencv2/core.hpp>

#include <algorithm>
#include <cmath>
#include <concepts>
#include <cstddef>
#include <optional>
#include <string>
#include <utility>
#include <vector>

namespace vmap {

/// Wraps an Estimator so that it sees undistorted keypoints.
///
/// - With a camera: the matched keypoints of both images are undistorted (one camera
///   took both images), matches whose keypoints the lens model cannot undistort (beyond
///   its field of view) are left out and marked outliers, and the wrapped estimator
///   runs on the rest. The Verification's inlier_mask is aligned with the given
///   matches; `matches` counts all of them; the model (F or H) is the model of the ideal
///   pinhole image, x_ideal = K * normalised ray.
/// - With an ideal camera (no distortion): the wrapped estimator on the given keypoints.
/// - With a camera of either kind, a verified F-matrix (FundamentalEstimator) also gives
///   the relative pose (Verification::relative_pose: R and the unit t from camera a to
///   camera b), so the F-matrix decides as without a camera and the pose comes with it.
/// - Without a camera (std::nullopt): the wrapped estimator, unchanged, so a command
///   line can choose at run time with one type.
///
/// The wrapped estimator sees keypoints only (positions, with the other KeyPoint fields
/// kept) and no descriptors. Const and thread-safe when the wrapped estimator is.
template <Estimator E>
class Calibrated {
 public:
  /// `source` names the camera in errors (its calibration file).
  Calibrated(std::optional<Camera> camera, E estimator, std::string source = "Calibrated: camera")
      : camera_(std::move(camera)), estimator_(std::move(estimator)), source_(std::move(source)) {
    if (camera_) camera_->validate(source_);
  }

  [[nodiscard]] Verification verify(const Features& a, const Features& b, const Matches& matches) const {
    if (camera_) {
      camera_->check_frame_size(a.image_size, source_);
      camera_->check_frame_size(b.image_size, source_);
    }
    if (!camera_) return estimator_.verify(a, b, matches);
    if (camera_->ideal()) {
      Verification v = estimator_.verify(a, b, matches);
      if constexpr (std::same_as<E, FundamentalEstimator>) {
        if (v.ok()) {
          std::vector<cv::Point2f> ia, ib;
          for (std::size_t k = 0; k < matches.size(); ++k)
            if (v.inlier_mask[k]) {
              ia.push_back(a.keypoints[static_cast<std::size_t>(matches[k].queryIdx)].pt);
              ib.push_back(b.keypoints[static_cast<std::size_t>(matches[k].trainIdx)].pt);
            }
          recover_pose(ia, ib, v);
        }
      }
      return v;
    }
    std::vector<cv::Point2f> pa, pb;
    std::vector<int> order;
    detail::gather_points(a, b, matches, 0, pa, pb, order);  // checks the indices; seed 0: given order
    const std::vector<cv::Point2f> ua = undistort_points(*camera_, pa);
    const std::vector<cv::Point2f> ub = undistort_points(*camera_, pb);
    Features fa, fb;
    fa.norm = a.norm;
    fb.norm = b.norm;
    fa.image_size = a.image_size;
    fb.image_size = b.image_size;
    Matches kept;
    std::vector<std::size_t> original;  // kept[k] stands for matches[original[k]]
    kept.reserve(matches.size());
    original.reserve(matches.size());
    fa.keypoints.reserve(matches.size());
    fb.keypoints.reserve(matches.size());
    for (std::size_t k = 0; k < matches.size(); ++k) {
      if (!finite(ua[k]) || !finite(ub[k])) continue;
      cv::KeyPoint ka = a.keypoints[static_cast<std::size_t>(matches[k].queryIdx)];
      cv::KeyPoint kb = b.keypoints[static_cast<std::size_t>(matches[k].trainIdx)];
      ka.pt = ua[k];
      kb.pt = ub[k];
      const int i = static_cast<int>(kept.size());
      fa.keypoints.push_back(ka);
      fb.keypoints.push_back(kb);
      kept.emplace_back(i, i, matches[k].distance);
      original.push_back(k);
    }
    Verification v = estimator_.verify(fa, fb, kept);
    if constexpr (std::same_as<E, FundamentalEstimator>) {
      if (v.status == VerificationStatus::verified || v.status == VerificationStatus::too_few_inliers)
        rescore_in_image_pixels(pa, pb, fa, fb, original, v);
      if (v.ok()) {
        std::vector<cv::Point2f> ia, ib;
        for (std::size_t k = 0; k < kept.size(); ++k)
          if (v.inlier_mask[k]) {
            ia.push_back(fa.keypoints[k].pt);
            ib.push_back(fb.keypoints[k].pt);
          }
        recover_pose(ia, ib, v);
      }
    }
    v.matches = static_cast<int>(matches.size());
    if (!v.inlier_mask.empty()) {
      std::vector<std::uint8_t> mask(matches.size(), 0);
      for (std::size_t k = 0; k < kept.size(); ++k) mask[original[k]] = v.inlier_mask[k];
      v.inlier_mask = std::move(mask);
    }
    return v;
  }

  /// The wrapped FundamentalEstimator's buffers (verify_into).
  using Scratch = FundamentalEstimator::Scratch;

  /// verify() into `v` with the caller's buffers, so that a key-image selector whose
  /// estimator is wrapped keeps its fast path. Without a camera it is the wrapped
  /// estimator's verify_into, which defers its homography degeneracy test with
  /// `defer_degeneracy` (true returned; complete_degeneracy fills it in). With a camera
  /// it is verify(): nothing is deferred (false).
  bool verify_into(const Features& a, const Features& b, const Matches& matches, Verification& v, Scratch& scratch,
                   bool defer_degeneracy) const
    requires std::same_as<E, FundamentalEstimator>
  {
    if (!camera_) return estimator_.verify_into(a, b, matches, v, scratch, defer_degeneracy);
    v = verify(a, b, matches);
    return false;
  }

  /// The test verify_into deferred, on the same inputs and its result (only without a
  /// camera does verify_into defer it; with one this changes nothing).
  void complete_degeneracy(const Features& a, const Features& b, const Matches& matches, Verification& v) const
    requires std::same_as<E, FundamentalEstimator>
  {
    if (!camera_) estimator_.complete_degeneracy(a, b, matches, v);
  }

  [[nodiscard]] const std::optional<Camera>& camera() const noexcept { return camera_; }
  [[nodiscard]] const E& estimator() const noexcept { return estimator_; }

  /// The camera and the wrapped estimator's description (DescribesItself, when the
  /// wrapped one describes itself); without a camera it is the wrapped estimator, and
  /// describes itself as that.
  [[nodiscard]] std::string describe() const
    requires DescribesItself<E>
  {
    if (!camera_) return std::string(estimator_.describe());
    return "Calibrated camera=(" + camera_->describe() + ") " + std::string(estimator_.describe());
  }

 private:
  /// The F-matrix's final inliers by the Sampson distance in pixels of the real images
  /// (detail::sampson_in_image_pixels), against the wrapped estimator's pixel threshold:
  /// the robust search ran on ideal pixels, where the edge of a strong lens is stretched
  /// (an equidistant fisheye by 1/cos^2 of the ray angle), so a 1 px threshold there
  /// would reject correct matches the real image places within 1 px.
  void rescore_in_image_pixels(const std::vector<cv::Point2f>& pa, const std::vector<cv::Point2f>& pb,
                               const Features& fa, const Features& fb, const std::vector<std::size_t>& original,
                               Verification& v) const {
    // Only FundamentalEstimator's model is an F with these options (verify calls this
    // for it alone); the guard keeps explicit instantiations of other stacks compiling.
    if constexpr (std::same_as<E, FundamentalEstimator>) {
      std::vector<cv::Point2f> ra, rb, ia, ib;
      ra.reserve(original.size());
      rb.reserve(original.size());
      ia.reserve(original.size());
      ib.reserve(original.size());
      for (std::size_t k = 0; k < original.size(); ++k) {
        ra.push_back(pa[original[k]]);
        rb.push_back(pb[original[k]]);
        ia.push_back(fa.keypoints[k].pt);
        ib.push_back(fb.keypoints[k].pt);
      }
      const auto Ja = detail::undistortion_jacobians(*camera_, ra);
      const auto Jb = detail::undistortion_jacobians(*camera_, rb);
      const auto d = detail::sampson_in_image_pixels(v.model, ia, ib, Ja, Jb);
      const double threshold = estimator_.options().threshold_px;
      v.inlier_mask.assign(original.size(), 0);
      v.inliers = 0;
      for (std::size_t k = 0; k < d.size(); ++k)
        if (d[k] <= threshold) {
          v.inlier_mask[k] = 1;
          ++v.inliers;
        }
      v.status = v.inliers >= estimator_.options().min_inliers ? VerificationStatus::verified
                                                                : VerificationStatus::too_few_inliers;
      if (estimator_.options().check_degeneracy && v.ok()) check_degeneracy(ia, ib, Jb, v);
    }
  }

  /// FundamentalEstimator's homography test (planar scene or pure rotation), redone on
  /// the final inliers with the transfer error measured in pixels of the real image b
  /// (the ideal error mapped back through the inverse undistortion Jacobian): in ideal
  /// pixels a fixed threshold would reject the stretched edge of a strong lens and hide
  /// the degeneracy. The robust fit runs on ideal pixels with the threshold scaled by
  /// the median stretch; the count in real pixels decides.
  void check_degeneracy(const std::vector<cv::Point2f>& ia, const std::vector<cv::Point2f>& ib,
                        const std::vector<cv::Matx22d>& Jb, Verification& v) const
    requires std::same_as<E, FundamentalEstimator>
  {
    const FundamentalOptions& o = estimator_.options();
    std::vector<cv::Point2f> xa, xb;
    std::vector<std::size_t> at;
    std::vector<double> stretch;  // rms singular value of the Jacobian at each inlier
    for (std::size_t k = 0; k < v.inlier_mask.size(); ++k)
      if (v.inlier_mask[k]) {
        xa.push_back(ia[k]);
        xb.push_back(ib[k]);
        at.push_back(k);
        stretch.push_back(std::sqrt(Jb[k].dot(Jb[k]) / 2.0));
      }
    v.degeneracy = Degeneracy::none;
    v.homography_inliers = 0;
    if (xa.size() < 4) return;
    // The median stretch: the largest (near the lens' rim) would let any sample's H win.
    std::nth_element(stretch.begin(), stretch.begin() + static_cast<std::ptrdiff_t>(stretch.size() / 2), stretch.end());
    const double median_stretch = std::max(1.0, stretch[stretch.size() / 2]);
    cv::Mat H;
    try {
      // 2x the F threshold: a 2-D transfer error against a 1-D distance to a line (as in
      // FundamentalEstimator::check_degeneracy).
      H = cv::findHomography(xa, xb, cv::RANSAC, 2.0 * o.threshold_px * median_stretch, cv::noArray(), 2000, o.confidence);
    } catch (const cv::Exception&) {
      return;
    }
    if (H.empty()) return;
    const cv::Matx33d h(H);
    for (std::size_t i = 0; i < xa.size(); ++i) {
      const cv::Vec3d p = h * cv::Vec3d(xa[i].x, xa[i].y, 1.0);
      if (!(std::abs(p[2]) > 1e-12)) continue;
      const cv::Vec2d e(p[0] / p[2] - xb[i].x, p[1] / p[2] - xb[i].y);
      const cv::Matx22d& J = Jb[at[i]];
      const double det = J(0, 0) * J(1, 1) - J(0, 1) * J(1, 0);
      if (!(std::abs(det) > 1e-12)) continue;
      const cv::Vec2d r = cv::Matx22d(J(1, 1), -J(0, 1), -J(1, 0), J(0, 0)) * e * (1.0 / det);  // J^-1 e
      if (std::sqrt(r.dot(r)) <= 2.0 * o.threshold_px) ++v.homography_inliers;
    }
    if (v.homography_inliers >= o.degeneracy_ratio * v.inliers) v.degeneracy = Degeneracy::homography;
  }

  /// The motion from camera a to camera b behind a verified F of the ideal image: E =
  /// K^T F K (Hartley and Zisserman, eq. 9.12), decomposed by cv::recoverPose on the ideal
  /// pixels of the inliers (the cheirality test picks one of the four solutions). No pose
  /// is an expected outcome: when no inlier triangulates in front of both cameras (a
  /// camera that only turns gives no parallax), the test cannot choose, and the "best"
  /// solution is as often the twisted pair, 180 degrees off (see examples/camera.md and
  /// tests/unit/geometry/test_camera_data.cpp).
  void recover_pose(const std::vector<cv::Point2f>& ia, const std::vector<cv::Point2f>& ib, Verification& v) const
    requires std::same_as<E, FundamentalEstimator>
  {
    const cv::Matx33d K = camera_->K();
    cv::Mat R, t;
    try {
      const int front = cv::recoverPose(cv::Mat(K.t() * v.model * K), ia, ib, cv::Mat(K), R, t);
      if (front > 0) v.relative_pose = detail::relative_pose_of(R, t, front);
    } catch (const cv::Exception&) {
      // No pose (as above): recoverPose refuses a degenerate E.
    }
  }

  static bool finite(const cv::Point2f& p) noexcept { return std::isfinite(p.x) && std::isfinite(p.y); }

  std::optional<Camera> camera_;
  E estimator_;
  std::string source_;
};

static_assert(Estimator<Calibrated<FundamentalEstimator>>);
static_assert(Estimator<Calibrated<HomographyEstimator>>);

}  // namespace vmap
