// Exports for other tools (io/exports.hpp): the TUM trajectory read back by vmap's own
// TUM reader, g2o lines checked field by field, loop pairs and key image lists.
#include <vmap/io/exports.hpp>
#include <vmap/io/poses.hpp>

#include <doctest/doctest.h>
#include <opencv2/calib3d.hpp>

#include <cmath>
#include <random>
#include <sstream>
#include <string>
#include <vector>

namespace {

cv::Matx33d rodrigues(double x, double y, double z) {
  cv::Matx33d r;
  cv::Rodrigues(cv::Vec3d(x, y, z), r);
  return r;
}

std::vector<std::string> tokens(const std::string& line) {
  std::istringstream in(line);
  std::vector<std::string> out;
  for (std::string t; in >> t;) out.push_back(t);
  return out;
}

}  // namespace

TEST_CASE("quaternion_from_rotation inverts rotation_from_quaternion, also near half turns") {
  std::mt19937 rng(7);
  std::uniform_real_distribution<double> u(-3.1, 3.1);
  std::vector<cv::Matx33d> rotations = {cv::Matx33d::eye(), rodrigues(M_PI, 0, 0), rodrigues(0, M_PI, 0),
                                        rodrigues(0, 0, M_PI), rodrigues(0, 3.14159, 0.001)};
  for (int k = 0; k < 200; ++k) rotations.push_back(rodrigues(u(rng), u(rng), u(rng)));
  for (const auto& r : rotations) {
    const auto q = vmap::quaternion_from_rotation(r);
    CHECK(q[3] >= 0.0);
    CHECK(std::abs(q[0] * q[0] + q[1] * q[1] + q[2] * q[2] + q[3] * q[3] - 1.0) < 1e-12);
    CHECK(cv::norm(vmap::rotation_from_quaternion(q[0], q[1], q[2], q[3]) - r) < 1e-9);
  }
}

TEST_CASE("a TUM trajectory is read back by load_tum_poses: same times, positions and rotations") {
  std::vector<vmap::CameraPose> poses;
  for (int k = 0; k < 20; ++k)
    poses.push_back({1403636579.763555584 + 0.05 * k, {0.1 * k, -2.5 + k, 1e-3 * k * k}, rodrigues(0.1 * k, -0.2, 0.05 * k)});
  const std::string text = vmap::tum_trajectory_text(poses);
  CHECK(text.rfind("# timestamp tx ty tz qx qy qz qw\n", 0) == 0);
  const auto back = vmap::parse_tum_poses(text, "key_images.tum");
  REQUIRE(back.size() == poses.size());
  for (std::size_t k = 0; k < poses.size(); ++k) {
    CHECK(back[k].timestamp == poses[k].timestamp);  // shortest round-trip form
    CHECK(back[k].position == poses[k].position);
    CHECK(cv::norm(back[k].rotation - poses[k].rotation) < 1e-8);
  }
}

TEST_CASE("g2o EDGE_SE3:QUAT: ids, the relative pose T_from^-1 T_to, and the information matrix") {
  const vmap::CameraPose a{1.0, {1.0, 2.0, 3.0}, rodrigues(0, 0, M_PI / 2)};
  const vmap::CameraPose b{2.0, {1.0, 3.0, 3.0}, rodrigues(0, 0, M_PI)};
  const std::string line = vmap::g2o_edge_line(7, 3, a, b, 4.0, 9.0);
  CHECK(line.back() == '\n');
  const auto t = tokens(line);
  REQUIRE(t.size() == 3 + 7 + 21);
  CHECK(t[0] == "EDGE_SE3:QUAT");
  CHECK(t[1] == "7");
  CHECK(t[2] == "3");
  // b seen from a: a faces +y (turned 90 degrees about z), b lies 1 m along world +y,
  // i.e. 1 m along a's x axis, turned a further 90 degrees: q = (0, 0, sin 45, cos 45).
  const std::vector<double> pose = {1.0, 0.0, 0.0, 0.0, 0.0, std::sqrt(0.5), std::sqrt(0.5)};
  for (std::size_t k = 0; k < 7; ++k) CHECK(std::stod(t[3 + k]) == doctest::Approx(pose[k]).epsilon(1e-9));
  // Upper triangle of the 6x6 information matrix, row by row.
  std::size_t at = 10;
  for (int i = 0; i < 6; ++i)
    for (int j = i; j < 6; ++j, ++at) CHECK(std::stod(t[at]) == (i != j ? 0.0 : i < 3 ? 4.0 : 9.0));
}

TEST_CASE("loop pairs and key image lists carry names and times exact to the nanosecond") {
  const std::string pairs = vmap::loop_pairs_text(
      {{5, 1, 1403636590500000000LL, 1403636580763555584LL, "b.png", "a name.png", 120},
       {6, 2, -500000000LL, 12000000000LL, "line\nbreak", "", 7}});
  CHECK(pairs == "# query_time match_time query_name match_name inliers\n"
                 "1403636590.5 1403636580.763555584 b.png a_name.png 120\n"
                 "-0.5 12 line_break - 7\n");
  std::vector<vmap::KeyImage> keys(2);
  keys[0].frame_index = 0;
  keys[0].name = "euroc.mp4#0";
  keys[0].time_ns = 0;
  keys[1].frame_index = 12;
  keys[1].name = "two words.png";
  keys[1].time_ns = 1305031229528748000LL;
  CHECK(vmap::key_images_text(keys) ==
        "# frame_index name timestamp\n0 euroc.mp4#0 0\n12 two_words.png 1305031229.528748\n");
}
