#include <vmap/features/orb.hpp>
#include <vmap/geometry/essential.hpp>
#include <vmap/geometry/fundamental.hpp>
#include <vmap/io/calibration.hpp>
#include <vmap/io/files.hpp>
#include <vmap/io/frame_source.hpp>
#include <vmap/lcd/evaluation.hpp>
#include <vmap/lcd/loop_detector.hpp>
#include <vmap/lcd/loop_engine.hpp>
#include <vmap/lcd/place_decision.hpp>
#include <vmap/matching/brute_force.hpp>
#include <vmap/memory/stacks.hpp>
#include <vmap/memory/visual_memory.hpp>

#include "support/frames.hpp"
#include "support/scripted_ranker.hpp"
#include "support/shared_data.hpp"
#include "support/two_laps.hpp"

#include <doctest/doctest.h>

#include <opencv2/imgcodecs.hpp>
#include <opencv2/imgproc.hpp>

#include <cmath>
#include <functional>
#include <optional>
#include <random>
#include <string>
#include <vector>

using vmap::PlaceStatus;

namespace {

// P(X >= k) for X ~ Binomial(n, p), summed term by term in double precision.
double binomial_tail(int k, int n, double p) {
  double sum = 0.0;
  for (int i = k; i <= n; ++i) sum += std::exp(std::lgamma(n + 1.0) - std::lgamma(i + 1.0) - std::lgamma(n - i + 1.0)) *
                                      std::pow(p, i) * std::pow(1 - p, n - i);
  return sum;
}

// Keypoints on a w x h grid of `step` pixels, and matches i -> i; the first `inliers`
// marked inliers in the mask.
struct Pair {
  vmap::Features a, b;
  vmap::Matches matches;
  vmap::Verification v;
};

Pair grid_pair(int w, int h, int step, const std::function<bool(cv::Point2f)>& inlier) {
  Pair p;
  for (int y = 0; y < h; y += step)
    for (int x = 0; x < w; x += step) {
      p.a.keypoints.emplace_back(cv::Point2f(static_cast<float>(x), static_cast<float>(y)), 1.0f);
      p.b.keypoints.emplace_back(cv::Point2f(static_cast<float>(x), static_cast<float>(y)), 1.0f);
    }
  for (std::size_t i = 0; i < p.a.keypoints.size(); ++i) {
    p.matches.emplace_back(static_cast<int>(i), static_cast<int>(i), 0.0f);
    const bool in = inlier(p.a.keypoints[i].pt);
    p.v.inlier_mask.push_back(in ? 1 : 0);
    p.v.inliers += in ? 1 : 0;
  }
  p.v.matches = static_cast<int>(p.matches.size());
  p.v.status = vmap::VerificationStatus::verified;
  return p;
}

using vmap::test::ScriptedRanker;

using Engine = vmap::LoopEngine<vmap::BruteForceMatcher, vmap::FundamentalEstimator, ScriptedRanker>;

}  // namespace

TEST_CASE("place evidence: significance is the binomial tail beyond the minimal sample, exactly") {
  // Hand-checked small cases: P(Bin(10, 0.1) >= 5) = 0.0016349374...
  CHECK(vmap::detail::binomial_tail_significance(5, 10, 0.1) == doctest::Approx(-std::log10(0.00163493739)).epsilon(1e-9));
  for (const auto& [k, n] : {std::pair{3, 20}, {12, 40}, {40, 66}, {19, 25}, {300, 400}}) {
    CAPTURE(k);
    CAPTURE(n);
    const double tail = binomial_tail(k, n, 0.1);
    if (tail > 1e-300) CHECK(vmap::detail::binomial_tail_significance(k, n, 0.1) == doctest::Approx(-std::log10(tail)).epsilon(1e-9));
  }
  // At or below the mode there is no evidence; it grows with k for a fixed n.
  CHECK(vmap::detail::binomial_tail_significance(1, 10, 0.1) == 0.0);
  CHECK(vmap::detail::binomial_tail_significance(0, 0, 0.1) == 0.0);
  double last = 0.0;
  for (int k = 15; k <= 100; k += 5) {  // above the mode (10)
    const double s = vmap::detail::binomial_tail_significance(k, 100, 0.1);
    CHECK(s > last);
    last = s;
  }
}

