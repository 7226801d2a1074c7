#include <vmap/lcd/influence.hpp>
#include <vmap/lcd/label_vector.hpp>

#include <doctest/doctest.h>

#include <cmath>
#include <limits>
#include <vector>

using vmap::Detection;
using vmap::LabelVector;

namespace {
Detection det(int label, float score, float w = 10, float h = 10) { return {label, score, cv::Rect2f(0, 0, w, h)}; }
}  // namespace

TEST_CASE("labels: present labels keep score >= 0.5 (eq. 3)") {
  const std::vector<Detection> d = {det(56, 0.9f), det(0, 0.49f), det(2, 0.5f), det(56, 0.7f), det(9, 0.1f)};
  CHECK(vmap::present_labels(d, 0.5f) == std::vector<int>{2, 56});
  CHECK(vmap::present_labels(d, 0.0f) == std::vector<int>{0, 2, 9, 56});
  CHECK(vmap::present_labels({}, 0.5f).empty());
}

TEST_CASE("labels: vector in the schema's order (eq. 3-4)") {
  const vmap::LabelSchema schema({56, 0, 2, 60});
  const std::vector<Detection> d = {det(2, 0.8f), det(56, 0.6f), det(0, 0.3f), det(13, 0.99f)};
  CHECK(schema.vector(d) == LabelVector{1, 0, 1, 0});
  CHECK(schema.vector(d, {.min_score = 0.2f}) == LabelVector{1, 1, 1, 0});
  CHECK(schema.vector({}) == LabelVector{0, 0, 0, 0});
  CHECK(vmap::LabelSchema().vector(d).empty());
}

TEST_CASE("labels: NaN or out-of-range scores and bad schemas are an Error") {
  const vmap::LabelSchema schema({1});
  const float nan = std::numeric_limits<float>::quiet_NaN();
  CHECK_THROWS_AS((void)schema.vector({det(1, nan)}), vmap::Error);
  CHECK_THROWS_AS((void)schema.vector({det(1, 1.5f)}), vmap::Error);
  CHECK_THROWS_AS((void)schema.vector({det(1, -0.1f)}), vmap::Error);
  CHECK_THROWS_AS((void)schema.vector({det(1, 0.9f)}, {.min_score = 2.0f}), vmap::Error);
  CHECK_THROWS_AS(vmap::LabelSchema({3, 1, 3}), vmap::Error);
  CHECK_THROWS_AS(vmap::LabelSchema({-1}), vmap::Error);
  vmap::LabelStatistics stats;
  CHECK_THROWS_AS(stats.observe({det(1, nan)}), vmap::Error);
}

TEST_CASE("labels: statistics order labels large to small by mean box area") {
  vmap::LabelStatistics stats;
  stats.observe({det(0, 0.9f, 10, 10), det(56, 0.9f, 100, 50), det(2, 0.3f, 1000, 1000)});  // 2 below 0.5
  stats.observe({det(0, 0.9f, 30, 10), det(60, 0.8f, 20, 20)});
  stats.observe({});
  CHECK(stats.samples() == 3);
  CHECK(stats.presence(0) == 2);
  CHECK(stats.presence(2) == 0);
  CHECK(stats.mean_area(0) == doctest::Approx(200.0));
  CHECK(stats.mean_area(56) == doctest::Approx(5000.0));
  CHECK(stats.labels_by_area() == std::vector<int>{56, 60, 0});
}

TEST_CASE("influence: E(i) = p(i)/M and pruning to the band (eq. 5)") {
  // Ten vectors over four labels: label 0 everywhere, 1 in half, 2 once, 3 never.
  std::vector<LabelVector> sample(10, LabelVector{1, 0, 0, 0});
  for (int k = 0; k < 5; ++k) sample[static_cast<std::size_t>(k)][1] = 1;
  sample[7][2] = 1;
  const auto e = vmap::label_influence(sample);
  REQUIRE(e.size() == 4);
  CHECK(e[0] == 1.0);
  CHECK(e[1] == 0.5);
  CHECK(e[2] == doctest::Approx(0.1));
  CHECK(e[3] == 0.0);
  CHECK(vmap::kept_levels(e) == std::vector<std::size_t>{1, 2});  // defaults [0.05, 0.95]
  CHECK(vmap::kept_levels(e, {.min_influence = 0.2, .max_influence = 0.9}) == std::vector<std::size_t>{1});
  CHECK(vmap::kept_levels(e, {.min_influence = 0.0, .max_influence = 1.0}) ==
        std::vector<std::size_t>{0, 1, 2, 3});
  CHECK(vmap::label_influence({}).empty());
  CHECK_THROWS_AS((void)vmap::label_influence({{1, 0}, {1}}), vmap::Error);
  CHECK_THROWS_AS((void)vmap::label_influence({{1, 2}}), vmap::Error);
  CHECK_THROWS_AS((void)vmap::kept_levels(e, {.min_influence = 0.6, .max_influence = 0.5}), vmap::Error);
}

TEST_CASE("influence: the schema from a sample, user order first, pruned") {
  vmap::LabelStatistics stats;
  // 20 frames: label 0 (person, small) in all, 56 (chair, large) in 10, 60 (table,
  // larger) in 4, 13 (bench) in 1.
  for (int k = 0; k < 20; ++k) {
    std::vector<Detection> d = {det(0, 0.9f, 10, 20)};
    if (k % 2 == 0) d.push_back(det(56, 0.8f, 50, 50));
    if (k % 5 == 0) d.push_back(det(60, 0.8f, 100, 60));
    if (k == 3) d.push_back(det(13, 0.8f, 5, 5));
    stats.observe(d);
  }
  std::vector<vmap::LabelInfluence> report;
  const auto schema = vmap::make_label_schema(stats, {}, {}, &report);
  CHECK(schema.labels() == std::vector<int>{60, 56, 13});  // 0 is everywhere (E = 1 > 0.95)
  REQUIRE(report.size() == 4);
  CHECK(report[0].label == 60);
  CHECK(report[0].influence == doctest::Approx(0.2));
  CHECK(report[2].label == 0);  // order by area: 60, 56, 0, 13
  CHECK(report[2].influence == 1.0);
  CHECK_FALSE(report[2].kept);
  CHECK(report[3].label == 13);
  CHECK(report[3].kept);
  // E(13) = 0.05 is at the band's floor; raising it drops the one-off label.
  CHECK(vmap::make_label_schema(stats, {.min_influence = 0.1, .max_influence = 0.95}).labels() ==
        std::vector<int>{60, 56});
  // A user order overrides the areas for the labels it names.
  CHECK(vmap::make_label_schema(stats, {}, {56}).labels() == std::vector<int>{56, 60, 13});
}
