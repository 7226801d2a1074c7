#pragma once

// Camera models: the pinhole camera with OpenCV's radial-tangential distortion
// (Brown-Conrady: k1, k2, p1, p2[, k3[, k4, k5, k6]]) and the equidistant fisheye model
// (Kannala & Brandt 2006, k1..k4, as cv::fisheye implements it). Both map a keypoint of
// the real image to the ideal pinhole image with the same K, so that two-view
// estimation (geometry/fundamental.hpp, geometry/essential.hpp) sees straight lines as
// straight lines while its thresholds keep their meaning in pixels (at the image centre
// an ideal pixel is a real pixel).
//
// Files users have (ORB-SLAM YAML, ROS camera_info, KITTI calib.txt) are read by
// io/calibration.hpp.

#include <vmap/core/error.hpp>
#include <vmap/core/name_table.hpp>
#include <vmap/core/numeric.hpp>

#include <opencv2/calib3d.hpp>
#include <opencv2/core.hpp>

#include <cmath>
#include <cstddef>
#include <cstdint>
#include <cstdio>
#include <limits>
#include <string>
#include <string_view>
#include <vector>

namespace vmap {

namespace detail {

/// A number for a message, as printf's %g writes it ("1e-300", "500", "0.25").
inline std::string short_number(double v) {
  char buf[32];
  std::snprintf(buf, sizeof buf, "%g", v);
  return buf;
}

}  // namespace detail

/// The lens model of a Camera.
enum class LensModel : std::uint8_t {
  pinhole,  ///< pinhole + radial-tangential distortion (cv::undistortPoints); none when all zero
  fisheye,  ///< equidistant fisheye, Kannala-Brandt k1..k4 (cv::fisheye)
};

/// The lens models' names, in words (core/names.hpp).
[[nodiscard]] constexpr auto names_of(LensModel) noexcept {
  return detail::NameTable<LensModel, 2>{{{{LensModel::pinhole, "pinhole (radial-tangential)"},
                                           {LensModel::fisheye, "fisheye (equidistant, Kannala-Brandt)"}}}};
}
[[nodiscard]] constexpr std::string_view to_string(LensModel m) noexcept { return names_of(m).name(m); }

/// Intrinsics and distortion of one camera. An aggregate: build it with designated
/// initializers and call `validate()` (the readers of io/calibration.hpp do).
struct Camera {
  LensModel lens = LensModel::pinhole;
  double fx = 0.0;  ///< focal lengths, pixels
  double fy = 0.0;
  double cx = 0.0;  ///< principal point, pixels
  double cy = 0.0;
  /// OpenCV's order. Pinhole: k1 k2 p1 p2 [k3 [k4 k5 k6]] (0, 4, 5 or 8 values; empty =
  /// no distortion). Fisheye: exactly k1 k2 k3 k4.
  std::vector<double> distortion;
  cv::Size image_size{};  ///< (0, 0) when the file does not say

  [[nodiscard]] cv::Matx33d K() const { return {fx, 0, cx, 0, fy, cy, 0, 0, 1}; }

  /// Mean focal length: converts a pixel threshold to normalised image coordinates.
  [[nodiscard]] double focal() const noexcept { return 0.5 * (fx + fy); }

  /// True when undistortion is the identity (a pinhole without distortion, e.g. KITTI's
  /// rectified images): keypoints are then used as they are.
  [[nodiscard]] bool ideal() const noexcept {
    if (lens == LensModel::fisheye) return false;
    for (double d : distortion)
      if (d != 0.0) return false;
    return true;
  }

