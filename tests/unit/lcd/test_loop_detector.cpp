#include <vmap/features/orb.hpp>
#include <vmap/geometry/fundamental.hpp>
#include <vmap/hooks/callback_detector.hpp>
#include <vmap/hooks/precomputed_detections.hpp>
#include <vmap/lcd/evaluation.hpp>
#include <vmap/lcd/influence.hpp>
#include <vmap/lcd/loop_detector.hpp>
#include <vmap/matching/brute_force.hpp>

#include "support/scripted_ranker.hpp"
#include "support/two_laps.hpp"
#include "support/shared_data.hpp"

#include <doctest/doctest.h>

#include <opencv2/imgcodecs.hpp>
#include <opencv2/imgproc.hpp>

#include <algorithm>
#include <functional>
#include <limits>
#include <string>
#include <vector>

using vmap::Detection;
using vmap::PlaceStatus;

namespace {

constexpr int places = 8;

cv::Mat place_image(int place) { return vmap::test::place_image(1000 + static_cast<std::uint64_t>(place)); }
cv::Mat lap_frame(int k) { return vmap::test::lap_frame(k, places, 1000); }

// The scripted detector: place p shows the labels of the bits of p + 1 among {10, 11, 12, 13},
// so every place has its own label vector.
std::vector<Detection> scripted_labels(int frame) {
  const int code = frame % places + 1;
  std::vector<Detection> d;
  for (int b = 0; b < 4; ++b)
    if (code & (1 << b)) d.push_back({10 + b, 0.9f, cv::Rect2f(0, 0, 100.0f - 10.0f * b, 50)});
  d.push_back({20, 0.3f, cv::Rect2f(0, 0, 5, 5)});  // below the score threshold: ignored
  return d;
}

using vmap::test::ScriptedRanker;

// Scores the same place 1 and other places 0.1 (the first lap's frame k - places).
double place_score(std::size_t a, std::size_t b) { return a % places == b % places ? 1.0 : 0.1; }

using TestDetector =
    vmap::LoopDetector<vmap::OrbDescriptor, vmap::BruteForceMatcher, vmap::FundamentalEstimator, ScriptedRanker>;

TestDetector make_detector(vmap::CandidateIndex index, ScriptedRanker ranker = {}, std::size_t top_k = 3) {
  return TestDetector(vmap::LabelSchema({10, 11, 12, 13}), vmap::OrbDescriptor({.features = 500}),
                      vmap::BruteForceMatcher{}, vmap::FundamentalEstimator({.seed = 7}),
                      {.window = 3, .min_candidates = 1, .index = index, .top_k = top_k, .decision = {.min_inliers = 40}},
                      std::move(ranker));
}

}  // namespace

TEST_CASE("loop detector: two laps with a scripted detector find exactly the known loops") {
  auto tree = make_detector(vmap::CandidateIndex::tree);
  auto brute = make_detector(vmap::CandidateIndex::brute_force);
  vmap::FunctionDetector scripted([frame = 0](const cv::Mat&) mutable { return scripted_labels(frame++); });
  std::size_t brute_verifications = 0;
  for (int k = 0; k < 2 * places; ++k) {
    const cv::Mat img = lap_frame(k);
    const vmap::LoopResult r = tree.push(img, scripted);
    const vmap::LoopResult b = brute.push(img, scripted_labels(k));
    CAPTURE(k);
    CAPTURE(r.evidence.inliers);
    CHECK(r.frame == static_cast<std::size_t>(k));
    brute_verifications += b.verifications;
    if (k <= 3) {  // nothing outside the window yet
      CHECK(r.status == PlaceStatus::too_little_evidence);
      CHECK(r.reason_code == vmap::DecisionReason::no_candidates);
      CHECK(r.candidates == 0);
      continue;
    }
    if (k < places) {
      // First lap: the tree backtracks to at least one older place, which is not this one.
      CHECK_FALSE(r.loop());
      CHECK(r.candidates >= 1);
      CHECK_FALSE(b.loop());
    } else {
      // Second lap: the leaf holds exactly the first visit of the place.
      CHECK(r.candidates == 1);
      CHECK(r.verifications == 1);
      CHECK(r.status == PlaceStatus::accepted);
      REQUIRE(r.best.has_value());
      CHECK(*r.best == static_cast<std::size_t>(k - places));
      CHECK(r.labels == tree.schema().vector(scripted_labels(k)));
      // Brute force finds the same loop with every older frame verified.
      CHECK(b.loop());
      CHECK(b.best == r.best);
      CHECK(b.candidates == static_cast<std::size_t>(k - 3));
    }
  }
  CHECK(tree.frames() == 2 * places);
  CHECK(tree.tree().size() == 2 * places - 4);  // frames older than the window
  CHECK(tree.verifications() * 3 < brute_verifications);
  CHECK(brute.verifications() == brute_verifications);
}

