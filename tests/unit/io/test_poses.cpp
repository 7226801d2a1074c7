// 3-D camera poses from TUM and KITTI trajectory files: exact values on hand-written
// lines, the errors a user meets (wrong field count, zero quaternion, non-numbers,
// missing file), and the two trajectories in ../shared/data.
#include <vmap/io/atomic_file.hpp>
#include <vmap/io/poses.hpp>

#include "support/shared_data.hpp"

#include <doctest/doctest.h>
#include <Eigen/Geometry>

#include <cmath>
#include <limits>
#include <string>
#include <vector>

namespace {

void check_matrix(const cv::Matx33d& got, const cv::Matx33d& want, double tol) {
  for (int r = 0; r < 3; ++r)
    for (int c = 0; c < 3; ++c) {
      CAPTURE(r);
      CAPTURE(c);
      CHECK(std::abs(got(r, c) - want(r, c)) <= tol);
    }
}

void check_vec(const cv::Vec3d& got, const cv::Vec3d& want, double tol) {
  for (int k = 0; k < 3; ++k) {
    CAPTURE(k);
    CHECK(std::abs(got[k] - want[k]) <= tol);
  }
}

/// Largest entry of |R^T R - I|.
double orthonormality_error(const cv::Matx33d& r) {
  const cv::Matx33d e = r.t() * r - cv::Matx33d::eye();
  double worst = 0.0;
  for (double v : e.val) worst = std::max(worst, std::abs(v));
  return worst;
}

}  // namespace

TEST_CASE("poses: quaternion to rotation, exact") {
  // q = (1, 2, 3, 4) / sqrt(30): every entry of R is a multiple of 1/15.
  const cv::Matx33d want(2 / 15.0, -10 / 15.0, 11 / 15.0,  //
                         14 / 15.0, 5 / 15.0, 2 / 15.0,    //
                         -5 / 15.0, 10 / 15.0, 10 / 15.0);
  check_matrix(vmap::rotation_from_quaternion(1, 2, 3, 4), want, 1e-12);
  // Scale does not matter (normalised), nor sign (q and -q are the same rotation).
  check_matrix(vmap::rotation_from_quaternion(0.1, 0.2, 0.3, 0.4), want, 1e-12);
  check_matrix(vmap::rotation_from_quaternion(-1, -2, -3, -4), want, 1e-12);
  // Against Eigen's independent conversion (Eigen takes w first).
  const Eigen::Matrix3d e = Eigen::Quaterniond(4, 1, 2, 3).normalized().toRotationMatrix();
  check_matrix(vmap::rotation_from_quaternion(1, 2, 3, 4),
               cv::Matx33d(e(0, 0), e(0, 1), e(0, 2), e(1, 0), e(1, 1), e(1, 2), e(2, 0), e(2, 1), e(2, 2)), 1e-12);
  check_matrix(vmap::rotation_from_quaternion(0, 0, 0, 1), cv::Matx33d::eye(), 0.0);
  CHECK_THROWS_AS((void)vmap::rotation_from_quaternion(0, 0, 0, 0), vmap::Error);
  CHECK_THROWS_AS((void)vmap::rotation_from_quaternion(0, 0, 0, std::numeric_limits<double>::quiet_NaN()), vmap::Error);
}

TEST_CASE("poses: TUM lines") {
  const auto poses = vmap::parse_tum_poses(
      "# timestamp tx ty tz qx qy qz qw\n"
      "\n"
      "1.5 1 2 3 0 0 0 1\n"
      "  2.25\t-1 0.5 1.25\t0 0 0.7071067811865476 0.7071067811865476\r\n"
      "3 0 0 0 1 2 3 4\n",  // a non-unit quaternion is normalised
      "gt.txt");
  REQUIRE(poses.size() == 3);
  CHECK(poses[0].timestamp == 1.5);
  check_vec(poses[0].position, {1, 2, 3}, 0.0);
  check_matrix(poses[0].rotation, cv::Matx33d::eye(), 0.0);
  check_vec(poses[0].viewing_direction(), {0, 0, 1}, 0.0);

  // Yaw by +90 deg about world z: camera x -> world y, camera z stays world z.
  CHECK(poses[1].timestamp == 2.25);
  check_vec(poses[1].position, {-1, 0.5, 1.25}, 0.0);
  check_matrix(poses[1].rotation, cv::Matx33d(0, -1, 0, 1, 0, 0, 0, 0, 1), 1e-12);
  check_vec(poses[1].to_world({1, 0, 0}), {-1, 1.5, 1.25}, 1e-12);

  check_vec(poses[2].viewing_direction(), {11 / 15.0, 2 / 15.0, 10 / 15.0}, 1e-12);
  CHECK(orthonormality_error(poses[2].rotation) < 1e-15);
}

