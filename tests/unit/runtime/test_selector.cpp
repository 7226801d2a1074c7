// Key-image selection over a stack chosen at run time (runtime/selector.hpp): AnySelector
// selects what the typed KeyframeSelector of the same policies selects, pushed or run
// over a source; the sweep of a stack is the typed sweep; one image pair through a stack
// (runtime/pair.hpp) is the pair the selector scores.

#include "support/errors.hpp"
#include "support/shared_data.hpp"

#include <vmap/features/orb.hpp>
#include <vmap/geometry/calibrated.hpp>
#include <vmap/geometry/fundamental.hpp>
#include <vmap/geometry/similarity.hpp>
#include <vmap/io/frame_source.hpp>
#include <vmap/keyframe/map_io.hpp>
#include <vmap/keyframe/selector.hpp>
#include <vmap/keyframe/sweep.hpp>
#include <vmap/matching/brute_force.hpp>
#include <vmap/runtime/frame_range.hpp>
#include <vmap/runtime/pair.hpp>
#include <vmap/runtime/selector.hpp>
#include <vmap/runtime/stack_choice.hpp>

#include <doctest/doctest.h>

#include <string>
#include <vector>

namespace {

std::filesystem::path sample() { return vmap::test::source_dir() / "examples/data/tum_fr1_rpy_60/rgb.txt"; }

/// The typed selector of the stack `vmap build` runs by default: ORB 1000, mutual NN,
/// MAGSAC++ at 1 px without the homography test, eq. 5.
auto typed_selector(const vmap::SelectorOptions& o) {
  return vmap::KeyframeSelector(vmap::OrbDescriptor({.features = 1000}),
                                vmap::BruteForceMatcher({.mode = vmap::MatchMode::mutual}),
                                vmap::Calibrated<vmap::FundamentalEstimator>(
                                    std::nullopt, vmap::FundamentalEstimator({.check_degeneracy = false})),
                                vmap::InlierRatio{}, o);
}

}  // namespace

TEST_CASE("AnySelector selects what the typed selector of the same stack selects") {
  const vmap::SelectorOptions o{.tau = 0.4, .rule = vmap::KeyRule::current_frame};
  vmap::AnySelector any(vmap::PolicyStack{}, o);
  auto typed = typed_selector(o);
  auto frames = vmap::FrameSource::open(sample(), vmap::FrameRange{.end = 30}.apply({.grey = true}));
  while (auto f = frames.next()) {
    const vmap::FrameResult a = any.push(*f);
    const vmap::FrameResult t = typed.push(*f);
    CHECK(a.key_taken == t.key_taken);
    CHECK(a.similarity == t.similarity);
    CHECK(a.reason == t.reason);
  }
  CHECK(vmap::serialize_map(any.map()) == vmap::serialize_map(typed.map()));
  CHECK(any.options().rule == vmap::KeyRule::current_frame);
  REQUIRE(any.map().keys.size() >= 2);

  // A link of the map, matched and verified again as the selector scored it.
  const auto& k = any.map().keys;
  const vmap::VerifiedPair p = vmap::verify_pair(any, k[0].features, k[1].features);
  const vmap::VerifiedPair q = vmap::verify_pair(typed, k[0].features, k[1].features);
  CHECK(p.score.verification.inliers == any.map().pairs[0].inliers);
  CHECK(p.matches.size() == q.matches.size());
  CHECK(p.score.similarity == any.map().pairs[0].similarity);

  // Run over a source (pipelined), after a reset: the map of the typed run.
  any.reset();
  CHECK(any.map().frames == 0);
  auto again = vmap::FrameSource::open(sample(), vmap::FrameRange{.end = 30}.apply({.grey = true}));
  std::size_t called = 0;
  any.run(again, {.pipelined = true}, [&](const vmap::FrameResult&) { ++called; });
  CHECK(called == 30);
  CHECK(vmap::serialize_map(any.map()) == vmap::serialize_map(typed.map()));
  CHECK(vmap::test::error_of([] { vmap::AnySelector(vmap::PolicyStack{}, {.tau = 0.0}); }) ==
        "SelectorOptions.tau must be in (0, 1], got 0.000000");
}

TEST_CASE("AnySelector of every shipped classic stack; the sweep of a stack is the typed sweep") {
  for (const char* name : {"orb", "akaze", "sift"}) {
    const vmap::PolicyStack s = vmap::stack_of({.descriptor = name, .features = 400, .method = "ransac"});
    vmap::AnySelector selector(s, {.tau = 0.3});
    auto frames = vmap::FrameSource::open(sample(), {.end = 8, .grey = true});
    selector.run(frames, {.pipelined = false});
    CHECK(selector.map().frames == 8);
    CHECK(selector.stack() == s);
  }
  const vmap::SweepOptions so{.taus = {0.2, 0.5}, .pipelined = false};
  auto a = vmap::FrameSource::open(sample(), {.end = 20, .grey = true});
  auto b = vmap::FrameSource::open(sample(), {.end = 20, .grey = true});
  const vmap::SweepResult by_stack = vmap::sweep_thresholds(a, vmap::PolicyStack{}, so);
  const vmap::SweepResult typed =
      vmap::sweep_thresholds(b, vmap::OrbDescriptor({.features = 1000}), vmap::BruteForceMatcher({.mode = vmap::MatchMode::mutual}),
                             vmap::Calibrated<vmap::FundamentalEstimator>(
                                 std::nullopt, vmap::FundamentalEstimator({.check_degeneracy = false})),
                             vmap::InlierRatio{}, so);
  REQUIRE(by_stack.rows.size() == 2);
  for (std::size_t r = 0; r < 2; ++r) {
    CHECK(by_stack.rows[r].key_frames == typed.rows[r].key_frames);
    CHECK(by_stack.rows[r].stats.quality == typed.rows[r].stats.quality);
  }
  CHECK(by_stack.best == typed.best);
}

TEST_CASE("one image pair through a stack: features, matches, the F-matrix with its degeneracy test, eq. 5") {
  auto frames = vmap::FrameSource::open(sample(), {.end = 10, .grey = true});
  std::vector<cv::Mat> images;
  while (auto f = frames.next()) images.push_back(f->image);
  const vmap::PolicyStack s;
  const vmap::PairCheck c = vmap::check_pair(s, images[0], images[9], {.epipolar_px = 1.5});
  vmap::OrbDescriptor orb({.features = 1000});
  const vmap::Features a = orb.extract(images[0]);
  const vmap::Features b = orb.extract(images[9]);
  const vmap::Matches m = vmap::BruteForceMatcher({.mode = vmap::MatchMode::mutual}).match(a, b);
  const vmap::Verification v =
      vmap::FundamentalEstimator({.threshold_px = 1.5, .check_degeneracy = true}).verify(a, b, m);
  CHECK(c.a.size() == a.size());
  CHECK(c.matches.size() == m.size());
  CHECK(c.verification.inliers == v.inliers);
  CHECK(c.verification.degeneracy == v.degeneracy);
  CHECK(c.verification.homography_inliers == v.homography_inliers);
  CHECK(c.similarity == vmap::InlierRatio{}(a, b, v));
  CHECK(c.seconds() == c.extract_seconds + c.match_seconds + c.verify_seconds);
}