TEST_CASE("place evidence: inliers, ratio, significance and spread of a pair with known inliers") {
  // 20 x 20 keypoints over 400 x 400 px; the inliers are the keypoints left of x = 100:
  // 5 columns of 20, all in the first of the four grid columns.
  const Pair left = grid_pair(400, 400, 20, [](cv::Point2f p) { return p.x < 100; });
  const vmap::PlaceEvidence e =
      vmap::measure_place_evidence(left.a, left.b, left.matches, left.v, vmap::PlaceModel::fundamental);
  CHECK(e.matches == 400);
  CHECK(e.inliers == 100);
  CHECK(e.inlier_ratio == doctest::Approx(0.25));
  CHECK(e.significance == doctest::Approx(-std::log10(binomial_tail(93, 393, 0.1))).epsilon(1e-9));
  CHECK(e.spread == doctest::Approx(4.0 / 16.0));  // one grid column of four cells
  // The same count spread over the image (every 4th keypoint): every cell holds inliers.
  std::size_t i = 0;
  const Pair spread = grid_pair(400, 400, 20, [&](cv::Point2f) { return (i++ % 4) == 0; });
  const vmap::PlaceEvidence s =
      vmap::measure_place_evidence(spread.a, spread.b, spread.matches, spread.v, vmap::PlaceModel::fundamental);
  CHECK(s.inliers == 100);
  CHECK(s.spread == 1.0);
  CHECK(s.significance == doctest::Approx(e.significance));
  // Bunched inliers lose confidence in proportion to the spread below full_spread.
  const vmap::PlaceDecisionOptions o;
  const double full = 1.0 - std::exp2(-s.significance / o.half_significance);
  CHECK(vmap::place_confidence(s, o) == doctest::Approx(full));
  CHECK(vmap::place_confidence(e, o) == doctest::Approx(full * 0.25 / o.full_spread));
  // An essential matrix's minimal sample is 5: two more inliers count as evidence.
  const vmap::PlaceEvidence ess =
      vmap::measure_place_evidence(spread.a, spread.b, spread.matches, spread.v, vmap::PlaceModel::essential);
  CHECK(ess.significance == doctest::Approx(-std::log10(binomial_tail(95, 395, 0.1))).epsilon(1e-9));
  // Below min_inliers, or unverified: no confidence at all.
  vmap::PlaceEvidence few = s;
  few.inliers = 11;
  CHECK(vmap::place_confidence(few, o) == 0.0);
  vmap::Verification failed;
  const auto none = vmap::measure_place_evidence(spread.a, spread.b, spread.matches, failed, vmap::PlaceModel::fundamental);
  CHECK(none.inliers == 0);
  CHECK(none.significance == 0.0);
  CHECK(vmap::place_confidence(none, o) == 0.0);
}

TEST_CASE("place decision: a repeated texture patch with many inliers in a small area loses to a real revisit") {
  // The place: a textured scene. A revisit: the scene seen again, rotated by 4 degrees.
  // An impostor: another scene that holds one 80 x 80 patch of the place (a poster, a
  // repeated tile): its inliers fill one small area of the image.
  const cv::Mat place = vmap::test::place_image(71);
  const cv::Mat revisit = vmap::test::lap_frame(9, 8, 70);  // place 1 (seed 71), second lap
  cv::Mat impostor = vmap::test::place_image(99);
  place(cv::Rect(120, 80, 80, 80)).copyTo(impostor(cv::Rect(20, 20, 80, 80)));
  vmap::OrbDescriptor orb({.features = 1000});
  const vmap::Features fp = orb.extract(place), fr = orb.extract(revisit), fi = orb.extract(impostor);
  const vmap::BruteForceMatcher matcher;
  const vmap::FundamentalEstimator estimator({.seed = 3});
  const auto evidence = [&](const vmap::Features& q) {
    const auto m = matcher.match(q, fp);
    return vmap::measure_place_evidence(q, fp, m, estimator.verify(q, fp, m), vmap::PlaceModel::fundamental);
  };
  const vmap::PlaceEvidence real = evidence(fr), patch = evidence(fi);
  CAPTURE(real.inliers);
  CAPTURE(patch.inliers);
  CAPTURE(real.spread);
  CAPTURE(patch.spread);
  REQUIRE(patch.inliers >= 12);  // the patch does verify
  CHECK(patch.spread * 2 <= real.spread);
  const double c_real = vmap::place_confidence(real), c_patch = vmap::place_confidence(patch);
  CAPTURE(c_real);
  CAPTURE(c_patch);
  CHECK(c_real >= 0.5);
  CHECK(c_patch < c_real);
}

