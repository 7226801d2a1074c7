// Ground truth by timestamp: poses associated to frames by the nearest time within a
// tolerance (TUM's 100 Hz ground truth against 30 Hz images).
#include <vmap/io/frame_source.hpp>
#include <vmap/io/poses.hpp>

#include "support/errors.hpp"
#include "support/shared_data.hpp"

#include <doctest/doctest.h>

#include <algorithm>
#include <cmath>
#include <optional>
#include <vector>

namespace {

std::vector<vmap::CameraPose> poses_at(const std::vector<double>& times) {
  std::vector<vmap::CameraPose> out;
  for (std::size_t k = 0; k < times.size(); ++k) {
    vmap::CameraPose p;
    p.timestamp = times[k];
    p.position = cv::Vec3d(static_cast<double>(k), 0, 0);
    out.push_back(p);
  }
  return out;
}

using Match = std::vector<std::optional<std::size_t>>;

}  // namespace

TEST_CASE("100 Hz poses against 30 Hz frames: the nearest pose of each frame") {
  std::vector<double> pose_times;
  for (int k = 0; k <= 100; ++k) pose_times.push_back(10.0 + 0.01 * k);  // 10.00 .. 11.00
  const auto poses = poses_at(pose_times);
  // Frames at 30 Hz, offset by 3 ms from the pose grid: nearest is round((t - 10) / 0.01).
  std::vector<double> frames;
  for (int k = 0; k < 30; ++k) frames.push_back(10.003 + k / 30.0);
  const auto m = vmap::associate_by_timestamp(poses, frames, 0.02);
  REQUIRE(m.size() == frames.size());
  for (std::size_t k = 0; k < frames.size(); ++k) {
    CAPTURE(k);
    REQUIRE(m[k].has_value());
    CHECK(*m[k] == static_cast<std::size_t>(std::lround((frames[k] - 10.0) / 0.01)));
  }
}

TEST_CASE("tolerance edges, ties, gaps and unsorted poses") {
  const auto poses = poses_at({1.0, 2.0, 2.5, 4.0});
  // Exactly at the tolerance is in; just beyond is out; before the first and after the
  // last pose only within the tolerance.
  CHECK(vmap::associate_by_timestamp(poses, {1.1, 1.1 + 1e-4, 0.9, 0.89, 4.1, 4.2}, 0.1) ==
        Match{0, std::nullopt, 0, std::nullopt, 3, std::nullopt});
  // Midway between two poses: the earlier one.
  CHECK(vmap::associate_by_timestamp(poses, {2.25}, 0.5) == Match{1});
  // A gap in the ground truth: frames in it have none.
  CHECK(vmap::associate_by_timestamp(poses, {3.0, 3.2, 3.9}, 0.2) == Match{std::nullopt, std::nullopt, 3});
  // Tolerance 0: exact times only.
  CHECK(vmap::associate_by_timestamp(poses, {2.0, 2.001}, 0.0) == Match{1, std::nullopt});
  // Order of the pose file does not matter; indices refer to the given order.
  const auto shuffled = poses_at({4.0, 1.0, 2.5, 2.0});
  CHECK(vmap::associate_by_timestamp(shuffled, {1.01, 2.02, 2.4, 3.99}, 0.2) == Match{1, 3, 2, 0});
  // Duplicate times resolve to the first in the file.
  CHECK(vmap::associate_by_timestamp(poses_at({1.0, 1.0, 2.0}), {1.0, 0.99}, 0.1) == Match{0, 0});
  // No poses: no frame has one.
  CHECK(vmap::associate_by_timestamp(std::vector<vmap::CameraPose>{}, {1.0}, 1.0) == Match{std::nullopt});
  // Printed Unix times: 1305031229.548748 - 1305031229.528748 is 0.0200002 in doubles.
  CHECK(vmap::associate_by_timestamp(poses_at({1305031229.548748}), {1305031229.528748}, 0.02) == Match{0});
}

TEST_CASE("poses_for_frames: by order when counts match, else by time, every frame needs one") {
  const auto poses = poses_at({1.0, 2.0, 3.0});
  const auto same = vmap::poses_for_frames(poses, {7.0, 8.0, 9.0}, "gt.txt");
  CHECK(same[2].position[0] == 2.0);
  const auto timed = vmap::poses_for_frames(poses, {2.01, 2.99}, "gt.txt");
  REQUIRE(timed.size() == 2);
  CHECK(timed[0].position[0] == 1.0);
  CHECK(timed[1].position[0] == 2.0);
  CHECK(vmap::test::error_of([&] { (void)vmap::poses_for_frames(poses, {2.01, 5.0}, "gt.txt"); }) ==
        "gt.txt: no pose within 0.020000 s of frame 1 (time 5.000000 s); the 3 poses cover 1.000000 .. 3.000000 s, "
        "the 2 frames 2.010000 .. 5.000000 s (are both on one clock?)");
  CHECK(vmap::test::error_of([&] { (void)vmap::associate_by_timestamp(poses, {1.0}, -1.0); })
            .find("the tolerance must be a finite number >= 0") != std::string::npos);
  CHECK(vmap::test::error_of([&] { (void)vmap::associate_by_timestamp(poses, {1.0, std::nan("")}, 0.1); }) ==
        "associate_by_timestamp: frame 1 has no finite time");
}

TEST_SUITE("data") {
  TEST_CASE("tum_fr1_rpy: rgb.txt frames get their nearest 100 Hz ground-truth pose; a gap leaves three without") {
    const auto gt = vmap::load_tum_poses(vmap::test::data_path("tum_fr1_rpy/groundtruth.txt"));
    auto src = vmap::FrameSource::open(vmap::test::data_path("tum_fr1_rpy/rgb.txt"));
    const std::vector<double> frames = src.timestamps();
    REQUIRE(frames.size() == 723);
    REQUIRE(gt.size() == 2742);
    const auto m = vmap::associate_by_timestamp(gt, frames, 0.02);
    std::vector<std::size_t> without;
    double worst = 0;
    for (std::size_t k = 0; k < m.size(); ++k)
      if (!m[k]) {
        without.push_back(k);
      } else {
        worst = std::max(worst, std::abs(gt[*m[k]].timestamp - frames[k]));
        // Nearest: neither neighbour of the chosen pose is closer.
        const std::size_t j = *m[k];
        if (j > 0) CHECK(std::abs(gt[j - 1].timestamp - frames[k]) >= std::abs(gt[j].timestamp - frames[k]));
        if (j + 1 < gt.size()) CHECK(std::abs(gt[j + 1].timestamp - frames[k]) >= std::abs(gt[j].timestamp - frames[k]));
      }
    // The ground truth has a gap near t = 1305031244.9: frames 460, 461 and 464 are 49, 45
    // and 25 ms from the nearest pose (measured with a separate script); all others are
    // within 16.8 ms.
    CHECK(without == std::vector<std::size_t>{460, 461, 464});
    CHECK(worst < 0.017);
    const auto m50 = vmap::associate_by_timestamp(gt, frames, 0.05);
    CHECK(std::count(m50.begin(), m50.end(), std::nullopt) == 0);
    // The first frame (1305031229.528748) pairs with the pose printed as 1305031229.5332 (4.5 ms; .5232 is 5.5 ms away).
    CHECK(gt[*m[0]].timestamp == doctest::Approx(1305031229.5332).epsilon(1e-12));
  }
}
