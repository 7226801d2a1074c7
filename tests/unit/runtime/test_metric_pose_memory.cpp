// The metric pose of a localized query in a memory (memory/metric_pose.hpp through
// AnyMemory): what a memory without poses or without a camera answers, how a sequence
// carries the pose, the pose graph exported for an optimizer (read back), and on real
// frames with every 5th held out the poses against the ground truth (subsets of the
// benchmark's sequences, examples/results/localize.md, "Where am I, in metres").
#include "support/sample_memory.hpp"
#include "support/shared_data.hpp"

#include <vmap/io/calibration.hpp>
#include <vmap/io/poses.hpp>
#include <vmap/memory/metric_pose.hpp>
#include <vmap/memory/sequence.hpp>
#include <vmap/runtime/exports.hpp>
#include <vmap/runtime/memory.hpp>

#include <doctest/doctest.h>

#include <opencv2/core/affine.hpp>

#include <algorithm>
#include <cmath>
#include <fstream>
#include <sstream>
#include <string>
#include <vector>

namespace {

namespace fs = std::filesystem;
using vmap::test::sample_frames;

vmap::Camera sample_camera() {
  return vmap::read_camera(vmap::test::source_dir() / "examples/data/tum_fr1_camera.yaml");
}

vmap::PolicyStack with_camera(const vmap::Camera& c) {
  vmap::PolicyStack s;
  s.camera = c;
  return s;
}

/// A made-up camera-to-world pose per sample frame: a slow walk along x, turning about y.
cv::Affine3d walk_pose(std::size_t i) {
  return cv::Affine3d(cv::Vec3d(0.0, 0.004 * static_cast<double>(i), 0.0),
                      cv::Vec3d(0.01 * static_cast<double>(i), 0.0, 0.002 * static_cast<double>(i)));
}

double median_of(std::vector<double> v) {
  std::sort(v.begin(), v.end());
  return v.empty() ? 0.0 : v[v.size() / 2];
}

}  // namespace

TEST_CASE("metric pose: a memory without poses keeps today's answer; with poses but no camera it says so") {
  // With a camera and no poses: the key image and its relative pose, as before; no pose.
  auto plain = vmap::AnyMemory::in_ram(with_camera(sample_camera()));
  for (std::size_t i = 0; i < 60; ++i)
    if (i % 5 != 2) (void)plain.push(sample_frames()[i]);
  const vmap::MemoryLocalization a = plain.localize(sample_frames()[27].image);
  REQUIRE(a.ok());
  CHECK(a.relative_pose.has_value());
  CHECK_FALSE(a.pose);
  CHECK(a.pose_reason_code == vmap::PoseReason::no_key_pose);
  CHECK(a.pose_reason.find("--poses") != std::string::npos);
  // With poses and no camera: no pose, and the reason names the camera.
  auto uncalibrated = vmap::AnyMemory::in_ram(vmap::PolicyStack{});
  for (std::size_t i = 0; i < 60; ++i)
    if (i % 5 != 2) (void)uncalibrated.push(sample_frames()[i], walk_pose(i));
  const vmap::MemoryLocalization b = uncalibrated.localize(sample_frames()[27].image);
  REQUIRE(b.ok());
  CHECK_FALSE(b.pose);
  CHECK(b.pose_reason_code == vmap::PoseReason::no_camera);
  CHECK(b.pose_reason.find("--camera") != std::string::npos);
  // A query the memory does not accept: no pose, "the place was not accepted".
  const cv::Mat noise(480, 640, CV_8U, cv::Scalar(0));
  cv::Mat random = noise.clone();
  cv::randu(random, 0, 255);
  const vmap::MemoryLocalization c = uncalibrated.localize(random);
  CHECK_FALSE(c.ok());
  CHECK_FALSE(c.pose);
  CHECK(c.pose_reason_code == vmap::PoseReason::not_accepted);
}