TEST_CASE("revisit rule: scripted chains of views (never left, left and came back, turned on the spot)") {
  // The chain of views alone decides what is a revisit: the bags of words are scripted,
  // or there are none (brute force, no vocabulary).
  vmap::OrbDescriptor orb({.features = 500});
  const auto trembling = [&](std::uint64_t seed, int k) {
    // A place with the camera trembling by up to 2.5 px, no two frames alike (identical
    // images give no F-matrix).
    const cv::Mat still = vmap::test::place_image(seed);
    cv::Mat moved;
    cv::warpAffine(still, moved, cv::Matx23d(1, 0, 0.13 * k, 0, 1, 0.07 * k), still.size(), cv::INTER_LINEAR,
                   cv::BORDER_REFLECT);
    return orb.extract(moved);
  };
  SUBCASE("never left: the camera rests on one place and the chain stays in one view") {
    std::vector<vmap::Features> frames;
    for (int k = 0; k < 20; ++k) frames.push_back(trembling(300, k));
    Engine e(vmap::BruteForceMatcher{}, vmap::FundamentalEstimator({.seed = 7}),
             {.window = 3, .index = vmap::CandidateIndex::bow}, ScriptedRanker([](std::size_t, std::size_t) { return 1.0; }));
    const auto lookup = [&](std::size_t j) -> const vmap::Features& { return frames[j]; };
    for (std::size_t k = 0; k < frames.size(); ++k) {
      const auto d = e.add(frames[k], {}, lookup, k == 0 ? vmap::ViewStep::new_view : vmap::ViewStep::same_view);
      CAPTURE(k);
      CHECK_FALSE(d.accepted());
      CHECK(e.view_of(k) == 0);
      if (k > 3) {
        CHECK(d.status == PlaceStatus::not_a_revisit);
        CHECK(d.reason_code == vmap::DecisionReason::camera_stayed);
        CHECK(d.reason == to_string(d.reason_code));
        for (const auto& c : d.considered)
          CHECK((c.stage == vmap::CandidateStage::not_a_revisit || c.stage == vmap::CandidateStage::verification_failed));
      }
    }
    CHECK(e.stationary());
    CHECK(e.not_a_revisit_queries() == 16);
    // The detector's own test of the chain (the selector's eq. 5 against the view's first
    // frame) keeps the trembling camera in one view, with no vocabulary at all.
    vmap::LoopDetector det(vmap::LabelSchema{}, vmap::OrbDescriptor({.features = 500}), vmap::BruteForceMatcher{},
                           vmap::FundamentalEstimator({.seed = 7}),
                           {.window = 3, .index = vmap::CandidateIndex::brute_force});
    std::size_t loops = 0;
    for (const auto& f : frames) loops += det.add(f, {}).loop() ? 1 : 0;
    CHECK(loops == 0);
    CHECK(det.view_start() == 0);
    CHECK(det.stationary());
  }
  SUBCASE("left and came back: places 0..7, then 0..7 again, each a new view") {
    std::vector<vmap::Features> frames;
    for (int k = 0; k < 16; ++k) frames.push_back(orb.extract(vmap::test::lap_frame(k, 8, 300)));
    Engine e(vmap::BruteForceMatcher{}, vmap::FundamentalEstimator({.seed = 7}),
             {.window = 3, .index = vmap::CandidateIndex::bow},
             ScriptedRanker([](std::size_t a, std::size_t b) { return a % 8 == b % 8 ? 1.0 : 0.05; }));
    // The same chain without bags of words: brute force verifies every older frame.
    vmap::LoopDetector det(vmap::LabelSchema{}, vmap::OrbDescriptor({.features = 500}), vmap::BruteForceMatcher{},
                           vmap::FundamentalEstimator({.seed = 7}),
                           {.window = 3, .index = vmap::CandidateIndex::brute_force});
    const auto lookup = [&](std::size_t j) -> const vmap::Features& { return frames[j]; };
    for (std::size_t k = 0; k < frames.size(); ++k) {
      const auto d = e.add(frames[k], {}, lookup);
      const auto r = det.add(frames[k], {});
      CAPTURE(k);
      CHECK(e.view_of(k) == k);
      CHECK(det.view_start() == k);  // each place is a new view for the detector's own test too
      if (k < 8) {
        CHECK_FALSE(d.accepted());
        CHECK_FALSE(r.loop());
        continue;
      }
      CHECK(d.status == PlaceStatus::accepted);
      REQUIRE(d.best.has_value());
      CHECK(*d.best == k - 8);
      CHECK(d.reason_code == vmap::DecisionReason::confident);
      CHECK(d.reason.rfind("confidence", 0) == 0);
      REQUIRE(r.loop());
      CHECK(*r.best == k - 8);
    }
    CHECK_FALSE(e.stationary());
    CHECK_FALSE(det.stationary());
  }
  SUBCASE("turned on the spot: eight views around, back to the first, then rests there") {
    // Views 0..7 are the directions around the spot; frame 8 faces direction 0 again
    // (rotated 4 degrees), frames 9..12 rest there in frame 8's view.
    std::vector<vmap::Features> frames;
    for (int k = 0; k < 9; ++k) frames.push_back(orb.extract(vmap::test::lap_frame(k, 8, 700)));
    for (int k = 9; k < 13; ++k) {
      const cv::Mat warp = cv::getRotationMatrix2D(cv::Point2f(160, 120), 4.0, 1.03);
      cv::Mat out, shifted;
      cv::warpAffine(vmap::test::place_image(700), out, warp, cv::Size(320, 240), cv::INTER_LINEAR, cv::BORDER_REFLECT);
      cv::warpAffine(out, shifted, cv::Matx23d(1, 0, 0.5 * (k % 5), 0, 1, 0.4 * (k % 3)), out.size(), cv::INTER_LINEAR,
                     cv::BORDER_REFLECT);
      frames.push_back(orb.extract(shifted));
    }
    Engine e(vmap::BruteForceMatcher{}, vmap::FundamentalEstimator({.seed = 7}),
             {.window = 3, .index = vmap::CandidateIndex::brute_force});
    const auto lookup = [&](std::size_t j) -> const vmap::Features& { return frames[j]; };
    for (std::size_t k = 0; k < frames.size(); ++k) {
      const auto d = e.add(frames[k], {}, lookup, k <= 8 ? vmap::ViewStep::new_view : vmap::ViewStep::same_view);
      CAPTURE(k);
      if (k < 8) {
        CHECK_FALSE(d.accepted());
        continue;
      }
      // Direction 0 was left (the chain turned through seven views) and is a revisit.
      CHECK(d.status == PlaceStatus::accepted);
      REQUIRE(d.best.has_value());
      CHECK(*d.best == 0);
      if (k == 12) {
        // Frame 8, past the window, is in frame 12's own view: not a revisit.
        bool saw_8 = false;
        for (const auto& c : d.considered)
          if (c.frame == 8) saw_8 = c.stage == vmap::CandidateStage::not_a_revisit;
        CHECK(saw_8);
      }
    }
    CHECK(e.view_of(12) == 8);
    CHECK_FALSE(e.stationary());
  }
}

