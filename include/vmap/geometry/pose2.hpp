#pragma once

// SE(2) poses (x, y, theta) of a robot on the floor: the pose algebra of the GCS
// localization paper (Trujillo-Romero 2024, examples/methods.md, sec. 3 step 1), where odometry
// increments are `pose2DInverse(a) * b` and poses are integrated by composition.

#include <vmap/core/error.hpp>

#include <Eigen/Core>
#include <Eigen/Geometry>

#include <cmath>
#include <numbers>
#include <ostream>
#include <string>
#include <vector>

namespace vmap {

/// Wraps an angle to (-pi, pi].
inline double wrap_angle(double a) {
  detail::check(std::isfinite(a), "wrap_angle: the angle is not a finite number");
  constexpr double pi = std::numbers::pi;
  double w = std::remainder(a, 2.0 * pi);  // [-pi, pi]
  if (w <= -pi) w += 2.0 * pi;             // -pi itself maps to +pi
  return w;
}

/// A rigid motion of the plane: rotation by theta then translation by (x, y). As a
/// robot pose it maps robot coordinates to world coordinates. theta is always kept in
/// (-pi, pi].
class Pose2 {
 public:
  Pose2() = default;
  Pose2(double x, double y, double theta) : t_(x, y), theta_(wrap_angle(theta)) {
    detail::check(std::isfinite(x) && std::isfinite(y), "Pose2: x and y must be finite numbers");
  }
  Pose2(const Eigen::Vector2d& t, double theta) : Pose2(t.x(), t.y(), theta) {}

  [[nodiscard]] double x() const noexcept { return t_.x(); }
  [[nodiscard]] double y() const noexcept { return t_.y(); }
  [[nodiscard]] double theta() const noexcept { return theta_; }
  [[nodiscard]] const Eigen::Vector2d& translation() const noexcept { return t_; }
  [[nodiscard]] Eigen::Matrix2d rotation() const { return Eigen::Rotation2Dd(theta_).toRotationMatrix(); }

  /// The 3x3 homogeneous matrix [R t; 0 0 1].
  [[nodiscard]] Eigen::Matrix3d matrix() const {
    Eigen::Matrix3d m = Eigen::Matrix3d::Identity();
    m.topLeftCorner<2, 2>() = rotation();
    m.topRightCorner<2, 1>() = t_;
    return m;
  }

  /// Composition: (a * b) applies b first, then a (a's frame holds b).
  [[nodiscard]] Pose2 operator*(const Pose2& b) const {
    return Pose2(t_ + rotation() * b.t_, theta_ + b.theta_);
  }

  /// Maps a point given in this pose's frame to the outer frame.
  [[nodiscard]] Eigen::Vector2d operator*(const Eigen::Vector2d& p) const { return t_ + rotation() * p; }

  [[nodiscard]] Pose2 inverse() const {
    const Eigen::Vector2d ti = -(rotation().transpose() * t_);
    return Pose2(ti, -theta_);
  }

  /// The motion from this pose to `b` expressed in this pose's frame:
  /// inverse() * b, the paper's odometry increment `pose2DInverse(a) * b`.
  [[nodiscard]] Pose2 between(const Pose2& b) const { return inverse() * b; }

  [[nodiscard]] double distance(const Pose2& b) const { return (t_ - b.t_).norm(); }

  friend std::ostream& operator<<(std::ostream& os, const Pose2& p) {
    return os << "(" << p.x() << ", " << p.y() << ", " << p.theta() << ")";
  }

 private:
  Eigen::Vector2d t_ = Eigen::Vector2d::Zero();
  double theta_ = 0.0;
};

/// Interpolates on SE(2) the simple way robots do: position linearly, angle along the
/// shorter arc. s = 0 gives a, s = 1 gives b.
inline Pose2 interpolate(const Pose2& a, const Pose2& b, double s) {
  detail::check(std::isfinite(s), "interpolate: the fraction s must be a finite number");
  const double dtheta = wrap_angle(b.theta() - a.theta());
  return Pose2(a.translation() + s * (b.translation() - a.translation()), a.theta() + s * dtheta);
}

/// Odometry integration: pose_{k+1} = pose_k * increment_k. Returns start followed by
/// one pose per increment.
inline std::vector<Pose2> integrate_odometry(const Pose2& start, const std::vector<Pose2>& increments) {
  std::vector<Pose2> out;
  out.reserve(increments.size() + 1);
  out.push_back(start);
  for (const auto& inc : increments) out.push_back(out.back() * inc);
  return out;
}

/// The increments between consecutive poses (the inverse of integrate_odometry).
inline std::vector<Pose2> odometry_increments(const std::vector<Pose2>& poses) {
  std::vector<Pose2> out;
  for (std::size_t k = 1; k < poses.size(); ++k) out.push_back(poses[k - 1].between(poses[k]));
  return out;
}

/// Mean of poses: arithmetic mean of positions, circular mean of angles (the mean of
/// unit vectors, so 179 deg and -179 deg average to 180 deg, not 0). An empty input is
/// an Error.
inline Pose2 mean_pose(const std::vector<Pose2>& poses) {
  detail::check(!poses.empty(), "mean_pose: no poses given");
  Eigen::Vector2d t = Eigen::Vector2d::Zero();
  double c = 0.0, s = 0.0;
  for (const auto& p : poses) {
    t += p.translation();
    c += std::cos(p.theta());
    s += std::sin(p.theta());
  }
  t /= static_cast<double>(poses.size());
  const double theta = (std::abs(c) + std::abs(s) > 1e-12) ? std::atan2(s, c) : poses.front().theta();
  return Pose2(t, theta);
}

}  // namespace vmap
