#include <vmap/io/atomic_file.hpp>
#include <vmap/som/gcs.hpp>
#include <vmap/som/pose_io.hpp>
#include <vmap/som/pose_map.hpp>

#include "support/shared_data.hpp"

#include <doctest/doctest.h>

#include <Eigen/Geometry>

#include <cmath>
#include <numbers>
#include <vector>

using vmap::Pose2;

namespace {

using Gcs2 = vmap::GrowingCellStructures<double, 2>;

// A small trained network on points of a line, so that bmu(x) is easy to predict.
Gcs2 small_network() {
  std::vector<Gcs2::Vector> data;
  for (int i = 0; i < 60; ++i) data.emplace_back(i % 6, 0.1 * (i % 2));
  Gcs2 g({.lambda = 20, .max_cells = 6, .seed = 1});
  g.train(data);
  return g;
}

}  // namespace

TEST_CASE("PoseMap: means, spread and counts from hand-made assignments") {
  const Gcs2 g = small_network();
  REQUIRE(g.size() == 6);
  const std::vector<std::size_t> winners{0, 0, 0, 2, 2, 5};
  const std::vector<Pose2> poses{Pose2(0, 0, 0.1), Pose2(2, 0, 0.3), Pose2(1, 3, 0.2), Pose2(5, 5, std::numbers::pi - 0.1),
                                 Pose2(7, 5, -std::numbers::pi + 0.1), Pose2(-1, -1, 0)};
  const auto m = vmap::PoseMap<Gcs2>::from_assignments(g, winners, poses);
  const auto& n = m.neurons();
  REQUIRE(n.size() == 6);
  CHECK(n[0].count == 3);
  CHECK(n[0].mean.x() == doctest::Approx(1.0));
  CHECK(n[0].mean.y() == doctest::Approx(1.0));
  CHECK(n[0].mean.theta() == doctest::Approx(0.2));
  CHECK(n[0].spread.x() == doctest::Approx(std::sqrt(2.0 / 3.0)));
  CHECK(n[0].spread.y() == doctest::Approx(std::sqrt(2.0)));
  CHECK(n[2].mean.x() == doctest::Approx(6.0));
  CHECK(n[2].mean.theta() == doctest::Approx(std::numbers::pi));  // circular mean
  CHECK(n[2].spread.x() == doctest::Approx(1.0));
  CHECK(n[5].count == 1);
  CHECK(n[5].spread.isZero());
  CHECK_FALSE(n[1].has_pose());
  CHECK_FALSE(n[3].has_pose());
  CHECK(m.neurons_with_pose() == 3);

  // A query exactly at a neuron with a pose gets that neuron's pose at distance 0.
  const auto one = m.localize({g.weights()[2]});
  REQUIRE(one.matches.size() == 1);
  CHECK(one.matches[0].neuron == 2);
  CHECK(one.matches[0].distance == doctest::Approx(0.0));
  CHECK_FALSE(one.matches[0].substituted);
  CHECK(one.pose.x() == doctest::Approx(6.0));
  // Two queries: the mean of the two neurons' poses (Algorithm 5).
  const auto two = m.localize({g.weights()[0], g.weights()[5]});
  CHECK(two.pose.x() == doctest::Approx(0.0));
  CHECK(two.pose.y() == doctest::Approx(0.0));
  // A query at a neuron without a pose falls back to the nearest neuron that has one.
  const auto sub = m.localize({g.weights()[1]});
  CHECK(sub.matches[0].substituted);
  CHECK(n[sub.matches[0].neuron].has_pose());
  CHECK(sub.matches[0].distance > 0.0);

  CHECK_THROWS_AS((void)m.localize({}), vmap::Error);
  CHECK_THROWS_AS(vmap::PoseMap<Gcs2>::from_assignments(g, {0, 1}, poses), vmap::Error);     // mismatched
  CHECK_THROWS_AS(vmap::PoseMap<Gcs2>::from_assignments(g, {9}, {Pose2()}), vmap::Error);  // no such neuron
  CHECK_THROWS_AS(vmap::PoseMap<Gcs2>::from_assignments(Gcs2{}, {}, {}), vmap::Error);       // untrained
}

TEST_CASE("PoseMap from vectors: Algorithm 4 assigns each vector to its winner") {
  const Gcs2 g = small_network();
  std::vector<Gcs2::Vector> v;
  std::vector<Pose2> poses;
  for (std::size_t c = 0; c < g.size(); ++c) {
    v.push_back(g.weights()[c]);
    poses.emplace_back(static_cast<double>(c), 2.0 * static_cast<double>(c), 0.0);
  }
  const vmap::PoseMap<Gcs2> m(g, v, poses);
  for (std::size_t c = 0; c < g.size(); ++c) {
    CHECK(m.neurons()[c].count == 1);
    CHECK(m.neurons()[c].mean.y() == doctest::Approx(2.0 * static_cast<double>(c)));
  }
  CHECK_THROWS_AS(vmap::PoseMap<Gcs2>(g, v, {Pose2()}), vmap::Error);
}