TEST_CASE("revisit rule and ambiguity: a lookup that keeps one frame's features at a time gives the same decisions") {
  // A visual memory that bounds its RAM lends a released key image's features from one
  // buffer, replaced at its next read: the engine must not hold two of its references.
  vmap::OrbDescriptor orb({.features = 500});
  std::vector<vmap::Features> frames;
  for (int k = 0; k < 16; ++k) frames.push_back(orb.extract(vmap::test::lap_frame(k, 8, 900)));
  const vmap::LoopOptions o{.window = 3, .index = vmap::CandidateIndex::brute_force};
  Engine stable(vmap::BruteForceMatcher{}, vmap::FundamentalEstimator({.seed = 7}), o);
  Engine slotted(vmap::BruteForceMatcher{}, vmap::FundamentalEstimator({.seed = 7}), o);
  const auto lookup = [&](std::size_t j) -> const vmap::Features& { return frames[j]; };
  std::optional<std::pair<std::size_t, vmap::Features>> slot;
  const auto one_slot = [&](std::size_t j) -> const vmap::Features& {
    if (!slot || slot->first != j) slot.emplace(j, frames[j]);
    return slot->second;
  };
  std::size_t accepted = 0;
  for (std::size_t k = 0; k < frames.size(); ++k) {
    const auto a = stable.add(frames[k], {}, lookup);
    const auto b = slotted.add(frames[k], {}, one_slot);
    CAPTURE(k);
    CHECK(a.status == b.status);
    CHECK(a.best == b.best);
    CHECK(a.confidence == b.confidence);
    accepted += a.accepted() ? 1 : 0;
  }
  CHECK(accepted == 8);
}