TEST_CASE("loop detector: tree_ranked and bow verify only the top k, and say where each candidate stopped") {
  // Two laps; the ranker scores the same place 1 and others 0.1.
  auto ranked = make_detector(vmap::CandidateIndex::tree_ranked, ScriptedRanker(place_score), 1);
  auto bow = make_detector(vmap::CandidateIndex::bow, ScriptedRanker(place_score), 2);
  for (int k = 0; k < 2 * places; ++k) {
    const cv::Mat img = lap_frame(k);
    const vmap::LoopResult t = ranked.push(img, scripted_labels(k));
    const vmap::LoopResult w = bow.push(img, scripted_labels(k));
    CAPTURE(k);
    if (k <= 3) {
      CHECK(t.status == PlaceStatus::too_little_evidence);
      CHECK(w.reason_code == vmap::DecisionReason::no_candidates);
      CHECK(w.verifications == 0);
      continue;
    }
    // bow: every indexed frame is a candidate, two verified.
    CHECK(w.candidates == static_cast<std::size_t>(k - 3));
    CHECK(w.verifications == std::min<std::size_t>(2, w.candidates));
    CHECK(w.not_in_top_k == w.candidates - w.verifications);
    CHECK(w.considered.size() == w.verifications);
    // tree_ranked: the leaf (backtracked to m = 1), one verified.
    CHECK(t.verifications == 1);
    CHECK(t.not_in_top_k == t.candidates - 1);
    if (k >= places) {
      for (const vmap::LoopResult& r : {t, w}) {
        CHECK(r.status == PlaceStatus::accepted);
        REQUIRE(r.best.has_value());
        CHECK(*r.best == static_cast<std::size_t>(k - places));
        CHECK(r.evidence.bow_score == 1.0);
        CHECK(r.considered.front().frame == *r.best);  // the best-ranked comes first
        CHECK(r.considered.front().stage == vmap::CandidateStage::chosen);
      }
    } else {
      CHECK_FALSE(w.loop());
      CHECK_FALSE(t.loop());
    }
  }
  // The ranker holds every frame; the window only filters the candidates.
  CHECK(bow.ranker().indexed().size() == 2 * places);
  CHECK(bow.verifications() < 2 * 2 * places);
}

TEST_CASE("loop detector: a minimum bag-of-words score stops candidates before verification") {
  auto d = TestDetector(vmap::LabelSchema{}, vmap::OrbDescriptor({.features = 500}), vmap::BruteForceMatcher{},
                        vmap::FundamentalEstimator({.seed = 7}),
                        {.window = 3, .index = vmap::CandidateIndex::bow, .top_k = 2, .min_bow_score = 0.5,
                         .decision = {.min_inliers = 40}},
                        ScriptedRanker(place_score));
  for (int k = 0; k < 2 * places; ++k) {
    const vmap::LoopResult r = d.push(lap_frame(k), std::vector<Detection>{});
    CAPTURE(k);
    if (k <= 3) continue;
    if (k < places) {
      // Every older frame is another place (score 0.1): nothing is verified.
      CHECK(r.status == PlaceStatus::too_little_evidence);
      CHECK(r.reason_code == vmap::DecisionReason::below_bow_score);
      CHECK(r.verifications == 0);
      CHECK(r.below_bow_score == std::min<std::size_t>(2, r.candidates));
      for (const auto& c : r.considered) CHECK(c.stage == vmap::CandidateStage::below_bow_score);
    } else {
      CHECK(r.loop());
      CHECK(r.verifications == 1);  // the revisit; the second-ranked is below the floor
      CHECK(r.below_bow_score == 1);
    }
  }
  CHECK(vmap::to_string(vmap::CandidateStage::not_in_top_k) == "not in top k");
}