TEST_CASE("metric pose: a sequence keeps, takes or drops the pose with the key image it answers") {
  vmap::MemoryLocalization a;
  vmap::MetricPose p;
  p.key = 4;
  p.inliers = 50;
  // Accepted alone and kept by the sequence: the pose stays.
  a.status = vmap::PlaceStatus::accepted;
  a.pose = p;
  a.pose_reason_code = vmap::PoseReason::posed;
  vmap::detail::settle_pose(a, false);
  REQUIRE(a.pose);
  CHECK(a.pose->inliers == 50);
  // Lowered by the sequence: no pose, and the pose is kept at the candidate.
  a.status = vmap::PlaceStatus::unknown_place;
  vmap::detail::settle_pose(a, false);
  CHECK_FALSE(a.pose);
  CHECK(a.pose_reason_code == vmap::PoseReason::not_accepted);
  REQUIRE(a.candidate_pose.pose);
  // Not accepted alone, accepted by the sequence at its own candidate: the candidate's pose.
  a.status = vmap::PlaceStatus::accepted;
  vmap::detail::settle_pose(a, false);
  REQUIRE(a.pose);
  CHECK(a.pose_reason_code == vmap::PoseReason::posed);
  CHECK_FALSE(a.candidate_pose.pose);
  // Placed at another key image: no pose (it was computed at its own).
  vmap::detail::settle_pose(a, true);
  CHECK_FALSE(a.pose);
  CHECK(a.pose_reason_code == vmap::PoseReason::moved);
}

TEST_CASE("memory export: loops.g2o is a pose graph (vertices, odometry edges of each session, measured loops)") {
  auto mem = vmap::AnyMemory::in_ram(with_camera(sample_camera()));
  for (std::size_t i = 0; i < 60; ++i) {
    if (i == 30) mem.start_session();
    (void)mem.push(sample_frames()[i], walk_pose(i));
  }
  const fs::path dir = vmap::test::scratch_dir("metric_pose_export");
  vmap::G2oExportCounts counts;
  const auto written = vmap::export_memory(mem, dir, true, {.odometry_translation_sigma = 0.02}, &counts);
  CHECK(std::find(written.begin(), written.end(), "loops.g2o") != written.end());
  CHECK(counts.vertices == mem.key_images());
  CHECK(counts.odometry_edges == mem.key_images() - 2);  // two sessions: one chain each
  CHECK(counts.loop_edges + counts.loops_unmeasured == mem.loops().size());
  std::ifstream in(dir / "loops.g2o");
  std::vector<std::vector<std::string>> vertices, edges;
  for (std::string line; std::getline(in, line);) {
    std::istringstream row(line);
    std::vector<std::string> t;
    for (std::string s; row >> s;) t.push_back(s);
    (t.at(0) == "VERTEX_SE3:QUAT" ? vertices : edges).push_back(t);
  }
  CHECK(vertices.size() == counts.vertices);
  CHECK(edges.size() == counts.odometry_edges + counts.loop_edges);
  // The first odometry edge: the poses' relative motion, with the odometry's information.
  REQUIRE(!edges.empty());
  const auto& e = edges.front();
  REQUIRE(e.size() == 31);
  CHECK(e[1] == "0");
  CHECK(e[2] == "1");
  const auto frame_of = [&](std::size_t k) { return mem.map().keys[k].frame_index; };
  const cv::Affine3d rel = walk_pose(frame_of(0)).inv() * walk_pose(frame_of(1));
  for (int k = 0; k < 3; ++k)
    CHECK(std::stod(e[3 + static_cast<std::size_t>(k)]) == doctest::Approx(rel.translation()[k]).epsilon(1e-9));
  const auto q = vmap::quaternion_from_rotation(rel.rotation());
  for (int k = 0; k < 4; ++k) CHECK(std::stod(e[6 + static_cast<std::size_t>(k)]) == doctest::Approx(q[static_cast<std::size_t>(k)]).epsilon(1e-9));
  CHECK(std::stod(e[10]) == doctest::Approx(1.0 / (0.02 * 0.02)));  // I11 = 1 / sigma_t^2
  const double sr = 0.5 * CV_PI / 180.0;
  CHECK(std::stod(e[25]) == doctest::Approx(4.0 / (sr * sr)));  // I44: the quaternion's vector part is half the angle
}