TEST_CASE("place decision: each rejection says why") {
  vmap::OrbDescriptor orb({.features = 500});
  std::vector<vmap::Features> frames;
  for (int k = 0; k < 16; ++k) frames.push_back(orb.extract(vmap::test::lap_frame(k, 8, 400)));
  const auto lookup = [&](std::size_t j) -> const vmap::Features& { return frames[j]; };
  const auto run = [&](const vmap::LoopOptions& o) {
    Engine e(vmap::BruteForceMatcher{}, vmap::FundamentalEstimator({.seed = 7}), o,
             ScriptedRanker([](std::size_t a, std::size_t b) { return a % 8 == b % 8 ? 1.0 : 0.05; }));
    std::vector<vmap::PlaceDecision> out;
    for (const auto& f : frames) out.push_back(e.add(f, {}, lookup));
    return out;
  };
  const vmap::LoopOptions base{.window = 3, .index = vmap::CandidateIndex::bow};
  // No candidates: the first frames.
  CHECK(run(base)[0].reason_code == vmap::DecisionReason::no_candidates);
  CHECK(run(base)[0].reason == "no candidates");
  // Below the bag-of-words score.
  auto floor = base;
  floor.min_bow_score = 2.0;
  CHECK(run(floor)[9].reason_code == vmap::DecisionReason::below_bow_score);
  CHECK(run(floor)[9].reason == "every candidate below the bag-of-words score");
  // Too few inliers for the floor.
  auto strict = base;
  strict.decision.min_inliers = 100000;
  const auto few = run(strict)[9];
  CHECK(few.status == PlaceStatus::too_little_evidence);
  CHECK(few.reason_code == vmap::DecisionReason::too_few_inliers);
  CHECK(few.reason.find(" inliers < 100000") != std::string::npos);
  // Not confident enough: an unknown place, with its confidence.
  auto high = base;
  high.decision.min_confidence = 1.0;
  const auto unknown = run(high)[9];
  CHECK(unknown.status == PlaceStatus::unknown_place);
  CHECK(unknown.reason_code == vmap::DecisionReason::low_confidence);
  CHECK(unknown.reason.find("< 1.00") != std::string::npos);
  CHECK(unknown.confidence > 0.5);
  // Two places, both verified and about equally confident, that are not one place (they
  // do not verify against each other): ambiguous. Frames 0 and 5 are two places; query 9
  // sees the left half of the one and the right half of the other (rotated).
  const cv::Mat place_a = vmap::test::place_image(500), place_b = vmap::test::place_image(600);
  cv::Mat both = place_a.clone();
  place_b(cv::Rect(160, 0, 160, 240)).copyTo(both(cv::Rect(160, 0, 160, 240)));
  cv::Mat seen;
  cv::warpAffine(both, seen, cv::getRotationMatrix2D(cv::Point2f(160, 120), 4.0, 1.03), both.size(), cv::INTER_LINEAR,
                 cv::BORDER_REFLECT);
  std::vector<vmap::Features> twins = {orb.extract(place_a), frames[2], frames[3], frames[4], frames[5],
                                       orb.extract(place_b), frames[6], frames[7], frames[1], orb.extract(seen)};
  vmap::LoopOptions amb{.window = 2, .index = vmap::CandidateIndex::brute_force, .decision = {.ambiguity_ratio = 0.5}};
  Engine a(vmap::BruteForceMatcher{}, vmap::FundamentalEstimator({.seed = 7}), amb);
  const auto twin_lookup = [&](std::size_t j) -> const vmap::Features& { return twins[j]; };
  vmap::PlaceDecision last;
  for (const auto& f : twins) last = a.add(f, {}, twin_lookup);
  CAPTURE(last.reason);
  CHECK(last.status == PlaceStatus::ambiguous);
  CHECK(last.reason_code == vmap::DecisionReason::two_places);
  REQUIRE(last.second.has_value());
  CHECK(((*last.best == 0 && *last.second == 5) || (*last.best == 5 && *last.second == 0)));
  CHECK(last.reason.find("frames") == 0);
  // The same place seen on two earlier laps is one place, not two: the two candidates
  // verify against each other.
  std::vector<vmap::Features> laps = {orb.extract(place_a), frames[2], frames[3], frames[4], frames[5],
                                      orb.extract(vmap::test::lap_frame(8, 8, 500)), frames[6], frames[7], frames[1],
                                      orb.extract(seen)};
  Engine l(vmap::BruteForceMatcher{}, vmap::FundamentalEstimator({.seed = 7}), amb);
  const auto lap_lookup = [&](std::size_t j) -> const vmap::Features& { return laps[j]; };
  for (const auto& f : laps) last = l.add(f, {}, lap_lookup);
  CAPTURE(last.reason);
  CHECK(last.status == PlaceStatus::accepted);
  CHECK((*last.best == 0 || *last.best == 5));
  if (last.second) CHECK((*last.second != 0 && *last.second != 5));
  // Temporal consistency holds a first sighting back until the next query agrees.
  auto held = base;
  held.temporal_consistency = 1;
  const auto t = run(held);
  CHECK(t[8].status == PlaceStatus::too_little_evidence);
  CHECK(t[8].reason_code == vmap::DecisionReason::not_yet_confirmed);
  CHECK(t[8].reason == "not yet confirmed: 0 of 1 earlier queries agree");
  CHECK(t[9].status == PlaceStatus::accepted);
}

