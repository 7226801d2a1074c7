// The selector's per-frame path with reused buffers and a deferred degeneracy check:
// every reusing form gives exactly what the allocating one gives, on the repository's
// sample TUM frames.
#include "support/shared_data.hpp"

#include <vmap/io/frame_source.hpp>
#include <vmap/keyframe/map_io.hpp>
#include <vmap/keyframe/selector.hpp>
#include <vmap/keyframe/stacks.hpp>

#include <doctest/doctest.h>

#include <cstddef>
#include <filesystem>
#include <optional>
#include <string>
#include <vector>

namespace {

using vmap::test::sample_list;

std::vector<vmap::Frame> sample_frames(std::size_t end) {
  auto src = vmap::FrameSource::open(sample_list(), {.end = end, .grey = true});
  std::vector<vmap::Frame> frames;
  while (auto f = src.next()) frames.push_back(std::move(*f));
  return frames;
}

std::vector<vmap::Features> sample_features(std::size_t end) {
  vmap::OrbDescriptor orb;
  std::vector<vmap::Features> out;
  for (const auto& f : sample_frames(end)) out.push_back(orb.extract(f.image));
  return out;
}

void check_same(const vmap::Verification& a, const vmap::Verification& b) {
  CHECK(a.status == b.status);
  CHECK(a.model == b.model);
  CHECK(a.inlier_mask == b.inlier_mask);
  CHECK(a.inliers == b.inliers);
  CHECK(a.matches == b.matches);
  CHECK(a.degeneracy == b.degeneracy);
  CHECK(a.homography_inliers == b.homography_inliers);
}

// The same policies without their buffer-reusing forms: the front end falls back to
// match() and verify(), i.e. the allocating path with the eager degeneracy check.
struct PlainMatcher {
  vmap::BruteForceMatcher m = vmap::BruteForceMatcher();
  [[nodiscard]] vmap::Matches match(const vmap::Features& a, const vmap::Features& b) const { return m.match(a, b); }
};
struct PlainEstimator {
  vmap::FundamentalEstimator e = vmap::FundamentalEstimator();
  [[nodiscard]] vmap::Verification verify(const vmap::Features& a, const vmap::Features& b,
                                          const vmap::Matches& m) const {
    return e.verify(a, b, m);
  }
};

}  // namespace

TEST_CASE("hot path: match_into with reused buffers equals match, pair after pair") {
  const auto f = sample_features(8);
  for (const auto mode : {vmap::MatchMode::mutual, vmap::MatchMode::ratio}) {
    const vmap::BruteForceMatcher matcher({.mode = mode});
    vmap::BruteForceMatcher::Scratch scratch;
    vmap::Matches reused;
    for (std::size_t j = 1; j < f.size(); ++j) {
      matcher.match_into(f[0], f[j], reused, scratch);
      const vmap::Matches fresh = matcher.match(f[0], f[j]);
      REQUIRE(reused.size() == fresh.size());
      CHECK(reused.size() > 50);
      for (std::size_t k = 0; k < fresh.size(); ++k) {
        CHECK(reused[k].queryIdx == fresh[k].queryIdx);
        CHECK(reused[k].trainIdx == fresh[k].trainIdx);
        CHECK(reused[k].distance == fresh[k].distance);
      }
    }
  }
}

