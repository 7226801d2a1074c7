#include <vmap/features/akaze.hpp>
#include <vmap/io/frame_source.hpp>
#include <vmap/som/localizer.hpp>
#include <vmap/som/pose_io.hpp>
#include <vmap/som/virtual_room.hpp>

#include "support/shared_data.hpp"

#include <doctest/doctest.h>

#include <algorithm>
#include <cmath>
#include <numbers>
#include <vector>

using vmap::Pose2;

// Every member of the shipped stacks compiles (STYLE.md, Sophus pattern).
template class vmap::GcsLocalizer<vmap::AkazeDescriptor, vmap::BowHistogram>;
template class vmap::GcsLocalizer<vmap::AkazeDescriptor, vmap::GridHistogram>;
template class vmap::PoseMap<vmap::GcsXf>;

namespace {

std::filesystem::path poster_dir() { return vmap::test::source_dir() / "examples/data/tum_fr1_rpy_60/rgb"; }

double median(std::vector<double> v) {
  std::sort(v.begin(), v.end());
  return v.size() % 2 ? v[v.size() / 2] : 0.5 * (v[v.size() / 2 - 1] + v[v.size() / 2]);
}

// A smaller room image than the example's (160 x 120) keeps the test fast under
// AddressSanitizer; the method is the same.
vmap::VirtualRoomOptions test_room() {
  vmap::VirtualRoomOptions o;
  o.image_size = {160, 120};
  o.texture_px_per_m = 150.0;
  return o;
}

}  // namespace

TEST_CASE("virtual room: rendering and bad input") {
  const auto o = test_room();
  const auto posters = vmap::load_posters(poster_dir(), 16);
  const vmap::VirtualRoom room(posters, o);
  const cv::Mat a = room.render(Pose2(1.5, 1.5, -std::numbers::pi / 2));
  REQUIRE(a.size() == cv::Size(160, 120));
  CHECK(a.type() == CV_8UC3);
  CHECK(cv::norm(a, room.render(Pose2(1.5, 1.5, -std::numbers::pi / 2)), cv::NORM_INF) == 0.0);  // deterministic
  CHECK(cv::norm(a, room.render(Pose2(3.0, 1.5, -std::numbers::pi / 2)), cv::NORM_L1) > 0.0);   // position matters
  // looking straight at the south wall from 1.5 m: the floor band is at the bottom,
  // the wall paint fills the middle rows
  CHECK(room.distance_to_wall(Pose2(1.5, 1.5, 0), -std::numbers::pi / 2) == doctest::Approx(1.5));
  CHECK(room.distance_to_wall(Pose2(1.5, 1.5, 0), 0.0) == doctest::Approx(4.5));
  CHECK_THROWS_AS((void)room.render(Pose2(7, 1, 0)), vmap::Error);
  CHECK_THROWS_AS(vmap::VirtualRoom(std::vector<cv::Mat>(posters.begin(), posters.begin() + 5), o), vmap::Error);
  auto bad = o;
  bad.camera_height_m = 3.0;
  CHECK_THROWS_AS(vmap::VirtualRoom(posters, bad), vmap::Error);
  CHECK_THROWS_AS(vmap::load_posters(poster_dir(), 1000), vmap::Error);
}

TEST_CASE("square circuit: exact without noise, odometry drifts with it") {
  const vmap::VirtualRoomOptions room;
  vmap::CircuitOptions c{.margin_m = 1.0, .laps = 2, .images_per_lap = 40, .path_noise_m = 0, .heading_noise_deg = 0,
                         .odometry_noise_m = 0, .odometry_noise_deg = 0};
  const auto clean = vmap::square_circuit(room, c);
  REQUIRE(clean.size() == 80);
  CHECK(clean[0].truth.x() == doctest::Approx(1.0));
  CHECK(clean[0].truth.y() == doctest::Approx(1.0));
  CHECK(clean[10].truth.x() == doctest::Approx(5.0));  // 10 steps of 0.4 m: the first corner
  CHECK(clean[10].truth.theta() == doctest::Approx(std::numbers::pi / 2));
  CHECK(clean[40].truth.distance(clean[0].truth) == doctest::Approx(0.0).scale(1.0));  // second lap
  for (const auto& s : clean) CHECK(s.odometry.distance(s.truth) < 1e-9);
  c.odometry_noise_m = 0.01;
  c.odometry_noise_deg = 0.5;
  const auto noisy = vmap::square_circuit(room, c);
  CHECK(noisy[0].odometry.distance(noisy[0].truth) == 0.0);
  CHECK(noisy.back().odometry.distance(noisy.back().truth) > 0.0);
  const auto again = vmap::square_circuit(room, c);
  CHECK(again.back().odometry.x() == noisy.back().odometry.x());  // seeded
  CHECK_THROWS_AS(vmap::square_circuit(room, {.margin_m = 3.5}), vmap::Error);
}