  /// Throws vmap::Error naming `source` (a file, an option) when a value is unusable.
  void validate(const std::string& source = "camera") const {
    const std::string where = source + ": ";
    detail::check(std::isfinite(fx) && fx > 0,
                  [&] { return where + "fx must be a finite number > 0, got " + std::to_string(fx); });
    detail::check(std::isfinite(fy) && fy > 0,
                  [&] { return where + "fy must be a finite number > 0, got " + std::to_string(fy); });
    detail::check(std::isfinite(cx) && std::isfinite(cy),
                  [&] { return where + "the principal point (cx, cy) must be finite"; });
    for (std::size_t k = 0; k < distortion.size(); ++k)
      detail::check(std::isfinite(distortion[k]),
                    [&] { return where + "distortion coefficient " + std::to_string(k) + " is not finite"; });
    const std::size_t n = distortion.size();
    if (lens == LensModel::fisheye)
      detail::check(n == 4, [&] {
        return where + "a fisheye (Kannala-Brandt) camera has 4 distortion coefficients k1..k4, got " +
               std::to_string(n);
      });
    else
      detail::check(n == 0 || n == 4 || n == 5 || n == 8, [&] {
        return where + "a pinhole camera has 0, 4, 5 or 8 distortion coefficients (k1 k2 p1 p2 [k3 [k4 k5 k6]]), got " +
               std::to_string(n);
      });
    detail::check(
        image_size.width >= 0 && image_size.height >= 0 && (image_size.width == 0) == (image_size.height == 0),
        [&] { return where + "the image size must be positive or unknown (0 x 0)"; });
    // Physical sense: a value outside these bounds is a unit or typing mistake (metres
    // for pixels, a lost decimal point), which would otherwise run and give nothing.
    detail::check(fx >= min_focal_px && fx <= max_focal_px && fy >= min_focal_px && fy <= max_focal_px, [&] {
      return where + "focal lengths fx = " + detail::short_number(fx) + ", fy = " + detail::short_number(fy) +
             " pixels are outside [" + detail::short_number(min_focal_px) + ", " + detail::short_number(max_focal_px) + "]";
    });
    detail::check(image_size.width <= max_image_side && image_size.height <= max_image_side, [&] {
      return where + "the image size " + std::to_string(image_size.width) + " x " + std::to_string(image_size.height) +
             " exceeds " + std::to_string(max_image_side) + " pixels a side";
    });
    if (image_size.width > 0)
      detail::check(cx >= 0 && cx <= image_size.width && cy >= 0 && cy <= image_size.height, [&] {
        return where + "the principal point (" + detail::short_number(cx) + ", " + detail::short_number(cy) +
               ") lies outside the " + std::to_string(image_size.width) + " x " + std::to_string(image_size.height) +
               " image";
      });
    for (std::size_t k = 0; k < distortion.size(); ++k) {
      // Tangential terms (p1, p2: indices 2, 3 of a pinhole) are fractions of a pixel
      // ray; radial ones of real lenses stay within tens (rational model) or units.
      const bool tangential = lens == LensModel::pinhole && (k == 2 || k == 3);
      const double bound = tangential ? max_tangential : max_radial;
      detail::check(std::abs(distortion[k]) <= bound, [&] {
        return where + "distortion coefficient " + std::to_string(k) + " = " + detail::short_number(distortion[k]) +
               " is outside [-" + detail::short_number(bound) + ", " + detail::short_number(bound) + "]";
      });
    }
  }

  /// Bounds of `validate`'s physical check.
  static constexpr double min_focal_px = 1.0;
  static constexpr double max_focal_px = 1e6;
  static constexpr int max_image_side = 65536;
  static constexpr double max_radial = 1000.0;
  static constexpr double max_tangential = 1.0;

  /// Fails when the camera states an image size and `frames` (the size of the images it
  /// is applied to) is another one: its K and distortion would be applied to the wrong
  /// pixels. `frames` of (0, 0) (unknown) passes.
  void check_frame_size(cv::Size frames, const std::string& source = "camera") const {
    if (image_size.width == 0 || frames.width == 0 || frames == image_size) return;
    detail::fail(source + ": the calibration is for " + std::to_string(image_size.width) + " x " +
                 std::to_string(image_size.height) + " images, the frames are " + std::to_string(frames.width) + " x " +
                 std::to_string(frames.height));
  }

