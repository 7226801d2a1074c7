// Selection logic (Algorithm 1 / eq. 6) with scripted front ends, the PairMatcher front
// end on synthetic correspondences, and eq. 7 on hand-computed maps.
#include "support/synthetic.hpp"

#include <vmap/keyframe/pipeline.hpp>
#include <vmap/keyframe/selector.hpp>
#include <vmap/keyframe/stacks.hpp>
#include <vmap/keyframe/visual_map.hpp>

#include <doctest/doctest.h>

#include <cmath>
#include <functional>
#include <limits>
#include <set>
#include <vector>

namespace {

using vmap::KeyReason;
using vmap::KeyRule;
using vmap::PairScore;

/// A front end whose similarity is a given function of (key frame, frame): items are the
/// frame numbers. Raw matches are 1000 * (S + 0.05), so the upper bound is S + 0.05.
/// Frames in `failing` fail verification (too few matches) against any key.
struct ScriptedFrontEnd {
  using Item = int;
  std::function<double(int, int)> similarity;
  std::set<int> failing;
  int* verifications = nullptr;  // counts estimator runs

  PairScore score(int key, int frame, double skip_below) const {
    const double s = similarity(key, frame);
    PairScore p;
    p.raw_matches = static_cast<int>(std::lround(1000.0 * std::min(1.0, s + 0.05)));
    p.upper_bound = p.raw_matches / 1000.0;
    if (p.upper_bound < skip_below) return p;
    if (verifications) ++*verifications;
    p.verified_run = true;
    if (failing.count(frame)) {
      p.verification.status = vmap::VerificationStatus::too_few_matches;
      return p;
    }
    p.verification.status = vmap::VerificationStatus::verified;
    p.verification.inliers = static_cast<int>(std::lround(1000.0 * s));
    p.verification.matches = p.raw_matches;
    p.similarity = s;
    return p;
  }
  vmap::Features features_of(int) const { return {}; }
};
static_assert(vmap::KeyframeFrontEnd<ScriptedFrontEnd>);
static_assert(!vmap::FrameFrontEnd<ScriptedFrontEnd>);  // no prepare(): items come from the test

std::vector<std::size_t> run(ScriptedFrontEnd fe, int frames, vmap::SelectorOptions o,
                             std::vector<vmap::FrameResult>* results = nullptr) {
  vmap::BasicKeyframeSelector<ScriptedFrontEnd> sel(std::move(fe), o);
  for (int j = 0; j < frames; ++j) {
    auto r = sel.push(vmap::PreparedFrame<int>{j, static_cast<std::size_t>(j), "f" + std::to_string(j), 0.0, {}});
    if (results) results->push_back(r);
  }
  return sel.map().key_indices();
}

using Keys = std::vector<std::size_t>;

// S falls by 0.1 per frame of distance to the key image.
double linear(int key, int frame) { return std::max(0.0, 1.0 - 0.1 * (frame - key)); }

}  // namespace

TEST_CASE("selector: eq. 6 takes the previous frame, Algorithm 1 the current one") {
  ScriptedFrontEnd fe{linear, {}, nullptr};
  // tau 0.65: frames at distance 1..3 pass (0.9, 0.8, 0.7), distance 4 (0.6) fails.
  CHECK(run(fe, 12, {.tau = 0.65, .rule = KeyRule::previous_frame}) == Keys{0, 3, 6, 9});
  CHECK(run(fe, 12, {.tau = 0.65, .rule = KeyRule::current_frame}) == Keys{0, 4, 8});
}

TEST_CASE("selector: when I_{j-1} is the key image, eq. 6 takes I_j") {
  // Every frame differs from every other one: S = 0.2 < tau for any pair.
  ScriptedFrontEnd fe{[](int, int) { return 0.2; }, {}, nullptr};
  std::vector<vmap::FrameResult> rs;
  CHECK(run(fe, 5, {.tau = 0.5}, &rs) == Keys{0, 1, 2, 3, 4});
  for (std::size_t j = 1; j < rs.size(); ++j) {
    CHECK(rs[j].key_taken);
    REQUIRE(rs[j].key_frame.has_value());
    CHECK(*rs[j].key_frame == j);
    CHECK(rs[j].reason == KeyReason::bound_below_threshold);  // bound 0.25 < 0.5
  }
}

