#include <vmap/features/orb.hpp>
#include <vmap/geometry/fundamental.hpp>
#include <vmap/hooks/callback_detector.hpp>
#include <vmap/hooks/precomputed_detections.hpp>
#include <vmap/lcd/evaluation.hpp>
#include <vmap/lcd/influence.hpp>
#include <vmap/lcd/loop_detector.hpp>
#include <vmap/matching/brute_force.hpp>

#include "support/shared_data.hpp"

#include <doctest/doctest.h>

#include <opencv2/imgcodecs.hpp>
#include <opencv2/imgproc.hpp>

#include <functional>
#include <limits>
#include <string>
#include <vector>

using vmap::Detection;
using vmap::LoopStatus;

// Every member of the shipped stack compiles (an unconstrained member with a broken
// policy would otherwise compile silently until called).
template class vmap::LoopDetector<vmap::PrecomputedDetections, vmap::OrbDescriptor, vmap::BruteForceMatcher,
                                  vmap::FundamentalEstimator>;
template class vmap::LoopDetector<vmap::FunctionDetector, vmap::OrbDescriptor, vmap::BruteForceMatcher,
                                  vmap::FundamentalEstimator>;

namespace {

constexpr int places = 8;

// A textured "place": random filled shapes, distinct per seed.
cv::Mat place_image(int place) {
  cv::RNG rng(1000 + static_cast<std::uint64_t>(place));
  cv::Mat img(240, 320, CV_8U, cv::Scalar(rng.uniform(40, 200)));
  for (int k = 0; k < 70; ++k) {
    const cv::Point c(rng.uniform(0, 320), rng.uniform(0, 240));
    const cv::Scalar colour(rng.uniform(0, 256));
    if (k % 2 == 0)
      cv::circle(img, c, rng.uniform(4, 25), colour, cv::FILLED);
    else
      cv::rectangle(img, cv::Rect(c, cv::Size(rng.uniform(6, 40), rng.uniform(6, 40))), colour, cv::FILLED);
  }
  return img;
}

// Frame k of two laps: place k % places, seen from a slightly different position on the
// second lap (a shift and a small rotation).
cv::Mat lap_frame(int k) {
  const cv::Mat base = place_image(k % places);
  if (k < places) return base;
  const cv::Mat warp = cv::getRotationMatrix2D(cv::Point2f(160, 120), 4.0, 1.03);
  cv::Mat out;
  cv::warpAffine(base, out, warp, base.size(), cv::INTER_LINEAR, cv::BORDER_REFLECT);
  return out;
}

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

auto make_detector(vmap::CandidateIndex index) {
  vmap::FunctionDetector scripted([frame = 0](const cv::Mat&) mutable { return scripted_labels(frame++); });
  return vmap::LoopDetector(vmap::LabelSchema({10, 11, 12, 13}), std::move(scripted),
                            vmap::OrbDescriptor({.features = 500}), vmap::BruteForceMatcher{},
                            vmap::FundamentalEstimator({.seed = 7}),
                            {.window = 3, .min_candidates = 1, .min_inliers = 40, .index = index});
}

}  // namespace

TEST_CASE("loop detector: two laps with a scripted detector find exactly the known loops") {
  auto tree = make_detector(vmap::CandidateIndex::tree);
  auto brute = make_detector(vmap::CandidateIndex::brute_force);
  std::size_t brute_verifications = 0;
  for (int k = 0; k < 2 * places; ++k) {
    const cv::Mat img = lap_frame(k);
    const vmap::LoopResult r = tree.push(img);
    const vmap::LoopResult b = brute.push(img);
    CAPTURE(k);
    CAPTURE(r.inliers);
    CHECK(r.frame == static_cast<std::size_t>(k));
    brute_verifications += b.verifications;
    if (k <= 3) {  // nothing outside the window yet
      CHECK(r.status == LoopStatus::no_candidates);
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
      CHECK(r.status == LoopStatus::loop_found);
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

TEST_CASE("loop detector: bad options and inputs are an Error; status strings print") {
  CHECK_THROWS_AS(vmap::LoopDetector(vmap::LabelSchema({1}), vmap::PrecomputedDetections{}, vmap::OrbDescriptor{},
                                     vmap::BruteForceMatcher{}, vmap::FundamentalEstimator{}, {.min_inliers = -1}),
                  vmap::Error);
  CHECK_THROWS_AS(vmap::LoopDetector(vmap::LabelSchema({1}), vmap::PrecomputedDetections{}, vmap::OrbDescriptor{},
                                     vmap::BruteForceMatcher{}, vmap::FundamentalEstimator{},
                                     {.labels = {.min_score = 1.5f}}),
                  vmap::Error);
  auto d = vmap::LoopDetector(vmap::LabelSchema({1}), vmap::PrecomputedDetections{}, vmap::OrbDescriptor{},
                              vmap::BruteForceMatcher{}, vmap::FundamentalEstimator{});
  CHECK_THROWS_AS((void)d.push(cv::Mat(), {}), vmap::Error);
  CHECK_THROWS_AS((void)d.push(place_image(0), {{1, std::numeric_limits<float>::quiet_NaN(), cv::Rect2f()}}),
                  vmap::Error);
  CHECK(vmap::to_string(LoopStatus::below_threshold) == "candidates, too few inliers");
  CHECK(vmap::to_string(LoopStatus::loop_found) == "loop found");
}

TEST_SUITE("data") {
  TEST_CASE("loop detector: rtabmap_loop frame 41 closes a loop with frames 0..3") {
    // Frames 0..3 and 20 as the map, then frame 41 (images/42.jpg), whose ground-truth
    // row marks 0..3; brute-force index, window 0, so the test depends on the matching
    // and verification stack alone.
    const auto gt = vmap::LoopGroundTruth::load(vmap::test::data_path("rtabmap_loop/gt_loop_matrix_84x84.txt"), 84);
    const std::vector<std::size_t> frames = {0, 1, 2, 3, 20, 41};
    auto d = vmap::LoopDetector(vmap::LabelSchema{}, vmap::PrecomputedDetections{}, vmap::OrbDescriptor{},
                                vmap::BruteForceMatcher{}, vmap::FundamentalEstimator({.seed = 1}),
                                {.window = 0, .index = vmap::CandidateIndex::brute_force});
    vmap::LoopResult last;
    for (std::size_t f : frames) {
      const cv::Mat img = cv::imread(vmap::test::data_path("rtabmap_loop/images/" + std::to_string(f + 1) + ".jpg").string(),
                                     cv::IMREAD_GRAYSCALE);
      REQUIRE_FALSE(img.empty());
      last = d.push(img, {});
    }
    CHECK(last.verifications == 5);
    CHECK(last.status == LoopStatus::loop_found);
    REQUIRE(last.best.has_value());
    CAPTURE(last.inliers);
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
