#include <vmap/lcd/evaluation.hpp>

#include "support/shared_data.hpp"

#include <doctest/doctest.h>

#include <algorithm>
#include <cmath>
#include <functional>
#include <random>
#include <limits>
#include <vector>

using vmap::LoopGroundTruth;
using vmap::LoopScore;

namespace {

// Six frames; frames 3, 4 and 5 close loops (3 with 0, 4 with 1, 5 with 1 or 2).
LoopGroundTruth hand_truth() {
  return LoopGroundTruth::parse(
      "0 0 0 0 0 0\n"
      "0 0 0 0 0 0\n"
      "0 0 0 0 0 0\n"
      "1 0 0 0 0 0\n"
      "0 1 0 0 0 0\n"
      "0 1 1 0 0 0\n");
}

}  // namespace

TEST_CASE("evaluation: precision, recall and the PR curve on a hand-made score list") {
  const auto gt = hand_truth();
  CHECK(gt.frames() == 6);
  CHECK(gt.loop_frames() == 3);
  CHECK(gt(5, 2));
  CHECK_FALSE(gt(2, 5));
  const std::vector<LoopScore> scores = {
      {0, std::nullopt, 0},  // nothing verified
      {1, 0, 12},            // false, weak
      {2, 0, 30},            // false, strong
      {3, 0, 80},            // true
      {4, 1, 50},            // true
      {5, 0, 20},            // false (5 loops with 1 and 2, not 0)
  };
  const auto at50 = vmap::evaluate_loops(scores, gt, 50);
  CHECK(at50.true_positives == 2);
  CHECK(at50.false_positives == 0);
  CHECK(at50.false_negatives == 1);
  CHECK(at50.precision == 1.0);
  CHECK(at50.recall == doctest::Approx(2.0 / 3.0));

  const auto curve = vmap::precision_recall_curve(scores, gt);
  REQUIRE(curve.size() == 5);  // thresholds 80, 50, 30, 20, 12
  CHECK(curve[0].threshold == 80);
  CHECK(curve[0].recall == doctest::Approx(1.0 / 3.0));
  CHECK(curve[2].threshold == 30);
  CHECK(curve[2].true_positives == 2);
  CHECK(curve[2].false_positives == 1);
  CHECK(curve[2].precision == doctest::Approx(2.0 / 3.0));
  CHECK(curve[4].threshold == 12);
  CHECK(curve[4].precision == doctest::Approx(2.0 / 5.0));
  const auto r100 = vmap::recall_at_full_precision(curve);
  CHECK(r100.recall == doctest::Approx(2.0 / 3.0));
  CHECK(r100.threshold == 50);
  CHECK(r100.true_positives == 2);

  const auto none = vmap::evaluate_loops(scores, gt, 1000);
  CHECK(none.precision == 1.0);  // no claim, no error
  CHECK(none.recall == 0.0);
  CHECK(vmap::recall_at_full_precision({}).recall == 0.0);
}

TEST_CASE("evaluation: bad ground truth and scores are an Error") {
  CHECK_THROWS_WITH_AS((void)LoopGroundTruth::parse("0 0\n0 0\n0 0\n"), doctest::Contains("not square"),
                       vmap::Error);
  CHECK_THROWS_AS((void)LoopGroundTruth::parse("0 0\n0\n"), vmap::Error);
  CHECK_THROWS_AS((void)LoopGroundTruth::parse("0 2\n0 0\n"), vmap::Error);
  CHECK_THROWS_AS((void)LoopGroundTruth::parse("0 01\n0 0 0\n0 0 0\n"), vmap::Error);
  CHECK_THROWS_WITH_AS((void)LoopGroundTruth::parse("0 0\n0 0\n", "gt.txt", 3), doctest::Contains("sequence has 3"),
                       vmap::Error);
  CHECK_THROWS_AS((void)LoopGroundTruth::load("/nonexistent/gt.txt"), vmap::Error);
  const auto gt = hand_truth();
  CHECK_THROWS_AS((void)vmap::evaluate_loops({{6, 0, 1}}, gt, 0), vmap::Error);  // query beyond the matrix
  CHECK_THROWS_AS((void)vmap::evaluate_loops({{3, 9, 1}}, gt, 0), vmap::Error);
  CHECK_THROWS_AS((void)vmap::evaluate_loops({{3, 0, std::numeric_limits<double>::quiet_NaN()}}, gt, 0),
                  vmap::Error);
  CHECK_THROWS_AS((void)gt(0, 6), vmap::Error);
  CHECK(LoopGroundTruth::parse(gt.to_text()).to_text() == gt.to_text());
}