TEST_CASE("selector: after an eq. 6 change, the frame that triggered it can be the next key") {
  // Key 0; frame 3 fails against 0 -> key 2. Frame 3 is not compared with key 2; frame 4
  // vs 2 fails (S by a distance-2 drop) -> key 3, whose link to 2 must be computed.
  auto s = [](int key, int frame) { return frame - key >= 2 && frame >= 3 ? 0.1 : 0.9; };
  int verifications = 0;
  ScriptedFrontEnd fe{s, {}, &verifications};
  vmap::BasicKeyframeSelector<ScriptedFrontEnd> sel(fe, {.tau = 0.5});
  for (int j = 0; j < 5; ++j) sel.push(vmap::PreparedFrame<int>{j, static_cast<std::size_t>(j), "", 0.0, {}});
  CHECK(sel.map().key_indices() == Keys{0, 2, 3});
  REQUIRE(sel.map().pairs.size() == 2);
  CHECK(sel.map().pairs[0].similarity == doctest::Approx(0.9));  // S(0, 2), cached from frame 2's turn
  CHECK(sel.map().pairs[1].similarity == doctest::Approx(0.9));  // S(2, 3), computed at the change
  CHECK(sel.map().pairs[1].inliers == 900);
}

TEST_CASE("selector: a verification failure ends the key image") {
  // S stays high, but frame 5 cannot be verified.
  ScriptedFrontEnd fe{[](int, int) { return 0.95; }, {5}, nullptr};
  std::vector<vmap::FrameResult> rs;
  CHECK(run(fe, 9, {.tau = 0.3, .rule = KeyRule::previous_frame}, &rs) == Keys{0, 4});
  CHECK(rs[5].reason == KeyReason::verification_failed);
  CHECK(rs[5].status == vmap::VerificationStatus::too_few_matches);
  CHECK(rs[5].key_frame == std::optional<std::size_t>(4));
  CHECK(run(fe, 9, {.tau = 0.3, .rule = KeyRule::current_frame}) == Keys{0, 5});
}

TEST_CASE("selector: per-frame results report similarity, matches and reasons") {
  ScriptedFrontEnd fe{linear, {}, nullptr};
  std::vector<vmap::FrameResult> rs;
  run(fe, 6, {.tau = 0.65, .skip_by_upper_bound = false}, &rs);
  REQUIRE(rs.size() == 6);
  CHECK(rs[0].reason == KeyReason::first_frame);
  CHECK(rs[0].key_frame == std::optional<std::size_t>(0));
  CHECK(rs[2].similarity == doctest::Approx(0.8));
  CHECK(rs[2].verified_matches == 800);
  CHECK(rs[2].raw_matches == 850);
  CHECK_FALSE(rs[2].key_taken);
  CHECK(rs[2].reason == KeyReason::none);
  CHECK(rs[4].key_taken);
  CHECK(rs[4].reason == KeyReason::below_threshold);
  CHECK(rs[4].similarity == doctest::Approx(0.6));
  CHECK(rs[4].exact);
  CHECK(rs[4].key_frame == std::optional<std::size_t>(3));
}

TEST_CASE("selector: the upper-bound skip never changes key images, and saves estimator runs") {
  const std::vector<std::function<double(int, int)>> scripts = {
      linear,
      [](int key, int frame) { return std::fmod(0.37 * frame + 0.11 * key, 1.0); },
      [](int key, int frame) { return (frame * 7 + key * 3) % 10 / 10.0; },
  };
  for (const auto& script : scripts)
    for (double tau : {0.15, 0.3, 0.5, 0.65, 0.9, 1.0})
      for (KeyRule rule : {KeyRule::previous_frame, KeyRule::current_frame}) {
        int with_skip = 0, without = 0;
        vmap::BasicKeyframeSelector<ScriptedFrontEnd> a(ScriptedFrontEnd{script, {7}, &with_skip},
                                                        {.tau = tau, .rule = rule, .skip_by_upper_bound = true});
        vmap::BasicKeyframeSelector<ScriptedFrontEnd> b(ScriptedFrontEnd{script, {7}, &without},
                                                        {.tau = tau, .rule = rule, .skip_by_upper_bound = false});
        for (int j = 0; j < 40; ++j) {
          a.push(vmap::PreparedFrame<int>{j, static_cast<std::size_t>(j), "", 0.0, {}});
          b.push(vmap::PreparedFrame<int>{j, static_cast<std::size_t>(j), "", 0.0, {}});
        }
        CAPTURE(tau);
        CHECK(a.map().key_indices() == b.map().key_indices());
        REQUIRE(a.map().pairs.size() == b.map().pairs.size());
        for (std::size_t k = 0; k < a.map().pairs.size(); ++k) {
          CHECK(a.map().pairs[k].similarity == b.map().pairs[k].similarity);
          CHECK(a.map().pairs[k].inliers == b.map().pairs[k].inliers);
        }
        CHECK(with_skip <= without);
      }
  // With the linear script at tau 0.65 the skip is exercised: S 0.6 has bound 0.65,
  // S 0.5 bound 0.55 < 0.65.
  int with_skip = 0, without = 0;
  run(ScriptedFrontEnd{[](int, int f) { return f % 2 ? 0.5 : 0.9; }, {}, &with_skip}, 20, {.tau = 0.65});
  run(ScriptedFrontEnd{[](int, int f) { return f % 2 ? 0.5 : 0.9; }, {}, &without}, 20,
      {.tau = 0.65, .skip_by_upper_bound = false});
  CHECK(with_skip < without);
}

