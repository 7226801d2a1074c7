#include <vmap/geometry/pose2.hpp>

#include <doctest/doctest.h>

#include <cmath>
#include <limits>
#include <numbers>
#include <vector>

using vmap::Pose2;

namespace {
constexpr double pi = std::numbers::pi;

void check_near(const Pose2& a, const Pose2& b, double tol = 1e-12) {
  CHECK(a.x() == doctest::Approx(b.x()).epsilon(tol).scale(1.0));
  CHECK(a.y() == doctest::Approx(b.y()).epsilon(tol).scale(1.0));
  CHECK(std::abs(vmap::wrap_angle(a.theta() - b.theta())) < 1e-12);
}
}  // namespace

TEST_CASE("wrap_angle maps to (-pi, pi]") {
  CHECK(vmap::wrap_angle(0.0) == 0.0);
  CHECK(vmap::wrap_angle(pi) == doctest::Approx(pi));
  CHECK(vmap::wrap_angle(-pi) == doctest::Approx(pi));  // -pi is outside the interval
  CHECK(vmap::wrap_angle(3 * pi) == doctest::Approx(pi));
  CHECK(vmap::wrap_angle(2 * pi + 0.25) == doctest::Approx(0.25));
  CHECK(vmap::wrap_angle(-2 * pi - 0.25) == doctest::Approx(-0.25));
  CHECK(vmap::wrap_angle(-pi + 1e-9) == doctest::Approx(-pi + 1e-9));
  CHECK_THROWS_AS(vmap::wrap_angle(std::numeric_limits<double>::quiet_NaN()), vmap::Error);
  CHECK_THROWS_AS(Pose2(std::numeric_limits<double>::infinity(), 0, 0), vmap::Error);
}

TEST_CASE("Pose2 group identities") {
  const Pose2 a(1.0, -2.0, 0.7), b(-0.5, 3.0, -2.9), c(2.0, 0.25, 2.5);
  check_near(a * a.inverse(), Pose2());
  check_near(a.inverse() * a, Pose2());
  check_near((a * b) * c, a * (b * c));
  check_near((a * b).inverse(), b.inverse() * a.inverse());
  check_near(a * a.between(b), b);               // a composed with the increment reaches b
  check_near(a.between(b), a.inverse() * b);     // the paper's pose2DInverse(a) * b
  // matrix form is a homomorphism
  CHECK((a * b).matrix().isApprox(a.matrix() * b.matrix(), 1e-12));
  // angles of compositions are wrapped: 2.5 + 2.5 = 5 -> 5 - 2 pi
  CHECK((c * c).theta() == doctest::Approx(5.0 - 2 * pi));
  // exact values: a quarter turn then one metre forward
  const Pose2 q(0, 0, pi / 2), fwd(1, 0, 0);
  check_near(q * fwd, Pose2(0, 1, pi / 2));
  const Eigen::Vector2d p = a * Eigen::Vector2d(1, 0);
  CHECK(p.x() == doctest::Approx(1.0 + std::cos(0.7)));
  CHECK(p.y() == doctest::Approx(-2.0 + std::sin(0.7)));
  CHECK(a.distance(b) == doctest::Approx(std::hypot(1.5, 5.0)));
}

TEST_CASE("interpolate takes the shorter arc") {
  const Pose2 a(0, 0, pi - 0.1), b(2, 4, -pi + 0.1);
  check_near(vmap::interpolate(a, b, 0.0), a);
  check_near(vmap::interpolate(a, b, 1.0), b);
  const Pose2 mid = vmap::interpolate(a, b, 0.5);
  CHECK(mid.x() == doctest::Approx(1.0));
  CHECK(mid.y() == doctest::Approx(2.0));
  CHECK(mid.theta() == doctest::Approx(pi));
}

TEST_CASE("odometry integration inverts the increments") {
  std::vector<Pose2> path;
  for (int k = 0; k < 20; ++k) path.emplace_back(std::cos(0.3 * k) * k, std::sin(0.2 * k), 0.37 * k);
  const auto inc = vmap::odometry_increments(path);
  REQUIRE(inc.size() == path.size() - 1);
  const auto back = vmap::integrate_odometry(path.front(), inc);
  REQUIRE(back.size() == path.size());
  for (std::size_t k = 0; k < path.size(); ++k) check_near(back[k], path[k], 1e-9);
  // a square: four times (1 m forward, quarter turn) comes back to the start
  const auto square = vmap::integrate_odometry(Pose2(), std::vector<Pose2>(4, Pose2(1, 0, pi / 2)));
  check_near(square.back(), Pose2(), 1e-12);
  check_near(square[2], Pose2(1, 1, pi), 1e-12);
}

TEST_CASE("mean_pose averages angles on the circle") {
  const Pose2 m = vmap::mean_pose({Pose2(0, 0, pi - 0.1), Pose2(2, 2, -pi + 0.1)});
  CHECK(m.x() == doctest::Approx(1.0));
  CHECK(m.y() == doctest::Approx(1.0));
  CHECK(m.theta() == doctest::Approx(pi));
  CHECK_THROWS_AS(vmap::mean_pose({}), vmap::Error);
}