  /// Every value, as text that reads back exactly ("pinhole fx=517.3 ... size=640x480"):
  /// part of the description of an estimator that uses the camera (DescribesItself).
  [[nodiscard]] std::string describe() const {
    std::string out = std::string(lens == LensModel::pinhole ? "pinhole" : "fisheye") + " fx=" + exact_text(fx) +
                      " fy=" + exact_text(fy) + " cx=" + exact_text(cx) + " cy=" + exact_text(cy) + " distortion=[";
    for (std::size_t i = 0; i < distortion.size(); ++i) out += (i ? " " : "") + exact_text(distortion[i]);
    return out + "] size=" + std::to_string(image_size.width) + "x" + std::to_string(image_size.height);
  }
};

namespace detail {

inline cv::Mat distortion_mat(const Camera& c) {
  cv::Mat d(1, static_cast<int>(c.distortion.size()), CV_64F);
  for (std::size_t k = 0; k < c.distortion.size(); ++k) d.at<double>(0, static_cast<int>(k)) = c.distortion[k];
  return d;
}

/// Undistorted points, in normalised coordinates (P empty) or re-projected by P.
inline void undistort_into(const Camera& c, const std::vector<cv::Point2f>& in, std::vector<cv::Point2f>& out,
                           const cv::Mat& P) {
  out.clear();
  if (in.empty()) return;
  const cv::Mat K(c.K());
  if (c.lens == LensModel::fisheye) {
    // 4.6's default: 10 Newton steps to 1e-8 on theta, enough for k1..k4 of real lenses.
    cv::fisheye::undistortPoints(in, out, K, distortion_mat(c), cv::noArray(), P.empty() ? cv::noArray() : P);
  } else if (c.distortion.empty()) {
    cv::undistortPoints(in, out, K, cv::noArray(), cv::noArray(), P.empty() ? cv::noArray() : P);
  } else {
    // The default 5 fixed-point iterations leave pixels of error where the distortion is
    // strong (corners of a wide lens); iterate to convergence instead.
    cv::undistortPoints(in, out, K, distortion_mat(c), cv::noArray(), P.empty() ? cv::noArray() : P,
                        cv::TermCriteria(cv::TermCriteria::COUNT | cv::TermCriteria::EPS, 100, 1e-10));
  }
}

}  // namespace detail

/// Keypoint positions re-projected to the ideal pinhole image with the same K (what the
/// image would show without distortion). Identity for an ideal camera. A point that
/// the model cannot undistort (beyond the lens' field of view) comes back non-finite;
/// callers drop those.
[[nodiscard]] inline std::vector<cv::Point2f> undistort_points(const Camera& c, const std::vector<cv::Point2f>& pixels) {
  if (c.ideal()) return pixels;
  std::vector<cv::Point2f> out;
  detail::undistort_into(c, pixels, out, cv::Mat(c.K()));
  return out;
}

namespace detail {

/// d(ideal pixel) / d(real pixel) at each point (central differences, h = 0.5 px): how
/// much the undistortion stretches the image there (1 at the centre, up to 1/cos^2 of
/// the ray angle at the edge of an equidistant fisheye).
inline std::vector<cv::Matx22d> undistortion_jacobians(const Camera& c, const std::vector<cv::Point2f>& real) {
  std::vector<cv::Matx22d> J(real.size(), cv::Matx22d::eye());
  if (c.ideal() || real.empty()) return J;
  constexpr float h = 0.5f;
  std::vector<cv::Point2f> shifted(4 * real.size());
  for (std::size_t i = 0; i < real.size(); ++i) {
    shifted[4 * i + 0] = real[i] + cv::Point2f(h, 0);
    shifted[4 * i + 1] = real[i] - cv::Point2f(h, 0);
    shifted[4 * i + 2] = real[i] + cv::Point2f(0, h);
    shifted[4 * i + 3] = real[i] - cv::Point2f(0, h);
  }
  std::vector<cv::Point2f> u;
  undistort_into(c, shifted, u, cv::Mat(c.K()));
  for (std::size_t i = 0; i < real.size(); ++i) {
    const cv::Point2f dx = (u[4 * i + 0] - u[4 * i + 1]) / (2 * h);
    const cv::Point2f dy = (u[4 * i + 2] - u[4 * i + 3]) / (2 * h);
    J[i] = cv::Matx22d(dx.x, dy.x, dx.y, dy.y);
  }
  return J;
}

/// Sampson distance of each correspondence to the epipolar geometry F of the ideal
/// images (x_b^T F x_a = 0 on ideal pixels), measured in pixels of the real images: the
/// gradient of the epipolar constraint is taken through the undistortion Jacobians
/// (Hartley & Zisserman, sec. 4.2.6, first-order geometric error). A pixel threshold
/// then means the same at the centre and at the edge of a strong lens.
inline std::vector<double> sampson_in_image_pixels(const cv::Matx33d& F, const std::vector<cv::Point2f>& ideal_a,
                                                   const std::vector<cv::Point2f>& ideal_b,
                                                   const std::vector<cv::Matx22d>& Ja,
                                                   const std::vector<cv::Matx22d>& Jb) {
  std::vector<double> d(ideal_a.size());
  for (std::size_t i = 0; i < d.size(); ++i) {
    const cv::Vec3d xa(ideal_a[i].x, ideal_a[i].y, 1.0);
    const cv::Vec3d xb(ideal_b[i].x, ideal_b[i].y, 1.0);
    const cv::Vec3d Fxa = F * xa;
    const cv::Vec3d Ftxb = F.t() * xb;
    const double e = xb.dot(Fxa);
    const cv::Vec2d ga = Ja[i].t() * cv::Vec2d(Ftxb[0], Ftxb[1]);
    const cv::Vec2d gb = Jb[i].t() * cv::Vec2d(Fxa[0], Fxa[1]);
    const double g2 = ga.dot(ga) + gb.dot(gb);
    d[i] = g2 > 0 ? std::abs(e) / std::sqrt(g2) : std::numeric_limits<double>::infinity();
  }
  return d;
}

}  // namespace detail

/// Normalised image coordinates (x/z, y/z of the viewing ray) of keypoint positions.
[[nodiscard]] inline std::vector<cv::Point2f> normalize_points(const Camera& c, const std::vector<cv::Point2f>& pixels) {
  std::vector<cv::Point2f> out;
  detail::undistort_into(c, pixels, out, cv::Mat());
  return out;
}

}  // namespace vmap