TEST_CASE("selector: tau outside (0, 1] is an Error naming the option") {
  ScriptedFrontEnd fe{linear, {}, nullptr};
  for (double tau : {0.0, -0.1, 1.5, std::numeric_limits<double>::quiet_NaN()}) {
    CAPTURE(tau);
    CHECK_THROWS_WITH_AS(vmap::BasicKeyframeSelector<ScriptedFrontEnd>(fe, {.tau = tau}),
                         doctest::Contains("SelectorOptions.tau"), vmap::Error);
  }
  CHECK_NOTHROW(vmap::BasicKeyframeSelector<ScriptedFrontEnd>(fe, {.tau = 1.0}));
}

TEST_CASE("selector: an empty image is an Error") {
  vmap::OrbMagsacSelector sel;
  CHECK_THROWS_AS(sel.push(cv::Mat()), vmap::Error);
}

TEST_CASE("selector: take_map and reset start a new sequence") {
  ScriptedFrontEnd fe{linear, {}, nullptr};
  vmap::BasicKeyframeSelector<ScriptedFrontEnd> sel(fe, {.tau = 0.65});
  for (int j = 0; j < 8; ++j) sel.push(vmap::PreparedFrame<int>{j, static_cast<std::size_t>(j), "", 0.0, {}});
  const vmap::VisualMap m = sel.take_map();
  CHECK(m.frames == 8);
  CHECK(m.key_indices() == Keys{0, 3, 6});
  CHECK(sel.map().frames == 0);
  CHECK(sel.map().keys.empty());
  sel.push(vmap::PreparedFrame<int>{5, 5, "", 0.0, {}});
  CHECK(sel.map().key_indices() == Keys{5});
}

// ---- PairMatcher front end -----------------------------------------------------------

namespace {

/// A detector-free matcher stand-in: images carry their frame number in pixel (0, 0);
/// a pair at distance d yields a synthetic two-view scene of 400 - 60 d correspondences
/// (30 % outliers), frame 5 yields only 5. Denominator: 400 cells.
struct ScriptedPairMatcher {
  int calls = 0;
  vmap::Correspondences match_pair(const cv::Mat& a, const cv::Mat& b) {
    ++calls;
    const int i = a.at<unsigned char>(0, 0), j = b.at<unsigned char>(0, 0);
    vmap::Correspondences c;
    c.cells = 400;
    const int points = j == 5 ? 5 : std::max(10, 400 - 60 * (j - i));
    const auto scene = vmap::test::make_two_view_scene(
        {.points = points, .outlier_fraction = 0.3, .seed = static_cast<std::uint64_t>(100 * i + j + 1)});
    for (const auto& m : scene.matches) {
      c.points_a.push_back(scene.a.keypoints[static_cast<std::size_t>(m.queryIdx)].pt);
      c.points_b.push_back(scene.b.keypoints[static_cast<std::size_t>(m.trainIdx)].pt);
      c.confidence.push_back(0.9f);
    }
    return c;
  }
};
static_assert(vmap::PairMatcher<ScriptedPairMatcher>);
static_assert(vmap::FrameFrontEnd<vmap::PairFrontEnd<ScriptedPairMatcher, vmap::FundamentalEstimator>>);

cv::Mat numbered(int j) { return cv::Mat(8, 8, CV_8UC1, cv::Scalar(j)); }

}  // namespace

TEST_CASE("pair-matcher selector: eq. 5 with the matcher's cells, both rules") {
  // Distance 1: 340 correspondences, ~238 inliers -> S ~ 0.6; distance 2: ~196 -> 0.49;
  // distance 3: ~154 -> 0.385. tau 0.45: a key image covers two more frames.
  const vmap::FundamentalEstimator est({.check_degeneracy = false});
  for (KeyRule rule : {KeyRule::previous_frame, KeyRule::current_frame}) {
    vmap::PairKeyframeSelector<ScriptedPairMatcher, vmap::FundamentalEstimator> sel(ScriptedPairMatcher{}, est,
                                                                                  {.tau = 0.45, .rule = rule});
    std::vector<vmap::FrameResult> rs;
    for (int j = 0; j < 5; ++j) rs.push_back(sel.push(numbered(j)));
    if (rule == KeyRule::previous_frame) {
      CHECK(sel.map().key_indices() == Keys{0, 2});
    } else {
      CHECK(sel.map().key_indices() == Keys{0, 3});
    }
    CHECK(rs[1].similarity == doctest::Approx(0.6).epsilon(0.05));
    CHECK(rs[1].raw_matches == 340);
    for (const auto& p : sel.map().pairs) {
      CHECK(p.status == vmap::VerificationStatus::verified);
      CHECK(p.similarity == doctest::Approx(p.inliers / 400.0));
    }
    CHECK(sel.map().keys[0].features.empty());  // a pair matcher keeps no features
  }
}