TEST_SUITE("data") {
  /// Frames `frames` of a sequence with their poses, every 5th (from the 3rd) held out of
  /// a memory built with the camera; the held-out frames' answers.
  struct HeldOut {
    std::size_t queries = 0, accepted = 0, posed = 0, gross = 0;
    std::vector<double> metres, degrees;
  };

  HeldOut held_out(const std::vector<vmap::Frame>& frames, const std::vector<cv::Affine3d>& truth,
                   const vmap::Camera& camera) {
    auto mem = vmap::AnyMemory::in_ram(with_camera(camera));
    std::vector<std::size_t> held;
    for (std::size_t i = 0; i < frames.size(); ++i) {
      if (i % 5 == 2)
        held.push_back(i);
      else
        (void)mem.push(frames[i], truth[i]);
    }
    HeldOut out;
    for (std::size_t i : held) {
      const vmap::MemoryLocalization a = mem.localize(frames[i].image);
      ++out.queries;
      if (!a.ok()) continue;
      ++out.accepted;
      if (!a.pose) continue;
      ++out.posed;
      const double m = cv::norm(a.pose->position() - truth[i].translation());
      const double d = vmap::rotation_angle_deg(a.pose->rotation().t() * truth[i].rotation());
      out.metres.push_back(m);
      out.degrees.push_back(d);
      if (m > 0.5 || d > 5.0) ++out.gross;
    }
    return out;
  }

  std::vector<cv::Affine3d> affine(const std::vector<vmap::CameraPose>& poses) {
    std::vector<cv::Affine3d> out;
    for (const auto& p : poses) out.emplace_back(p.rotation, p.position);
    return out;
  }

  TEST_CASE("metric pose on real frames: the sample of tum_fr1_rpy, every 5th frame held out") {
    std::vector<double> times;
    for (const auto& f : sample_frames()) times.push_back(f.timestamp);
    const auto truth = affine(vmap::poses_for_frames(vmap::load_tum_poses(vmap::test::data_path("tum_fr1_rpy/groundtruth.txt")),
                                                     times, "groundtruth.txt", 0.05));
    const HeldOut h = held_out(sample_frames(), truth, sample_camera());
    INFO("accepted " << h.accepted << ", posed " << h.posed << ", median " << median_of(h.metres) << " m, "
                     << median_of(h.degrees) << " deg");
    CHECK(h.queries == 12);
    CHECK(h.accepted == 12);
    CHECK(h.posed >= 10);
    CHECK(h.gross == 0);
    CHECK(median_of(h.metres) < 0.03);
    CHECK(median_of(h.degrees) < 1.0);
  }

  TEST_CASE("metric pose on real frames: kitti07_160's first 80 frames, every 5th held out") {
    std::vector<vmap::Frame> frames = vmap::test::read_grey_frames(vmap::test::data_path("kitti07_160/image_0"), {.end = 80});
    auto truth = affine(vmap::load_kitti_poses(vmap::test::data_path("kitti07_160/poses.txt")));
    truth.resize(frames.size());
    const HeldOut h = held_out(frames, truth, vmap::read_camera(vmap::test::data_path("kitti07_160/calib.txt")));
    INFO("accepted " << h.accepted << ", posed " << h.posed << ", median " << median_of(h.metres) << " m, "
                     << median_of(h.degrees) << " deg");
    CHECK(h.queries == 16);
    CHECK(h.accepted >= 15);
    CHECK(h.posed >= 12);
    CHECK(h.gross == 0);
    CHECK(median_of(h.metres) < 0.05);
    CHECK(median_of(h.degrees) < 1.0);
  }
}