TEST_CASE("poses: KITTI lines, with and without time") {
  // Turned 90 deg about y (the camera's down axis): it looks along world +x.
  const auto poses = vmap::parse_kitti_poses(
      "1 0 0 0 0 1 0 0 0 0 1 0\n"
      "0 0 1 4 0 1 0 -0.5 -1 0 0 8\n",
      "poses.txt");
  REQUIRE(poses.size() == 2);
  CHECK(poses[0].timestamp == 0.0);  // no time: the pose index
  CHECK(poses[1].timestamp == 1.0);
  check_matrix(poses[0].rotation, cv::Matx33d::eye(), 0.0);
  check_vec(poses[1].position, {4, -0.5, 8}, 0.0);
  check_matrix(poses[1].rotation, cv::Matx33d(0, 0, 1, 0, 1, 0, -1, 0, 0), 0.0);
  check_vec(poses[1].viewing_direction(), {1, 0, 0}, 0.0);
  check_vec(poses[1].to_world({0, 0, 2}), {6, -0.5, 8}, 0.0);

  const auto timed = vmap::parse_kitti_poses("0.1038752 0 0 1 4 0 1 0 -0.5 -1 0 0 8\n");
  REQUIRE(timed.size() == 1);
  CHECK(timed[0].timestamp == 0.1038752);
  check_vec(timed[0].position, {4, -0.5, 8}, 0.0);
  check_matrix(timed[0].rotation, poses[1].rotation, 0.0);
}

TEST_CASE("poses: format guessing") {
  CHECK(vmap::guess_camera_pose_format("# c\n1 2 3 4 0 0 0 1\n") == vmap::CameraPoseFormat::tum);
  CHECK(vmap::guess_camera_pose_format("1 0 0 0 0 1 0 0 0 0 1 0\n") == vmap::CameraPoseFormat::kitti);
  CHECK(vmap::guess_camera_pose_format("0 1 0 0 0 0 1 0 0 0 0 1 0\n") == vmap::CameraPoseFormat::kitti);
  CHECK_THROWS_WITH_AS((void)vmap::guess_camera_pose_format("\n0 0 0\n", "xyt.txt"),
                       doctest::Contains("xyt.txt:2: 3 numbers a line is neither TUM (8) nor KITTI (12 or 13)"),
                       vmap::Error);
  CHECK(vmap::camera_pose_format_for(8) == vmap::CameraPoseFormat::tum);
  CHECK(vmap::camera_pose_format_for(13) == vmap::CameraPoseFormat::kitti);
  CHECK_FALSE(vmap::camera_pose_format_for(3).has_value());
  CHECK(vmap::parse_camera_poses("1 2 3 4 0 0 0 1\n", vmap::CameraPoseFormat::tum).size() == 1);
}

TEST_CASE("poses: errors name the file, the line and what was wrong") {
  using doctest::Contains;
  CHECK_THROWS_WITH_AS((void)vmap::parse_tum_poses("# c\n1 2 3 4 0 0 0 1\n1 2 3 4 0 0 1\n", "p.txt"),
                       Contains("p.txt:3: 7 numbers, a TUM pose has 8"), vmap::Error);
  CHECK_THROWS_WITH_AS((void)vmap::parse_tum_poses("1 2 3 4 0 0 0 1 9\n", "p.txt"),
                       Contains("p.txt:1: 9 numbers, a TUM pose has 8"), vmap::Error);
  CHECK_THROWS_WITH_AS((void)vmap::parse_tum_poses("1 2 3 4 0 0 0 0\n", "p.txt"),
                       Contains("p.txt:1: the quaternion (qx qy qz qw) is zero"), vmap::Error);
  CHECK_THROWS_WITH_AS((void)vmap::parse_tum_poses("1 2 3 x 0 0 0 1\n", "p.txt"), Contains("p.txt:1: 'x' is not a number"),
                       vmap::Error);
  CHECK_THROWS_WITH_AS((void)vmap::parse_tum_poses("1 2 3 4.5m 0 0 0 1\n", "p.txt"),
                       Contains("p.txt:1: '4.5m' is not a number"), vmap::Error);
  // A decimal comma is not read as two numbers.
  CHECK_THROWS_WITH_AS((void)vmap::parse_tum_poses("1 2 3 4,5 0 0 0 1\n", "p.txt"),
                       Contains("'4,5' is not a number"), vmap::Error);
  CHECK_THROWS_WITH_AS((void)vmap::parse_tum_poses("1 2 nan 4 0 0 0 1\n", "p.txt"),
                       Contains("p.txt:1: 'nan' is not finite"), vmap::Error);
  CHECK_THROWS_WITH_AS((void)vmap::parse_tum_poses("1 2 1e999 4 0 0 0 1\n", "p.txt"),
                       Contains("'1e999' is not a number"), vmap::Error);
  CHECK_THROWS_WITH_AS((void)vmap::parse_tum_poses("# only a comment\n\n", "p.txt"), Contains("p.txt: holds no pose"),
                       vmap::Error);
  CHECK_THROWS_AS((void)vmap::parse_tum_poses(""), vmap::Error);
  // A leading '+' is a number, as printf("%+f") writes it.
  CHECK(vmap::parse_tum_poses("+1 2 3 4 0 0 0 +1\n")[0].timestamp == 1.0);

  CHECK_THROWS_WITH_AS((void)vmap::parse_kitti_poses("1 0 0 0 0 1 0 0 0 0 1\n", "k.txt"),
                       Contains("k.txt:1: 11 numbers, a KITTI pose has 12"), vmap::Error);
  CHECK_THROWS_WITH_AS((void)vmap::parse_kitti_poses("1 0 0 0 0 1 0 0 0 0 1 0\n2 0 0 0 0 2 0 0 0 0 2 0\n", "k.txt"),
                       Contains("k.txt:2: the 3x3 part is not a rotation"), vmap::Error);
  // A reflection is orthonormal but not a rotation.
  CHECK_THROWS_WITH_AS((void)vmap::parse_kitti_poses("-1 0 0 0 0 1 0 0 0 0 1 0\n", "k.txt"),
                       Contains("k.txt:1: the 3x3 part is not a rotation"), vmap::Error);

  const auto dir = vmap::test::scratch_dir("io_poses");
  CHECK_THROWS_WITH_AS((void)vmap::load_tum_poses(dir / "missing.txt"), Contains("missing.txt"), vmap::Error);
  CHECK_THROWS_AS((void)vmap::load_kitti_poses(dir / "missing.txt"), vmap::Error);
  vmap::write_file_atomically(dir / "short.txt", "1 2 3 4 0 0 0 1\n5 6 7\n");
  CHECK_THROWS_WITH_AS((void)vmap::load_camera_poses(dir / "short.txt"),
                       Contains((dir / "short.txt").string().append(":2: 3 numbers, a TUM pose has 8").c_str()), vmap::Error);
}