TEST_CASE("hot path: verify_into with reused buffers and a deferred degeneracy check equals verify") {
  const auto f = sample_features(8);
  const vmap::BruteForceMatcher matcher;
  int checked = 0;
  for (const auto method : {vmap::RobustMethod::magsac, vmap::RobustMethod::ransac, vmap::RobustMethod::lmeds,
                            vmap::RobustMethod::eight_point}) {
    const vmap::FundamentalEstimator est({.method = method, .seed = method == vmap::RobustMethod::ransac ? 5u : 0u});
    vmap::FundamentalEstimator::Scratch scratch;
    vmap::Verification eager_reused, deferred;
    for (std::size_t j = 1; j < f.size(); ++j) {
      CAPTURE(j);
      const vmap::Matches m = matcher.match(f[0], f[j]);
      const vmap::Verification fresh = est.verify(f[0], f[j], m);
      CHECK_FALSE(est.verify_into(f[0], f[j], m, eager_reused, scratch, false));
      check_same(eager_reused, fresh);
      const bool pending = est.verify_into(f[0], f[j], m, deferred, scratch, true);
      CHECK(pending == fresh.ok());
      CHECK(deferred.homography_inliers == 0);  // not computed yet
      est.complete_degeneracy(f[0], f[j], m, deferred);
      check_same(deferred, fresh);
      if (fresh.homography_inliers > 0) ++checked;
    }
  }
  CHECK(checked > 10);  // the homography check really ran on these pairs
  // Too few matches: nothing to defer, the reused result is reset.
  const vmap::FundamentalEstimator est;
  vmap::FundamentalEstimator::Scratch scratch;
  vmap::Verification v;
  (void)est.verify_into(f[0], f[1], matcher.match(f[0], f[1]), v, scratch, true);
  CHECK_FALSE(est.verify_into(f[0], f[1], vmap::Matches(5), v, scratch, true));
  CHECK(v.status == vmap::VerificationStatus::too_few_matches);
  CHECK(v.inlier_mask.empty());
  CHECK(v.matches == 5);
}

TEST_CASE("hot path: the selector with reused buffers keeps the same key images, links and saved state") {
  const auto frames = sample_frames(30);
  const vmap::SelectorOptions o{.tau = 0.35};
  // Degeneracy check on (the default): push() defers it, state() completes it.
  vmap::OrbMagsacSelector fast(vmap::OrbDescriptor{}, vmap::BruteForceMatcher{}, vmap::FundamentalEstimator{},
                               vmap::InlierRatio{}, o);
  vmap::KeyframeSelector<vmap::OrbDescriptor, PlainMatcher, PlainEstimator, vmap::InlierRatio> plain(
      vmap::OrbDescriptor{}, PlainMatcher{}, PlainEstimator{}, vmap::InlierRatio{}, o);
  int scored = 0, with_homography = 0;
  for (const auto& frame : frames) {
    const auto a = fast.push(frame);
    const auto b = plain.push(frame);
    CHECK(a.similarity == b.similarity);
    CHECK(a.raw_matches == b.raw_matches);
    CHECK(a.verified_matches == b.verified_matches);
    CHECK(a.key_frame == b.key_frame);
    CHECK(a.reason == b.reason);
    const auto sa = fast.state();
    const auto sb = plain.state();
    REQUIRE(sa.previous_score.has_value() == sb.previous_score.has_value());
    REQUIRE(sa.previous.has_value() == sb.previous.has_value());
    if (sa.previous) CHECK(sa.previous->name == sb.previous->name);
    if (!sa.previous_score) continue;
    ++scored;
    check_same(sa.previous_score->verification, sb.previous_score->verification);
    if (sa.previous_score->verification.homography_inliers > 0) ++with_homography;
  }
  CHECK(scored > 5);
  CHECK(with_homography > 5);
  CHECK(fast.map().key_indices() == plain.map().key_indices());
  CHECK(fast.map().keys.size() >= 3);
  REQUIRE(fast.map().pairs.size() == plain.map().pairs.size());
  for (std::size_t k = 0; k < fast.map().pairs.size(); ++k) {
    CHECK(fast.map().pairs[k].fundamental == plain.map().pairs[k].fundamental);
    CHECK(fast.map().pairs[k].inliers == plain.map().pairs[k].inliers);
    CHECK(fast.map().pairs[k].similarity == plain.map().pairs[k].similarity);
  }
  for (std::size_t k = 0; k < fast.map().keys.size(); ++k) CHECK(fast.map().keys[k].name == plain.map().keys[k].name);
}