TEST_CASE("loop detector: temporal consistency holds a loop until k earlier frames agree on the place") {
  auto d = TestDetector(vmap::LabelSchema{}, vmap::OrbDescriptor({.features = 500}), vmap::BruteForceMatcher{},
                        vmap::FundamentalEstimator({.seed = 7}),
                        {.window = 3, .index = vmap::CandidateIndex::bow, .top_k = 1, .temporal_consistency = 2,
                         .temporal_tolerance = 1, .decision = {.min_inliers = 40}},
                        ScriptedRanker(place_score));
  for (int k = 0; k < 2 * places; ++k) {
    const vmap::LoopResult r = d.push(lap_frame(k), std::vector<Detection>{});
    CAPTURE(k);
    if (k < places) {
      CHECK_FALSE(r.loop());
      continue;
    }
    REQUIRE(r.best.has_value());
    CHECK(*r.best == static_cast<std::size_t>(k - places));
    // Every frame of the revisit extends the island; its first two frames have fewer
    // than two consistent predecessors.
    CHECK(r.consistent_queries == static_cast<std::size_t>(k - places));
    CHECK(r.status == (k - places >= 2 ? PlaceStatus::accepted : PlaceStatus::too_little_evidence));
    if (k - places < 2) CHECK(r.reason_code == vmap::DecisionReason::not_yet_confirmed);
  }
}

TEST_CASE("loop detector: pre-extracted features give the same results as the detector extracting them") {
  auto pushed = make_detector(vmap::CandidateIndex::tree_ranked, ScriptedRanker(place_score));
  auto added = make_detector(vmap::CandidateIndex::tree_ranked, ScriptedRanker(place_score));
  vmap::OrbDescriptor orb({.features = 500});
  for (int k = 0; k < 2 * places; ++k) {
    const cv::Mat img = lap_frame(k);
    const vmap::LoopResult a = pushed.push(img, scripted_labels(k));
    const vmap::LoopResult b = added.add(orb.extract(img), scripted_labels(k));
    CAPTURE(k);
    CHECK(a.status == b.status);
    CHECK(a.best == b.best);
    CHECK(a.evidence.inliers == b.evidence.inliers);
    CHECK(a.confidence == b.confidence);
    CHECK(a.candidates == b.candidates);
    CHECK(a.verifications == b.verifications);
    CHECK(a.labels == b.labels);
  }
  CHECK(pushed.memory_bytes() == added.memory_bytes());
  CHECK(added.memory_bytes() > 0);
}

TEST_CASE("loop detector: bad options and inputs are an Error; status strings print") {
  const auto make = [](const vmap::LoopDetectorOptions& o, ScriptedRanker r = {}) {
    return TestDetector(vmap::LabelSchema({1}), vmap::OrbDescriptor{}, vmap::BruteForceMatcher{},
                        vmap::FundamentalEstimator{}, o, std::move(r));
  };
  CHECK_THROWS_AS(make({.index = vmap::CandidateIndex::tree, .decision = {.min_inliers = -1}}), vmap::Error);
  CHECK_THROWS_AS(make({.index = vmap::CandidateIndex::tree, .decision = {.min_confidence = 1.5}}), vmap::Error);
  CHECK_THROWS_AS(make({.index = vmap::CandidateIndex::tree, .left_ratio = -0.1}), vmap::Error);
  CHECK_THROWS_AS(make({.labels = {.min_score = 1.5f}, .index = vmap::CandidateIndex::tree}), vmap::Error);
  CHECK_THROWS_AS(make({.index = vmap::CandidateIndex::tree, .min_bow_score = -1}), vmap::Error);
  // A ranked source without a vocabulary, or with top_k 0.
  CHECK_THROWS_WITH_AS(make({}), doctest::Contains("needs a vocabulary"), vmap::Error);
  CHECK_THROWS_AS(make({.index = vmap::CandidateIndex::bow}), vmap::Error);
  CHECK_THROWS_AS(make({.index = vmap::CandidateIndex::bow, .top_k = 0}, ScriptedRanker(place_score)), vmap::Error);
  auto d = make({.index = vmap::CandidateIndex::tree});
  CHECK_THROWS_AS((void)d.push(cv::Mat(), std::vector<Detection>{}), vmap::Error);
  CHECK_THROWS_AS((void)d.push(place_image(0), {{1, std::numeric_limits<float>::quiet_NaN(), cv::Rect2f()}}),
                  vmap::Error);

  CHECK(vmap::to_string(PlaceStatus::accepted) == "accepted");
  CHECK(vmap::to_string(vmap::CandidateIndex::tree_ranked) == "tree_ranked");
}