TEST_SUITE("data") {
  TEST_CASE("poses: tum_fr3_cabinet_kf truth poses") {
    const auto path = vmap::test::data_path("tum_fr3_cabinet_kf/truth_cam_poses.txt");
    const auto poses = vmap::load_tum_poses(path);
    REQUIRE(poses.size() == 58);
    CHECK(vmap::load_camera_poses(path).size() == 58);
    // First line: 1341841278.8427 -2.5508 0.9872 1.1019 -0.4871 0.7673 -0.3519 0.2239
    CHECK(poses[0].timestamp == 1341841278.8427);
    check_vec(poses[0].position, {-2.5508, 0.9872, 1.1019}, 0.0);
    check_matrix(poses[0].rotation, vmap::rotation_from_quaternion(-0.4871, 0.7673, -0.3519, 0.2239), 0.0);
    CHECK(poses[57].timestamp == 1341841317.2506);
    for (std::size_t i = 0; i < poses.size(); ++i) {
      CAPTURE(i);
      CHECK(orthonormality_error(poses[i].rotation) < 1e-12);
      CHECK(cv::determinant(poses[i].rotation) == doctest::Approx(1.0).epsilon(1e-12));
      if (i > 0) CHECK(poses[i].timestamp > poses[i - 1].timestamp);
      // A hand-held camera in a z-up room: about 1.1 m high, looking roughly level.
      CHECK(std::abs(poses[i].position[2] - 1.12) < 0.4);
      CHECK(std::abs(poses[i].viewing_direction()[2]) < 0.8);
    }
  }

  TEST_CASE("poses: kitti07_160 poses") {
    const auto path = vmap::test::data_path("kitti07_160/poses.txt");
    const auto poses = vmap::load_kitti_poses(path);
    REQUIRE(poses.size() == 160);
    CHECK(vmap::load_camera_poses(path).size() == 160);
    // The world is camera 0's first frame.
    CHECK(poses[0].timestamp == 0.0);
    check_matrix(poses[0].rotation, cv::Matx33d::eye(), 1e-9);
    check_vec(poses[0].position, {0, 0, 0}, 1e-9);
    // Last line: 16.53376 0.9926196 0.01845295 -0.1198577 -76.96463 -0.0195747 0.9997748
    //            -0.008188277 0.9352274 0.1196796 0.01047402 0.9927573 15.68785
    CHECK(poses[159].timestamp == 16.53376);
    check_vec(poses[159].position, {-76.96463, 0.9352274, 15.68785}, 0.0);
    check_vec(poses[159].viewing_direction(), {-0.1198577, -0.008188277, 0.9927573}, 0.0);
    for (std::size_t i = 0; i < poses.size(); ++i) {
      CAPTURE(i);
      CHECK(orthonormality_error(poses[i].rotation) < 1e-5);  // 7 printed digits
      if (i > 0) CHECK(poses[i].timestamp > poses[i - 1].timestamp);
      // A car on a road: the optical axis stays near the y = 0 (horizontal) plane.
      CHECK(std::abs(poses[i].viewing_direction()[1]) < 0.1);
    }
  }
}
