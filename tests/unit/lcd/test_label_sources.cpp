#include <vmap/core/error.hpp>
#include <vmap/lcd/evaluation.hpp>
#include <vmap/lcd/influence.hpp>
#include <vmap/lcd/label_sources.hpp>

#include "support/shared_data.hpp"

#include <doctest/doctest.h>

#include <cmath>
#include <string>
#include <vector>

using vmap::Detection;
using vmap::LabelVector;
using vmap::PrecomputedDetections;

TEST_CASE("label sources: the union of two detectors, frame by frame") {
  const auto a = PrecomputedDetections::parse("# frames 4\n0 72 0.9 0 0 10 10\n2 62 0.6 1 1 5 5\n");
  const auto b = PrecomputedDetections::parse("# frames 4\n2 72 0.4 2 2 8 8\n3 0 0.7 3 3 4 4\n");
  const auto u = vmap::merge_detections({a, b});
  CHECK(u.frames() == 4);
  CHECK(u.frames_declared());
  CHECK(u.detections() == 4);
  REQUIRE(u.at(0).size() == 1);
  CHECK(u.at(0)[0].label == 72);
  CHECK(u.at(1).empty());
  const auto f2 = u.at(2);  // source order: a's detection, then b's
  REQUIRE(f2.size() == 2);
  CHECK(f2[0].label == 62);
  CHECK(f2[0].score == 0.6f);
  CHECK(f2[1].label == 72);
  CHECK(f2[1].box == cv::Rect2f(2, 2, 8, 8));
  REQUIRE(u.at(3).size() == 1);
  CHECK(u.at(3)[0].label == 0);
  // eq. 3 on the union: a label is present when any source has it above the threshold.
  CHECK(vmap::present_labels(u.at(2), 0.5f) == std::vector<int>{62});
  CHECK(vmap::present_labels(u.at(2), 0.3f) == std::vector<int>{62, 72});

  // Without declared lengths the union spans to the last frame listed.
  const auto c = PrecomputedDetections::parse("5 1 0.5 0 0 1 1\n");
  const auto d = PrecomputedDetections::parse("1 2 0.5 0 0 1 1\n");
  CHECK(vmap::merge_detections({c, d}).frames() == 6);
  CHECK(vmap::merge_detections({}).frames() == 0);
  // One declared source fixes the length for the others.
  CHECK(vmap::merge_detections({d, a}).frames() == 4);
}

TEST_CASE("label sources: sources of different sequences are an Error") {
  const auto four = PrecomputedDetections::parse("# frames 4\n0 72 0.9 0 0 10 10\n");
  const auto five = PrecomputedDetections::parse("# frames 5\n0 72 0.9 0 0 10 10\n");
  const auto beyond = PrecomputedDetections::parse("6 72 0.9 0 0 10 10\n");  // lists frame 6
  CHECK_THROWS_AS((void)vmap::merge_detections({four, five}), vmap::Error);
  CHECK_THROWS_AS((void)vmap::merge_detections({four, beyond}), vmap::Error);
  CHECK_THROWS_AS((void)vmap::merge_detections({beyond, four}), vmap::Error);
}

TEST_CASE("label sources: agreement of label vectors with hand-made ground truth") {
  // Five frames, window 1: pairs (2,0) (3,0) (3,1) (4,0) (4,1) (4,2). Loops (2,0), (3,1),
  // (4,1), and (1,0), which lies inside the window and is never a pair.
  const std::vector<LabelVector> v = {{1, 0}, {0, 1}, {1, 0}, {1, 0}, {0, 1}};
  vmap::LoopGroundTruth gt(5);
  gt.set(2, 0, true);
  gt.set(3, 1, true);
  gt.set(4, 1, true);
  gt.set(1, 0, true);
  const auto a = vmap::label_vector_agreement(v, gt, 1);
  CHECK(a.distinct_vectors == 2);
  CHECK(a.pairs == 6);
  CHECK(a.leaf_pairs == 3);  // (2,0) (3,0) (4,1)
  CHECK(a.loop_queries == 3);
  CHECK(a.reachable_queries == 2);  // 3 sees its loop frame 1 only under another vector
  CHECK(a.loop_pairs == 3);
  CHECK(a.agreeing_loop_pairs == 2);
  CHECK(a.max_reduction() == doctest::Approx(2.0));

  // All vectors equal: the tree is brute force; all different: no pair is left.
  const auto same = vmap::label_vector_agreement(std::vector<LabelVector>(5, LabelVector{1}), gt, 1);
  CHECK(same.leaf_pairs == same.pairs);
  CHECK(same.reachable_queries == 3);
  const std::vector<LabelVector> all_differ = {{0, 0, 0}, {0, 0, 1}, {0, 1, 0}, {1, 0, 0}, {1, 1, 1}};
  const auto differ = vmap::label_vector_agreement(all_differ, gt, 1);
  CHECK(differ.leaf_pairs == 0);
  CHECK(differ.reachable_queries == 0);
  CHECK(std::isinf(differ.max_reduction()));

  CHECK_THROWS_AS((void)vmap::label_vector_agreement({{1, 0}, {1}}, vmap::LoopGroundTruth(2), 1), vmap::Error);
  CHECK_THROWS_AS((void)vmap::label_vector_agreement(v, vmap::LoopGroundTruth(4), 1), vmap::Error);
}