TEST_CASE("place decision: every reason has a name, read back, and belongs to one status") {
  using R = vmap::DecisionReason;
  for (R r : {R::no_candidates, R::below_bow_score, R::not_verified, R::too_few_inliers, R::not_yet_confirmed,
              R::empty_memory, R::no_query_features, R::camera_stayed, R::low_confidence, R::two_places,
              R::confident}) {
    CAPTURE(to_string(r));
    CHECK(to_string(r) != "unknown");
    CHECK(vmap::from_string<R>(to_string(r)) == r);
  }
  CHECK(vmap::status_of(R::not_verified) == PlaceStatus::too_little_evidence);
  CHECK(vmap::status_of(R::camera_stayed) == PlaceStatus::not_a_revisit);
  CHECK(vmap::status_of(R::low_confidence) == PlaceStatus::unknown_place);
  CHECK(vmap::status_of(R::two_places) == PlaceStatus::ambiguous);
  CHECK(vmap::status_of(R::confident) == PlaceStatus::accepted);
}

TEST_CASE("loop engine: LoopDetector and VisualMemory find the same loops over the same key images") {
  // The memory's key images of the sample frames; a LoopDetector over their features
  // with the memory's vocabulary and loop options gives the memory's loop edges.
  auto src = vmap::FrameSource::open(vmap::test::source_dir() / "examples/data/tum_fr1_rpy_60/rgb.txt", {.grey = true});
  vmap::MemoryOptions o;
  o.vocabulary_after = 3;
  o.vocabulary = {.branching = 8, .depth = 2, .seed = 5};
  o.loops.window = 2;
  vmap::OrbVisualMemory mem(vmap::OrbDescriptor{}, vmap::BruteForceMatcher{},
                            vmap::FundamentalEstimator({.check_degeneracy = false}), vmap::InlierRatio{}, o);
  while (auto f = src.next()) mem.push(*f);
  REQUIRE(mem.key_images() > 5);
  auto voc = std::make_shared<const vmap::AnyVocabulary>(mem.vocabulary());
  vmap::LoopOptions lo = o.loops;
  lo.index = vmap::CandidateIndex::bow;
  vmap::LoopDetector det(vmap::LabelSchema{}, vmap::OrbDescriptor{}, vmap::BruteForceMatcher{},
                         vmap::FundamentalEstimator({.check_degeneracy = false}), lo, vmap::PlaceRanker(voc));
  std::vector<std::pair<std::size_t, std::size_t>> detector_loops, memory_loops;
  for (std::size_t k = 0; k < mem.key_images(); ++k) {
    const auto r = det.add(mem.map().keys[k].features, {}, vmap::ViewStep::new_view);  // each key image a view
    if (r.loop()) detector_loops.emplace_back(k, *r.best);
  }
  for (const auto& e : mem.loops()) memory_loops.emplace_back(e.from, e.link.key);
  MESSAGE(mem.key_images() << " key images, " << memory_loops.size() << " loops");
  CHECK(detector_loops == memory_loops);
  CHECK(det.stationary() == mem.stationary());
}