TEST_CASE("pair-matcher selector: too few correspondences is a verification failure") {
  vmap::PairKeyframeSelector<ScriptedPairMatcher, vmap::FundamentalEstimator> sel(
      ScriptedPairMatcher{}, vmap::FundamentalEstimator({.check_degeneracy = false}),
      {.tau = 0.01, .skip_by_upper_bound = false});
  std::vector<vmap::FrameResult> rs;
  for (int j = 0; j < 7; ++j) rs.push_back(sel.push(numbered(j)));
  CHECK(rs[5].reason == KeyReason::verification_failed);
  CHECK(sel.map().key_indices() == Keys{0, 4});  // eq. 6: frame 4 precedes the failure
}

TEST_CASE("pair-matcher selector: cells <= 0 is an Error") {
  struct NoCells {
    vmap::Correspondences match_pair(const cv::Mat&, const cv::Mat&) { return {}; }
  };
  vmap::PairKeyframeSelector<NoCells, vmap::FundamentalEstimator> sel(NoCells{}, vmap::FundamentalEstimator{});
  sel.push(numbered(0));
  CHECK_THROWS_WITH_AS(sel.push(numbered(1)), doctest::Contains("cells"), vmap::Error);
}

// ---- eq. 7 ---------------------------------------------------------------------------

namespace {
vmap::VisualMap hand_map(std::size_t frames, const std::vector<double>& sims, const std::vector<int>& inliers) {
  vmap::VisualMap m;
  m.frames = frames;
  m.keys.resize(sims.size() + 1);
  for (std::size_t k = 0; k < sims.size(); ++k) {
    vmap::KeyPair p;
    p.status = vmap::VerificationStatus::verified;
    p.similarity = sims[k];
    p.inliers = inliers[k];
    p.matches = inliers[k] + 10;
    m.pairs.push_back(p);
  }
  return m;
}
}  // namespace

TEST_CASE("quality: eq. 7 over the m-1 pairs and the paper's literal 1/m form") {
  // n = 10, m = 3, S = 0.5, 0.7: Q = 1/2 ((1 - 3/10) + 0.6) = 0.65; literal: 1.2 / 3 = 0.4
  // -> 1/2 (0.7 + 0.4) = 0.55.
  const auto m = hand_map(10, {0.5, 0.7}, {120, 80});
  CHECK(m.quality() == doctest::Approx(0.65));
  CHECK(m.quality(vmap::QualityForm::paper_literal) == doctest::Approx(0.55));
  const auto s = m.stats();
  CHECK(s.frames == 10);
  CHECK(s.key_images == 3);
  CHECK(s.min_matches == 80);
  CHECK(s.max_matches == 120);
  CHECK(s.mean_matches == doctest::Approx(100.0));
  CHECK(s.mean_similarity == doctest::Approx(0.6));
  CHECK(s.quality == doctest::Approx(0.65));

  // m = 1: no pair, the mean term is 0: Q = 1/2 (1 - 1/4).
  const auto one = hand_map(4, {}, {});
  CHECK(one.quality() == doctest::Approx(0.375));
  CHECK(one.quality(vmap::QualityForm::paper_literal) == doctest::Approx(0.375));
  CHECK(one.stats().min_matches == 0);
  CHECK(vmap::VisualMap{}.quality() == 0.0);

  // Every frame a key image with S = 1: Q = 1/2 (0 + 1).
  CHECK(hand_map(4, {1, 1, 1}, {9, 9, 9}).quality() == doctest::Approx(0.5));
}

// Every shipped stack compiles in full (STYLE.md: explicit instantiation).
template class vmap::BasicKeyframeSelector<
    vmap::FeatureFrontEnd<vmap::OrbDescriptor, vmap::BruteForceMatcher, vmap::FundamentalEstimator, vmap::InlierRatio>>;
template class vmap::BasicKeyframeSelector<vmap::FeatureFrontEnd<vmap::AkazeDescriptor, vmap::BruteForceMatcher,
                                                                 vmap::FundamentalEstimator, vmap::InlierRatioMin>>;
template class vmap::BasicKeyframeSelector<
    vmap::FeatureFrontEnd<vmap::SiftDescriptor, vmap::BruteForceMatcher, vmap::FundamentalEstimator, vmap::InlierRatio>>;
template class vmap::BasicKeyframeSelector<vmap::PairFrontEnd<ScriptedPairMatcher, vmap::FundamentalEstimator>>;
template class vmap::KeyframeSelector<vmap::OrbDescriptor, vmap::BruteForceMatcher, vmap::FundamentalEstimator,
                                      vmap::InlierRatio>;