// A store rewrites the selector's state at every frame without paying the homography
// fit push() deferred: deferred_state() keeps the F-matrix's inlier mask instead, and a
// selector restored from it completes the fit when its state() is read, to the value
// the uninterrupted selector reports; the restored selector then goes on identically.
TEST_CASE("hot path: a state with its degeneracy deferred restores to the same state and the same key images") {
  const auto frames = sample_frames(30);
  const vmap::SelectorOptions o{.tau = 0.35};
  const auto make = [&] {
    return vmap::OrbMagsacSelector(vmap::OrbDescriptor{}, vmap::BruteForceMatcher{}, vmap::FundamentalEstimator{},
                                   vmap::InlierRatio{}, o);
  };
  auto run = make();
  int deferred = 0, with_homography = 0;
  std::optional<vmap::SelectorState<vmap::Features>> a_deferred;
  for (std::size_t j = 0; j < frames.size(); ++j) {
    (void)run.push(frames[j]);
    auto d = run.deferred_state();
    if (d.degeneracy_deferred) {
      ++deferred;
      REQUIRE(d.previous_score.has_value());
      CHECK(d.previous_score->verification.degeneracy == vmap::Degeneracy::none);
      CHECK(d.previous_score->verification.homography_inliers == 0);
      CHECK(d.previous_score->verification.inlier_mask.size() ==
            static_cast<std::size_t>(d.previous_score->verification.matches));
    }
    d.map = run.map();
    if (d.degeneracy_deferred) a_deferred = d;
    auto resumed = make();
    resumed.restore(std::move(d));
    const auto want = run.state();
    const auto got = resumed.state();
    REQUIRE(got.previous_score.has_value() == want.previous_score.has_value());
    if (want.previous_score) {
      check_same(got.previous_score->verification, want.previous_score->verification);
      if (want.previous_score->verification.homography_inliers > 0) ++with_homography;
    }
    // The rest of the sequence from the restored selector: the same key images.
    if (j % 7 == 3) {
      auto rest = make();
      auto again = run.deferred_state();
      again.map = run.map();
      rest.restore(std::move(again));
      auto ref = make();
      for (std::size_t i = 0; i <= j; ++i) (void)ref.push(frames[i]);
      for (std::size_t i = j + 1; i < frames.size(); ++i) {
        const auto a = rest.push(frames[i]);
        const auto b = ref.push(frames[i]);
        CHECK(a.key_frame == b.key_frame);
        CHECK(a.similarity == b.similarity);
      }
      CHECK(rest.map().key_indices() == ref.map().key_indices());
    }
  }
  CHECK(deferred > 5);
  CHECK(with_homography > 5);

  // A deferred state without the mask that completes it is refused.
  REQUIRE(a_deferred.has_value());

  // As a memory file or store holds it (flag 2, the score, the inlier mask): read back
  // equal, and a damaged mask or flag is an Error naming what is wrong.
  vmap::detail::BinaryWriter w;
  vmap::detail::write_previous_score(w, *a_deferred);
  const std::string bytes = std::move(w).take();
  const auto read = [&](const std::string& b) {
    vmap::SelectorState<vmap::Features> s;
    s.previous = a_deferred->previous;
    vmap::detail::BinaryReader r(b, "selector state");
    vmap::detail::read_previous_score(r, s);
    r.expect_end("the score");
    return s;
  };
  const auto back = read(bytes);
  CHECK(back.degeneracy_deferred);
  REQUIRE(back.previous_score.has_value());
  check_same(back.previous_score->verification, a_deferred->previous_score->verification);
  CHECK(bytes[0] == 2);
  std::string bad_flag = bytes, bad_mask = bytes, short_mask = bytes;
  bad_flag[0] = 3;
  CHECK_THROWS_WITH_AS(read(bad_flag), doctest::Contains("invalid previous score flag"), vmap::Error);
  bad_mask.back() = 2;
  CHECK_THROWS_WITH_AS(read(bad_mask), doctest::Contains("inlier mask byte is not 0 or 1"), vmap::Error);
  bad_mask.back() = static_cast<char>(1 - bytes.back());
  CHECK_THROWS_WITH_AS(read(bad_mask), doctest::Contains("does not hold the score's inliers"), vmap::Error);
  short_mask.pop_back();
  CHECK_THROWS_AS(read(short_mask), vmap::Error);

  a_deferred->previous_score->verification.inlier_mask.pop_back();
  auto r = make();
  CHECK_THROWS_WITH_AS(r.restore(std::move(*a_deferred)), doctest::Contains("deferred degeneracy"), vmap::Error);
}