TEST_CASE("place decision: with a calibrated camera, localize gives the query's pose relative to the key image") {
  // The memory's estimator fits an essential matrix (TUM fr1 intrinsics): the evidence
  // counts its 5-point minimal sample, and an accepted answer holds R and the unit t.
  const vmap::Camera camera =
      vmap::parse_camera(vmap::read_file(vmap::test::source_dir() / "examples/data/tum_fr1_camera.yaml", 1 << 20, "camera"),
                         "tum_fr1_camera.yaml");
  using EssentialMemory =
      vmap::VisualMemory<vmap::OrbDescriptor, vmap::BruteForceMatcher, vmap::EssentialEstimator, vmap::InlierRatio>;
  vmap::MemoryOptions o;
  o.vocabulary_after = 3;
  o.vocabulary = {.branching = 8, .depth = 2, .seed = 5};
  EssentialMemory mem(vmap::OrbDescriptor{}, vmap::BruteForceMatcher{}, vmap::EssentialEstimator(camera, {.seed = 3}),
                      vmap::InlierRatio{}, o);
  auto src = vmap::FrameSource::open(vmap::test::source_dir() / "examples/data/tum_fr1_rpy_60/rgb.txt", {.grey = true});
  std::vector<vmap::Frame> held;
  while (auto f = src.next()) {
    if (f->index % 10 == 5) held.push_back(*f);
    else mem.push(*f);
  }
  std::size_t accepted = 0;
  for (const auto& f : held) {
    const auto a = mem.localize(f.image);
    CHECK(a.evidence.model == vmap::PlaceModel::essential);
    if (!a.ok()) continue;
    ++accepted;
    REQUIRE(a.relative_pose.has_value());
    CHECK(cv::norm(a.relative_pose->translation) == doctest::Approx(1.0).epsilon(1e-6));
    const cv::Matx33d rtr = a.relative_pose->rotation.t() * a.relative_pose->rotation;
    CHECK(cv::norm(rtr - cv::Matx33d::eye()) < 1e-6);
    // (A camera that mostly turns, as here, triangulates few points in front: no floor.)
    CHECK(a.relative_pose->points_in_front >= 0);
    CHECK(a.relative_pose->points_in_front <= a.evidence.inliers);
  }
  CHECK(accepted * 2 >= held.size());
  // Without a camera there is no relative pose.
  vmap::OrbVisualMemory plain;
  for (std::size_t i = 0; i < 4; ++i) plain.push(held[i].image);
  CHECK_FALSE(plain.localize(held[0].image).relative_pose.has_value());
}