TEST_SUITE("data") {
  TEST_CASE("label sources: what three COCO detectors' labels allow the tree on rtabmap_loop") {
    // The labels files of examples/data (YOLOX-nano, NanoDet-m, FastestDet via `vmap
    // detect`, frame k = images/(k+1).jpg) against the 84x84 ground truth, window 10.
    const auto gt = vmap::LoopGroundTruth::load(vmap::test::data_path("rtabmap_loop/gt_loop_matrix_84x84.txt"), 84);
    const auto dir = vmap::test::source_dir() / "examples/data";
    const auto yolox = PrecomputedDetections::load(dir / "rtabmap_loop_yolox.txt");
    const auto nanodet = PrecomputedDetections::load(dir / "rtabmap_loop_nanodet.txt");
    const auto fastestdet = PrecomputedDetections::load(dir / "rtabmap_loop_fastestdet.txt");
    CHECK(nanodet.frames() == 84);
    CHECK(fastestdet.frames() == 84);
    auto agreement = [&](const PrecomputedDetections& labels, const vmap::InfluenceOptions& band) {
      vmap::LabelStatistics stats;
      for (std::size_t k = 0; k < labels.frames(); ++k) stats.observe(labels.at(k));
      const auto schema = vmap::make_label_schema(stats, band);
      std::vector<LabelVector> v;
      for (std::size_t k = 0; k < labels.frames(); ++k) v.push_back(schema.vector(labels.at(k)));
      return std::pair(schema.labels(), vmap::label_vector_agreement(v, gt, 10));
    };
    {
      // YOLOX-nano: one label (refrigerator), two leaves; every revisit is reachable.
      const auto [labels, a] = agreement(yolox, {});
      CHECK(labels == std::vector<int>{72});
      CHECK(a.distinct_vectors == 2);
      CHECK(a.pairs == 2701);
      CHECK(a.leaf_pairs == 1768);
      CHECK(a.loop_queries == 44);
      CHECK(a.reachable_queries == 44);
    }
    {
      // FastestDet: six labels, 17 vectors, but 12 of the 44 revisits change vector.
      const auto [labels, a] = agreement(fastestdet, {});
      CHECK(labels.size() == 6);
      CHECK(a.distinct_vectors == 17);
      CHECK(a.leaf_pairs == 536);
      CHECK(a.reachable_queries == 32);
      CHECK(a.agreeing_loop_pairs == 59);
    }
    {
      // FastestDet, band from 0.10: refrigerator, surfboard, tvmonitor.
      const auto [labels, a] = agreement(fastestdet, {.min_influence = 0.10});
      CHECK(labels == std::vector<int>{72, 37, 62});
      CHECK(a.distinct_vectors == 7);
      CHECK(a.leaf_pairs == 886);
      CHECK(a.reachable_queries == 39);
    }
    {
      // The union of the three: more vectors, fewer stable ones.
      const auto [labels, a] = agreement(vmap::merge_detections({yolox, nanodet, fastestdet}), {});
      CHECK(labels.size() == 7);
      CHECK(a.distinct_vectors == 23);
      CHECK(a.leaf_pairs == 493);
      CHECK(a.reachable_queries == 25);
    }
  }
}