TEST_SUITE("data") {
  TEST_CASE("loop detector: rtabmap_loop frame 41 closes a loop with frames 0..3") {
    // Frames 0..3 and 20 as the map, then frame 41 (images/42.jpg), whose ground-truth
    // row marks 0..3; brute-force index, window 0, so the test depends on the matching
    // and verification stack alone.
    const auto gt = vmap::LoopGroundTruth::load(vmap::test::data_path("rtabmap_loop/gt_loop_matrix_84x84.txt"), 84);
    const std::vector<std::size_t> frames = {0, 1, 2, 3, 20, 41};
    auto d = TestDetector(vmap::LabelSchema{}, vmap::OrbDescriptor{}, vmap::BruteForceMatcher{},
                          vmap::FundamentalEstimator({.seed = 1}),
                          {.window = 0, .index = vmap::CandidateIndex::brute_force});
    vmap::LoopResult last;
    for (std::size_t f : frames) {
      const cv::Mat img = cv::imread(vmap::test::data_path("rtabmap_loop/images/" + std::to_string(f + 1) + ".jpg").string(),
                                     cv::IMREAD_GRAYSCALE);
      REQUIRE_FALSE(img.empty());
      last = d.push(img, std::vector<Detection>{});
    }
    CHECK(last.verifications == 5);
    CHECK(last.status == PlaceStatus::accepted);
    REQUIRE(last.best.has_value());
    CAPTURE(last.evidence.inliers);
    CHECK(gt(41, frames[*last.best]));
  }
}

TEST_SUITE("data") {
  TEST_CASE("loop detector: the tree over rtabmap_loop's YOLOX-nano labels") {
    // The labels file of examples/data (YOLOX-nano via `vmap detect`); its frames are
    // rtabmap_loop's images/(k+1).jpg. No image is read: this checks the label path.
    const auto gt = vmap::LoopGroundTruth::load(vmap::test::data_path("rtabmap_loop/gt_loop_matrix_84x84.txt"), 84);
    const auto labels =
        vmap::PrecomputedDetections::load(vmap::test::source_dir() / "examples/data/rtabmap_loop_yolox.txt");
    REQUIRE(labels.frames() == gt.frames());
    vmap::LabelStatistics stats;
    for (std::size_t k = 0; k < labels.frames(); ++k) stats.observe(labels.at(k));
    std::vector<vmap::LabelInfluence> report;
    const auto schema = vmap::make_label_schema(stats, {}, {}, &report);
    CHECK(schema.labels() == std::vector<int>{72});  // only "refrigerator" is in the eq. 5 band
    REQUIRE_FALSE(report.empty());
    CHECK(stats.presence(72) == 18);
    // Insert what LoopDetector would have indexed when frame 60 arrives (window 10).
    vmap::BinaryClassifiedTree<std::size_t> tree(schema.size());
    for (std::size_t j = 0; j + 10 < 60; ++j) tree.insert(schema.vector(labels.at(j)), j);
    const auto c = tree.candidates(schema.vector(labels.at(60)), 5);
    CHECK_FALSE(c.empty());
    for (std::size_t j : c) CHECK(schema.vector(labels.at(j)) == schema.vector(labels.at(60)));
  }
}
