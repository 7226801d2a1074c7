// The selector, pipeline and sweep on real frames: the repository's sample TUM frames
// (examples/data, self-contained) and ../shared/data/tum_fr1_rpy (suite "data").
#include "support/shared_data.hpp"

#include <vmap/keyframe/map_io.hpp>
#include <vmap/keyframe/pipeline.hpp>
#include <vmap/keyframe/selector.hpp>
#include <vmap/keyframe/stacks.hpp>
#include <vmap/keyframe/sweep.hpp>

#include <doctest/doctest.h>

#include <opencv2/imgcodecs.hpp>
#include <opencv2/videoio.hpp>

#include <filesystem>
#include <fstream>
#include <functional>
#include <algorithm>
#include <string>
#include <thread>
#include <vector>

namespace {

using Keys = std::vector<std::size_t>;

using vmap::test::sample_list;

/// The benchmark stack: ORB 1000, mutual NN, MAGSAC 1 px 0.99, eq. 5.
vmap::OrbMagsacSelector orb_selector(const vmap::SelectorOptions& o) {
  return vmap::OrbMagsacSelector(vmap::OrbDescriptor{}, vmap::BruteForceMatcher{},
                                 vmap::FundamentalEstimator({.check_degeneracy = false}), vmap::InlierRatio{}, o);
}

vmap::VisualMap select(const std::filesystem::path& input, const vmap::SelectorOptions& o, vmap::RunOptions run = {},
                       std::size_t start = 0, std::size_t end = 60) {
  auto src = vmap::FrameSource::open(input, {.start = start, .end = end, .grey = true});
  auto sel = orb_selector(o);
  vmap::run_selector(src, sel, run);
  return sel.take_map();
}

}  // namespace

TEST_CASE("sample frames: key images are verified, skip and pipeline change nothing") {
  const auto plain = select(sample_list(), {.tau = 0.3, .skip_by_upper_bound = false}, {.pipelined = false});
  CHECK(plain.frames == 60);
  CHECK(plain.keys.size() >= 3);
  CHECK(plain.keys.size() <= 30);
  CHECK(plain.keys.front().frame_index == 0);
  for (const auto& p : plain.pairs) {
    CHECK(p.status == vmap::VerificationStatus::verified);
    CHECK(p.similarity > 0.0);
  }
  const auto fast = select(sample_list(), {.tau = 0.3, .skip_by_upper_bound = true}, {.pipelined = true});
  CHECK(fast.key_indices() == plain.key_indices());
  REQUIRE(fast.pairs.size() == plain.pairs.size());
  for (std::size_t k = 0; k < fast.pairs.size(); ++k) CHECK(fast.pairs[k].inliers == plain.pairs[k].inliers);

  // Algorithm 1's rule takes different frames but links them just as well.
  const auto current = select(sample_list(), {.tau = 0.3, .rule = vmap::KeyRule::current_frame});
  CHECK(current.keys.size() >= 3);
  CHECK(current.key_indices() != plain.key_indices());
}