TEST_SUITE("data") {
  TEST_CASE("place decision: a memory of rtabmap_loop knows its own frames and refuses other places") {
    const auto rt = vmap::test::grey_frames(vmap::test::data_path("rtabmap_loop/images"));
    vmap::OrbVisualMemory mem;
    for (const auto& f : rt) mem.push(f);
    std::size_t foreign = 0, accepted = 0;
    for (const char* other : {"kitti07_160/image_0", "tum_fr3_cabinet_kf/rgb.txt"}) {
      for (const auto& f : vmap::test::grey_frames(vmap::test::data_path(other), 5)) {
        const auto a = mem.localize(f.image);
        ++foreign;
        if (a.ok()) MESSAGE(other << " frame " << f.index << " accepted: " << a.reason);
        accepted += a.ok() ? 1 : 0;
        CHECK(a.status != PlaceStatus::accepted);
        CHECK(!a.reason.empty());
      }
    }
    CHECK(foreign >= 40);
    CHECK(accepted == 0);
    // Its own frames: every 7th localizes to a key image within 5 frames or to the
    // other traverse's view of the place (the ground truth's loop frames, 3 frames
    // tolerance).
    const auto gt = vmap::LoopGroundTruth::load(vmap::test::data_path("rtabmap_loop/gt_loop_matrix_84x84.txt"), 84);
    std::size_t own = 0, right = 0;
    for (std::size_t i = 3; i < rt.size(); i += 7) {
      const auto a = mem.localize(rt[i].image);
      ++own;
      if (!a.ok()) continue;
      const std::size_t k = mem.map().keys[a.best()->key].frame_index;
      bool ok = (k > i ? k - i : i - k) <= 5;
      for (std::size_t d = k > 3 ? k - 3 : 0; d <= k + 3 && d < 84; ++d) ok = ok || gt(i, d) || gt(d, i);
      right += ok ? 1 : 0;
      CHECK(ok);
    }
    CHECK(right * 10 >= own * 8);
  }

  TEST_CASE("revisit rule: a forward traverse is never stationary, whatever the vocabulary") {
    // kitti07_160: a car driving forward. The chain of views changes whatever the bags of
    // words say: a vocabulary learned on the sequence, or the three imported ones (learned
    // on TUM frames, indoor).
    auto src = vmap::FrameSource::open(vmap::test::data_path("kitti07_160/image_0"), {.grey = true});
    vmap::OrbDescriptor orb;
    std::vector<vmap::Features> frames;
    std::vector<cv::Mat> sets;
    while (auto f = src.next()) {
      frames.push_back(orb.extract(f->image));
      sets.push_back(frames.back().descriptors);
    }
    REQUIRE(frames.size() == 160);
    std::vector<std::pair<std::string, vmap::AnyVocabulary>> vocabularies;
    vocabularies.emplace_back("learned", vmap::AnyVocabulary::learn(sets, {.branching = 10, .depth = 3, .seed = 1}));
    for (const char* name : {"orbslam2_k10L3.txt", "dbow2_k10L3.yml.gz", "fbow_k10L3.fbow"})
      vocabularies.emplace_back(name, vmap::AnyVocabulary::load(vmap::test::data_path(std::string("vocabularies/") + name)));
    for (auto& [name, voc] : vocabularies) {
      CAPTURE(name);
      vmap::LoopDetector det(vmap::LabelSchema{}, vmap::OrbDescriptor{}, vmap::BruteForceMatcher{},
                             vmap::FundamentalEstimator({.check_degeneracy = false}),
                             {.index = vmap::CandidateIndex::bow},
                             vmap::PlaceRanker(std::make_shared<const vmap::AnyVocabulary>(std::move(voc))));
      std::size_t loops = 0, not_revisit = 0;
      for (const auto& f : frames) {
        const auto r = det.add(f, {});
        loops += r.loop() ? 1 : 0;
        not_revisit += r.status == PlaceStatus::not_a_revisit ? 1 : 0;
      }
      MESSAGE(name << ": " << det.engine().view_of(159) + 1 << " views, " << loops << " loops, " << not_revisit
                   << " not a revisit");
      CHECK_FALSE(det.stationary());
      CHECK(det.engine().view_of(159) >= 20);
      CHECK(loops == 0);  // the car never comes back (the ground truth has no loop)
    }
  }

  TEST_CASE("revisit rule: the sample frames, then the same frames reversed, close loops into the first half") {
    std::vector<cv::Mat> images;
    auto src = vmap::FrameSource::open(vmap::test::source_dir() / "examples/data/tum_fr1_rpy_60/rgb.txt", {.grey = true});
    while (auto f = src.next()) images.push_back(f->image);
    REQUIRE(images.size() == 60);
    vmap::OrbVisualMemory mem;
    for (const auto& im : images) mem.push(im);
    const std::size_t first_half = mem.key_images();
    for (std::size_t i = images.size(); i-- > 0;) mem.push(images[i]);
    MESSAGE(first_half << " key images forward, " << mem.key_images() << " in all, " << mem.loops().size() << " loops");
    CHECK_FALSE(mem.stationary());
    std::size_t into_first = 0;
    for (const auto& e : mem.loops()) into_first += e.from >= first_half && e.link.key < first_half ? 1 : 0;
    CHECK(into_first >= 3);
  }

  TEST_CASE("revisit rule: a real frame repeated with sensor noise and sub-pixel jitter closes no loop") {
    const cv::Mat base = cv::imread(vmap::test::data_path("rtabmap_loop/images/1.jpg").string(), cv::IMREAD_GRAYSCALE);
    REQUIRE_FALSE(base.empty());
    std::mt19937_64 rng(11);
    std::uniform_real_distribution<double> jitter(-0.5, 0.5);
    vmap::OrbDescriptor orb;
    std::vector<vmap::Features> frames;
    std::vector<cv::Mat> sets;
    for (int i = 0; i < 40; ++i) {
      cv::Mat moved, noise(base.size(), CV_16SC1), wide;
      cv::warpAffine(base, moved, cv::Matx23d(1, 0, jitter(rng), 0, 1, jitter(rng)), base.size(), cv::INTER_LINEAR,
                     cv::BORDER_REFLECT);
      cv::RNG(static_cast<std::uint64_t>(1000 + i)).fill(noise, cv::RNG::NORMAL, 0, 2.0);
      moved.convertTo(wide, CV_16SC1);
      wide += noise;
      wide.convertTo(moved, CV_8UC1);
      frames.push_back(orb.extract(moved));
      sets.push_back(frames.back().descriptors);
    }
    auto voc = std::make_shared<const vmap::AnyVocabulary>(
        vmap::AnyVocabulary::learn(sets, {.branching = 10, .depth = 3, .seed = 1}));
    vmap::LoopDetector det(vmap::LabelSchema{}, vmap::OrbDescriptor{}, vmap::BruteForceMatcher{},
                           vmap::FundamentalEstimator({.check_degeneracy = false}),
                           {.index = vmap::CandidateIndex::bow}, vmap::PlaceRanker(voc));
    std::size_t loops = 0, not_revisit = 0;
    for (const auto& f : frames) {
      const auto r = det.add(f, {});
      loops += r.loop() ? 1 : 0;
      not_revisit += r.status == PlaceStatus::not_a_revisit ? 1 : 0;
    }
    CHECK(loops == 0);
    CHECK(not_revisit >= 25);
    CHECK(det.stationary());
  }
}