TEST_CASE("pose files: TUM, KITTI and x y theta, projected to the floor") {
  const auto dir = vmap::test::scratch_dir("som_pose_io");
  // TUM world has z up; a camera looking along world +x has its optical axis (z) = +x.
  // Rotating that camera by yaw 90 degrees makes it look along +y.
  Eigen::Matrix3d look_x;
  look_x.col(0) = Eigen::Vector3d(0, -1, 0);  // camera right
  look_x.col(1) = Eigen::Vector3d(0, 0, -1);  // camera down
  look_x.col(2) = Eigen::Vector3d(1, 0, 0);   // optical axis
  const Eigen::Quaterniond q0(look_x);
  const Eigen::Quaterniond q90(Eigen::AngleAxisd(std::numbers::pi / 2, Eigen::Vector3d::UnitZ()) * look_x);
  auto line = [](double t, double x, double y, double z, const Eigen::Quaterniond& q) {
    return std::to_string(t) + " " + std::to_string(x) + " " + std::to_string(y) + " " + std::to_string(z) + " " +
           std::to_string(q.x()) + " " + std::to_string(q.y()) + " " + std::to_string(q.z()) + " " +
           std::to_string(q.w()) + "\n";
  };
  vmap::write_file_atomically(dir / "gt.txt", "# timestamp tx ty tz qx qy qz qw\n" + line(1.5, 1, 2, 1.1, q0) +
                                                  line(2.5, -3, 4, 1.2, q90));
  CHECK(vmap::guess_pose_format(dir / "gt.txt") == vmap::PoseFormat::tum);
  const auto tum = vmap::read_tum_poses(dir / "gt.txt");
  REQUIRE(tum.size() == 2);
  CHECK(tum[0].timestamp == doctest::Approx(1.5));
  CHECK(tum[0].pose.x() == doctest::Approx(1.0));
  CHECK(tum[0].pose.y() == doctest::Approx(2.0));
  CHECK(tum[0].pose.theta() == doctest::Approx(0.0).epsilon(1e-5));
  CHECK(tum[1].pose.theta() == doctest::Approx(std::numbers::pi / 2).epsilon(1e-5));

  // KITTI: camera frame x right, y down, z forward; identity = looking along +z = floor
  // heading pi/2 (angle from +x in the (x, z) plane).
  vmap::write_file_atomically(dir / "poses.txt", "1 0 0 3 0 1 0 -0.5 0 0 1 7\n0 0 1 4 0 1 0 0 -1 0 0 8\n");
  const auto kitti = vmap::read_kitti_poses(dir / "poses.txt");
  REQUIRE(kitti.size() == 2);
  CHECK(kitti[0].pose.x() == doctest::Approx(3.0));
  CHECK(kitti[0].pose.y() == doctest::Approx(7.0));
  CHECK(kitti[0].pose.theta() == doctest::Approx(std::numbers::pi / 2));
  CHECK(kitti[1].pose.theta() == doctest::Approx(0.0));  // optical axis along +x
  vmap::write_file_atomically(dir / "timed.txt", "0.1 1 0 0 3 0 1 0 -0.5 0 0 1 7\n");
  CHECK(vmap::read_kitti_poses(dir / "timed.txt")[0].timestamp == doctest::Approx(0.1));

  vmap::write_file_atomically(dir / "xyt.txt", "0 0 0\n1.5 -2 3.0\n");
  const auto xyt = vmap::read_poses(dir / "xyt.txt", vmap::guess_pose_format(dir / "xyt.txt"));
  REQUIRE(xyt.size() == 2);
  CHECK(xyt[1].pose.y() == doctest::Approx(-2.0));
  CHECK(xyt[1].pose.theta() == doctest::Approx(3.0));

  vmap::write_file_atomically(dir / "bad1.txt", "1 2 x\n");
  CHECK_THROWS_WITH_AS(vmap::read_xytheta_poses(dir / "bad1.txt"), doctest::Contains("'x' is not a number"), vmap::Error);
  vmap::write_file_atomically(dir / "bad2.txt", "1 2 3 4\n");
  CHECK_THROWS_AS(vmap::read_xytheta_poses(dir / "bad2.txt"), vmap::Error);
  CHECK_THROWS_AS(vmap::guess_pose_format(dir / "bad2.txt"), vmap::Error);
  vmap::write_file_atomically(dir / "empty.txt", "# nothing\n");
  CHECK_THROWS_AS(vmap::read_tum_poses(dir / "empty.txt"), vmap::Error);
  vmap::write_file_atomically(dir / "zeroq.txt", "1 0 0 0 0 0 0 0\n");
  CHECK_THROWS_AS(vmap::read_tum_poses(dir / "zeroq.txt"), vmap::Error);
  CHECK_THROWS_AS(vmap::read_tum_poses(dir / "missing.txt"), vmap::Error);
}