TEST_CASE("sample frames: sweep rows equal separate single-threshold runs") {
  const std::vector<double> taus = {0.2, 0.45, 0.7};
  auto src = vmap::FrameSource::open(sample_list(), {.end = 40, .grey = true});
  const auto sweep = vmap::sweep_thresholds(src, vmap::OrbDescriptor{}, vmap::BruteForceMatcher{},
                                            vmap::FundamentalEstimator({.check_degeneracy = false}), vmap::InlierRatio{},
                                            {.taus = taus});
  REQUIRE(sweep.rows.size() == taus.size());
  CHECK(sweep.frames == 40);
  CHECK(sweep.pairs_scored <= sweep.pair_requests);
  double best_q = -1;
  for (std::size_t k = 0; k < taus.size(); ++k) {
    const auto single = select(sample_list(), {.tau = taus[k]}, {.pipelined = false}, 0, 40);
    const auto s = single.stats();
    CAPTURE(taus[k]);
    CHECK(sweep.rows[k].threshold == taus[k]);
    CHECK(sweep.rows[k].key_frames == single.key_indices());
    CHECK(sweep.rows[k].stats.key_images == s.key_images);
    CHECK(sweep.rows[k].stats.min_matches == s.min_matches);
    CHECK(sweep.rows[k].stats.max_matches == s.max_matches);
    CHECK(sweep.rows[k].stats.mean_matches == s.mean_matches);
    CHECK(sweep.rows[k].stats.quality == s.quality);
    best_q = std::max(best_q, s.quality);
  }
  CHECK(sweep.rows[sweep.best].stats.quality == best_q);
  CHECK(sweep.best_threshold() == sweep.rows[sweep.best].threshold);
  // One thread everywhere: the same rows.
  auto src1 = vmap::FrameSource::open(sample_list(), {.end = 40, .grey = true});
  const auto serial = vmap::sweep_thresholds(src1, vmap::OrbDescriptor{}, vmap::BruteForceMatcher{},
                                             vmap::FundamentalEstimator({.check_degeneracy = false}),
                                             vmap::InlierRatio{}, {.taus = taus, .pipelined = false, .parallel_pairs = false});
  for (std::size_t k = 0; k < taus.size(); ++k) {
    CHECK(serial.rows[k].key_frames == sweep.rows[k].key_frames);
    CHECK(serial.rows[k].stats.mean_matches == sweep.rows[k].stats.mean_matches);
  }
  // More key images at a stricter threshold.
  CHECK(sweep.rows[0].stats.key_images <= sweep.rows[2].stats.key_images);
}

TEST_CASE("sweep: invalid thresholds are Errors") {
  auto src = vmap::FrameSource::open(sample_list(), {.end = 2, .grey = true});
  CHECK_THROWS_WITH_AS((void)vmap::sweep_thresholds(src, vmap::OrbDescriptor{}, vmap::BruteForceMatcher{},
                                                    vmap::FundamentalEstimator{}, vmap::InlierRatio{}, {.taus = {}}),
                       doctest::Contains("taus"), vmap::Error);
  CHECK_THROWS_WITH_AS((void)vmap::sweep_thresholds(src, vmap::OrbDescriptor{}, vmap::BruteForceMatcher{},
                                                    vmap::FundamentalEstimator{}, vmap::InlierRatio{},
                                                    {.taus = {0.3, 1.2}}),
                       doctest::Contains("(0, 1]"), vmap::Error);
}

TEST_CASE("sample frames: any number of preparing threads gives the same map, frames in order") {
  const auto plain = select(sample_list(), {.tau = 0.3}, {.pipelined = false});
  for (const std::size_t threads : {1, 2, 3}) {
    CAPTURE(threads);
    auto src = vmap::FrameSource::open(sample_list(), {.grey = true});
    auto sel = orb_selector({.tau = 0.3});
    std::vector<std::size_t> order;
    vmap::run_selector(src, sel, {.pipelined = true, .prepare_threads = threads, .queue_capacity = 4},
                       [&](const vmap::FrameResult& r) { order.push_back(r.frame_index); });
    REQUIRE(order.size() == 60);
    for (std::size_t k = 0; k < order.size(); ++k) CHECK(order[k] == k);
    const auto m = sel.take_map();
    CHECK(m.key_indices() == plain.key_indices());
    REQUIRE(m.pairs.size() == plain.pairs.size());
    for (std::size_t k = 0; k < m.pairs.size(); ++k) CHECK(m.pairs[k].inliers == plain.pairs[k].inliers);
  }
  auto src = vmap::FrameSource::open(sample_list(), {.grey = true});
  auto sel = orb_selector({});
  CHECK_THROWS_WITH_AS(vmap::run_selector(src, sel, {.prepare_threads = 0}), doctest::Contains("prepare_threads"),
                       vmap::Error);
  CHECK_THROWS_WITH_AS(vmap::run_selector(src, sel, {.prepare_threads = 3, .queue_capacity = 2}),
                       doctest::Contains("queue_capacity"), vmap::Error);
}