TEST_CASE("virtual room: nearest-wall choice and localization error below a bound") {
  const auto o = test_room();
  const vmap::VirtualRoom room(vmap::load_posters(poster_dir(), 16), o);
  vmap::AkazeDescriptor akaze;
  // 2 laps x 60 images, 1.5 m from the walls: the outer wall is the nearer one (right).
  const vmap::CircuitOptions co{.margin_m = 1.5, .laps = 2, .images_per_lap = 60, .seed = 3};
  const auto rec = vmap::record_circuit(room, akaze, vmap::square_circuit(o, co));
  const auto right = std::count_if(rec.choices.begin(), rec.choices.end(),
                                   [](const vmap::NearestWall& w) { return w.side == vmap::WallSide::right; });
  MESSAGE("nearest wall = outer wall in " << right << " of " << rec.choices.size());
  CHECK(right >= static_cast<long>(rec.choices.size() * 7 / 10));

  vmap::BowHistogramOptions histogram;  // seed 1 and depth 1: the defaults
  histogram.vocabulary.branching = 64;
  vmap::AkazeBowLocalizer loc(vmap::AkazeDescriptor{}, vmap::BowHistogram(histogram),
                              {.lambda = 40, .max_cells = 100, .seed = 1});
  const auto report = loc.train(rec.images, rec.odometry);
  CHECK(report.gcs.cells == 100);
  CHECK(loc.map().neurons_with_pose() > 20);
  vmap::CircuitOptions qo = co;
  qo.laps = 1;
  qo.phase = 0.5;
  qo.seed = 99;
  const auto q = vmap::square_circuit(o, qo);
  std::vector<double> e1, e2;
  for (std::size_t k = 0; k < q.size(); k += 5) {
    const auto a = vmap::capture_view(room, akaze, q[k].truth);
    const auto b = vmap::capture_view(room, akaze, q[k].truth, 6.0 * std::numbers::pi / 180.0);
    e1.push_back(loc.localize({a.image}).pose.distance(q[k].truth));
    e2.push_back(loc.localize({a.image, b.image}).pose.distance(q[k].truth));
  }
  MESSAGE("room median error: one image " << median(e1) << " m, two images " << median(e2) << " m");
  // Training positions are 0.2 m apart and the training poses are odometry: a median
  // below 0.3 m means most queries find a neighbouring place.
  CHECK(median(e1) < 0.3);
  CHECK(median(e2) < 0.3);

  CHECK_THROWS_AS(loc.train({}, {}), vmap::Error);
  CHECK_THROWS_AS(loc.train(rec.images, std::vector<Pose2>(3)), vmap::Error);
  vmap::AkazeGridLocalizer untrained(vmap::AkazeDescriptor{}, vmap::GridHistogram{});
  CHECK_THROWS_AS((void)untrained.localize({rec.images[0]}), vmap::Error);
}

TEST_CASE("TUM fr3 cabinet: train on even frames, localize odd ones" * doctest::test_suite("data")) {
  const auto dir = vmap::test::data_path("tum_fr3_cabinet_kf");
  // Half resolution keeps the test fast; the example runs at full size.
  auto src = vmap::FrameSource::open(dir / "rgb", {.resize = {320, 240}});
  std::vector<cv::Mat> images;
  while (auto f = src.next()) images.push_back(f->image);
  const auto poses = vmap::read_tum_poses(dir / "truth_cam_poses.txt");
  REQUIRE(poses.size() == images.size());
  std::vector<cv::Mat> train, query;
  std::vector<Pose2> train_poses, query_truth;
  for (std::size_t i = 0; i < images.size(); ++i) {
    (i % 2 ? query : train).push_back(images[i]);
    (i % 2 ? query_truth : train_poses).push_back(poses[i].pose);
  }
  vmap::BowHistogramOptions histogram;  // seed 1 and depth 1: the defaults
  histogram.vocabulary.branching = 128;
  vmap::AkazeBowLocalizer loc(vmap::AkazeDescriptor{}, vmap::BowHistogram(histogram),
                              {.lambda = 20, .max_cells = 40, .seed = 1});
  loc.train(train, train_poses);
  std::vector<double> e1, e2;
  for (std::size_t k = 0; k < query.size(); ++k) {
    e1.push_back(loc.localize({query[k]}).pose.distance(query_truth[k]));
    if (k + 1 < query.size())
      e2.push_back(loc.localize({query[k], query[k + 1]})
                       .pose.distance(vmap::mean_pose({query_truth[k], query_truth[k + 1]})));
  }
  MESSAGE("cabinet median error: one image " << median(e1) << " m, two images " << median(e2) << " m");
  CHECK(median(e1) < 0.3);  // the target: a median error under 0.3 m
  // Two queries here are consecutive odd key frames, up to ~0.3 m apart: a wrong winner
  // for either moves their mean, and at this half resolution the pair is worse than
  // one image (0.37 m measured; see examples/results/localize.md for full resolution).
  CHECK(median(e2) < 0.5);
}