TEST_CASE("evaluation: ground truth from poses (distance and viewing angle)") {
  // A camera on a circle of radius 2 m looking at its centre, 24 poses a lap, 1.5 laps.
  std::vector<vmap::CameraPose> poses;
  for (int k = 0; k < 36; ++k) {
    const double a = 2 * CV_PI * k / 24.0;
    vmap::CameraPose p;
    p.position = {2 * std::cos(a), 2 * std::sin(a), 0};
    // Optical axis (0,0,1) rotated to (-cos a, -sin a, 0): rotation about y by -90 deg
    // then about z by a; written directly as a quaternion: qz(a) * qy(-90 deg).
    const double cz = std::cos(a / 2), sz = std::sin(a / 2), cy = std::cos(-CV_PI / 4), sy = std::sin(-CV_PI / 4);
    p.rotation = vmap::rotation_from_quaternion(-sz * sy, cz * sy, sz * cy, cz * cy);
    poses.push_back(p);
  }
  const cv::Vec3d d0 = poses[0].viewing_direction();
  CHECK(d0[0] == doctest::Approx(-1.0));
  CHECK(d0[1] == doctest::Approx(0.0).epsilon(1e-9));
  // Neighbours on the circle are 0.52 m and 15 deg apart.
  const auto gt = vmap::ground_truth_from_poses(poses, {.max_distance = 0.6, .max_angle_deg = 20, .window = 10});
  CHECK(gt(24, 0));
  CHECK(gt(25, 0));
  CHECK_FALSE(gt(24, 13));  // the opposite side of the circle
  CHECK_FALSE(gt(20, 0));
  CHECK_FALSE(gt(5, 0));  // inside the window
  CHECK(gt(30, 5));
  CHECK(gt(30, 6));
  CHECK(gt(30, 7));
  CHECK_FALSE(gt(30, 8));
  // Frames 24..35, and 23, whose neighbour 0 on the circle is outside its window.
  CHECK(gt.loop_frames() == 13);
  CHECK(gt(23, 0));
  CHECK_THROWS_AS((void)vmap::parse_tum_poses("1 2 3\n", "p.txt"), vmap::Error);
  CHECK_THROWS_AS((void)vmap::parse_tum_poses("1 2 3 4 0 0 0 0\n", "p.txt"), vmap::Error);
  CHECK(vmap::parse_tum_poses("# c\n1 2 3 4 0 0 0 1\n").size() == 1);
}

TEST_SUITE("data") {
  TEST_CASE("evaluation: the rtabmap_loop ground truth") {
    const auto gt = LoopGroundTruth::load(vmap::test::data_path("rtabmap_loop/gt_loop_matrix_84x84.txt"), 84);
    CHECK(gt.frames() == 84);
    CHECK(gt.loop_frames() == 44);  // frames 40..83 revisit 0..43
    CHECK(gt(40, 0));
    CHECK_FALSE(gt(39, 0));
    CHECK_THROWS_AS((void)LoopGroundTruth::load(vmap::test::data_path("rtabmap_loop/gt_loop_matrix_84x84.txt"), 83),
                    vmap::Error);
  }

  TEST_CASE("evaluation: tum_fr3_cabinet_kf poses give loops where the camera returns") {
    const auto poses = vmap::load_tum_poses(vmap::test::data_path("tum_fr3_cabinet_kf/truth_cam_poses.txt"));
    REQUIRE(poses.size() == 58);
    const auto gt = vmap::ground_truth_from_poses(poses, {.max_distance = 0.5, .max_angle_deg = 30, .window = 10});
    CHECK(gt.loop_frames() > 0);
    // The camera comes back within ~0.3 m of its start: the last frame closes with an early one.
    bool last_closes = false;
    for (std::size_t j = 0; j < 10; ++j) last_closes = last_closes || gt(57, j);
    CHECK(last_closes);
  }
}

namespace {

// The curve as written before it was made one sort: evaluate_loops at
// every distinct proposed score, highest first.
std::vector<vmap::PrecisionRecall> reference_curve(const std::vector<LoopScore>& scores, const LoopGroundTruth& gt) {
  std::vector<double> thresholds;
  for (const LoopScore& s : scores)
    if (s.match) thresholds.push_back(s.score);
  std::sort(thresholds.begin(), thresholds.end(), std::greater<>());
  thresholds.erase(std::unique(thresholds.begin(), thresholds.end()), thresholds.end());
  std::vector<vmap::PrecisionRecall> curve;
  for (double t : thresholds) curve.push_back(vmap::evaluate_loops(scores, gt, t));
  return curve;
}

}  // namespace

TEST_CASE("evaluation: the one-sort PR curve equals evaluate_loops at every threshold (random scores with ties)") {
  std::mt19937_64 rng(20261123);
  for (int trial = 0; trial < 20; ++trial) {
    const std::size_t frames = 40 + static_cast<std::size_t>(trial) * 7;
    LoopGroundTruth gt(frames);
    std::bernoulli_distribution loop(0.15);
    for (std::size_t q = 1; q < frames; ++q)
      for (std::size_t f = 0; f < q; ++f)
        if (loop(rng)) gt.set(q, f, true);
    std::vector<LoopScore> scores;
    // Scores on a coarse grid (many ties), some negative zero, some queries without a proposal.
    std::uniform_int_distribution<int> level(-2, 12);
    std::bernoulli_distribution proposes(0.8);
    for (std::size_t q = 0; q < frames; ++q) {
      LoopScore s;
      s.query = q;
      s.score = level(rng) * 0.25;
      if (s.score == 0.0 && (q % 2) == 1) s.score = -0.0;
      if (q > 0 && proposes(rng)) s.match = std::uniform_int_distribution<std::size_t>(0, q - 1)(rng);
      scores.push_back(s);
    }
    const auto fast = vmap::precision_recall_curve(scores, gt);
    const auto slow = reference_curve(scores, gt);
    REQUIRE(fast.size() == slow.size());
    CHECK(fast.size() > 5);
    for (std::size_t i = 0; i < fast.size(); ++i) {
      CHECK(std::signbit(fast[i].threshold) == std::signbit(slow[i].threshold));
      CHECK(fast[i].threshold == slow[i].threshold);
      CHECK(fast[i].true_positives == slow[i].true_positives);
      CHECK(fast[i].false_positives == slow[i].false_positives);
      CHECK(fast[i].false_negatives == slow[i].false_negatives);
      CHECK(fast[i].positives == slow[i].positives);
      CHECK(fast[i].precision == slow[i].precision);  // exact: the same counts and formula
      CHECK(fast[i].recall == slow[i].recall);
    }
  }
}