TEST_CASE("pipeline: a failure while preparing frame k reaches the caller after frames 0..k-1") {
  for (const std::size_t threads : {1, 2, 3}) {
    CAPTURE(threads);
    auto src = vmap::FrameSource::open(sample_list(), {.end = 20, .grey = true});
    std::vector<std::function<std::size_t(const vmap::Frame&)>> prepares(threads, [](const vmap::Frame& f) {
      if (f.index == 7) throw vmap::Error("frame 7 refused");
      return f.index;
    });
    std::vector<std::size_t> consumed;
    CHECK_THROWS_WITH_AS(
        vmap::detail::run_pipelined_on<std::size_t>(src, 4, prepares, [&](std::size_t i) { consumed.push_back(i); }),
        "frame 7 refused", vmap::Error);
    CHECK(consumed == std::vector<std::size_t>{0, 1, 2, 3, 4, 5, 6});
  }
}

TEST_CASE("sample frames: corrupt and missing frames are skipped in order, the run goes on") {
  const auto dir = vmap::test::scratch_dir("keyframe_corrupt");
  const auto frames = vmap::FrameSource::open(sample_list()).paths();
  {
    std::ofstream bad(dir / "corrupt.jpg", std::ios::binary);
    bad << "this is not a JPEG";
  }
  // Sequence positions 3 and 11 corrupt, 12 missing: the preparing threads decode them in
  // parallel, the calling thread reports them in order.
  std::ofstream list(dir / "list.txt");
  for (std::size_t k = 0; k < 20; ++k) {
    if (k == 3 || k == 10) list << (dir / "corrupt.jpg").string() << "\n";
    if (k == 10) list << (dir / "missing.jpg").string() << "\n";
    list << frames[k].string() << "\n";
  }
  list.close();
  std::vector<std::string> expected;
  {
    auto plain = vmap::FrameSource::open(dir / "list.txt", {.grey = true});
    while (plain.next()) {
    }
    for (const auto& s : plain.skipped()) expected.push_back(std::to_string(s.index) + " " + s.name + ": " + s.reason);
    CHECK(plain.delivered() == 20);
  }
  REQUIRE(expected.size() == 3);
  CHECK(expected[0].starts_with("3 "));
  CHECK(expected[1].starts_with("11 "));
  CHECK(expected[2].starts_with("12 "));
  const auto single = select(dir / "list.txt", {.tau = 0.3}, {.pipelined = false}, 0, 100);
  for (const std::size_t threads : {1, 2, 3}) {
    CAPTURE(threads);
    std::vector<std::string> reported;
    bool on_calling_thread = true;
    const auto caller = std::this_thread::get_id();
    auto src = vmap::FrameSource::open(dir / "list.txt", {.grey = true, .on_skip = [&](const vmap::SkippedFrame& s) {
                                                            reported.push_back(std::to_string(s.index) + " " + s.name + ": " + s.reason);
                                                            on_calling_thread = on_calling_thread && std::this_thread::get_id() == caller;
                                                          }});
    auto sel = orb_selector({.tau = 0.3});
    std::vector<std::size_t> order;
    vmap::run_selector(src, sel, {.pipelined = true, .prepare_threads = threads},
                       [&](const vmap::FrameResult& r) { order.push_back(r.frame_index); });
    CHECK(reported == expected);
    CHECK(on_calling_thread);
    REQUIRE(src.skipped().size() == 3);
    CHECK(src.skipped()[1].index == 11);
    CHECK(src.delivered() == 20);
    CHECK(sel.map().frames == 20);
    CHECK(std::is_sorted(order.begin(), order.end()));
    CHECK(std::find(order.begin(), order.end(), 11) == order.end());
    CHECK(sel.map().key_indices() == single.key_indices());
  }
}

TEST_CASE("sample frames as a video: a pipelined run reads it in order and equals one thread") {
  const auto dir = vmap::test::scratch_dir("keyframe_video");
  const auto path = dir / "clip.avi";
  {
    auto src = vmap::FrameSource::open(sample_list(), {.end = 30});
    cv::VideoWriter w(path.string(), cv::VideoWriter::fourcc('M', 'J', 'P', 'G'), 30.0, cv::Size(640, 480), true);
    REQUIRE_MESSAGE(w.isOpened(), "OpenCV cannot write MJPG video here");
    while (auto f = src.next()) w.write(f->image);
  }
  const auto single = select(path, {.tau = 0.3}, {.pipelined = false}, 0, 100);
  CHECK(single.frames == 30);
  for (const std::size_t threads : {1, 2}) {
    CAPTURE(threads);
    auto src = vmap::FrameSource::open(path, {.grey = true});
    auto sel = orb_selector({.tau = 0.3});
    std::vector<std::size_t> order;
    vmap::run_selector(src, sel, {.pipelined = true, .prepare_threads = threads},
                       [&](const vmap::FrameResult& r) { order.push_back(r.frame_index); });
    REQUIRE(order.size() == 30);
    for (std::size_t k = 0; k < order.size(); ++k) CHECK(order[k] == k);
    CHECK(src.delivered() == 30);
    const auto m = sel.take_map();
    CHECK(m.key_indices() == single.key_indices());
    REQUIRE(m.pairs.size() == single.pairs.size());
    for (std::size_t k = 0; k < m.pairs.size(); ++k) CHECK(m.pairs[k].inliers == single.pairs[k].inliers);
  }
}

TEST_CASE("bad inputs: missing path, empty video, unreadable sequence") {
  CHECK_THROWS_WITH_AS(vmap::FrameSource::open("/nonexistent/video.mp4"), doctest::Contains("/nonexistent/video.mp4"),
                       vmap::Error);
  const auto dir = vmap::test::scratch_dir("keyframe_bad");
  { std::ofstream(dir / "empty.avi"); }
  CHECK_THROWS_AS(vmap::FrameSource::open(dir / "empty.avi"), vmap::Error);
  // Every frame unreadable: the error reaches the caller of the pipelined run.
  {
    std::ofstream bad(dir / "bad.jpg", std::ios::binary);
    bad << "garbage";
  }
  {
    std::ofstream list(dir / "list.txt");
    list << (dir / "bad.jpg").string() << "\n" << (dir / "bad.jpg").string() << "\n";
  }
  auto src = vmap::FrameSource::open(dir / "list.txt", {.grey = true});
  auto sel = orb_selector({});
  CHECK_THROWS_WITH_AS(vmap::run_selector(src, sel, {.pipelined = true}), doctest::Contains("could be read"),
                       vmap::Error);
}

TEST_CASE("sample frames: a map with images round-trips through a file") {
  const auto m = select(sample_list(), {.tau = 0.3, .keep_images = true}, {}, 0, 20);
  REQUIRE(m.keys.size() >= 2);
  CHECK_FALSE(m.keys[0].image.empty());
  const auto dir = vmap::test::scratch_dir("keyframe_map_real");
  vmap::save_map(m, dir / "map.vmap");
  const auto back = vmap::load_map(dir / "map.vmap");
  CHECK(back.key_indices() == m.key_indices());
  CHECK(back.quality() == m.quality());
  for (std::size_t k = 0; k < m.keys.size(); ++k) {
    CHECK(cv::norm(back.keys[k].image, m.keys[k].image, cv::NORM_INF) == 0);
    CHECK(cv::norm(back.keys[k].features.descriptors, m.keys[k].features.descriptors, cv::NORM_INF) == 0);
  }
}

TEST_SUITE("data") {
  TEST_CASE("tum_fr1_rpy: key images at tau 0.3, every consecutive pair verified") {
    const auto list = vmap::test::data_path("tum_fr1_rpy/rgb.txt");
    // Frames 100-299 (200 frames of hand-held roll/pitch/yaw).
    const auto m = select(list, {.tau = 0.3}, {}, 100, 300);
    CHECK(m.frames == 200);
    MESSAGE("key images: " << m.keys.size() << ", quality " << m.quality());
    // 49 key images with this stack (about a quarter of the frames: the camera rolls
    // and yaws fast here); the band allows for other OpenCV builds' ORB/MAGSAC.
    CHECK(m.keys.size() >= 35u);
    CHECK(m.keys.size() <= 65u);
    CHECK(m.keys.front().frame_index == 100);
    REQUIRE(m.pairs.size() + 1 == m.keys.size());
    for (const auto& p : m.pairs) {
      CHECK(p.status == vmap::VerificationStatus::verified);
      CHECK(p.inliers >= 8);
      CHECK(p.similarity > 0.0);
    }
    CHECK(m.quality() > 0.5);
  }
}
