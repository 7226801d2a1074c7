// Conformance suites for the Estimator and Similarity concepts: every model runs the
// same checks of the contract (examples/methods.md, sec. 5) on top of its own tests.
#include <vmap/geometry/fundamental.hpp>
#include <vmap/geometry/homography.hpp>
#include <vmap/geometry/similarity.hpp>

#include "support/synthetic.hpp"

#include <doctest/doctest.h>

TEST_CASE_TEMPLATE("Estimator conformance", E, vmap::FundamentalEstimator, vmap::HomographyEstimator) {
  const E estimator;
  SUBCASE("below the minimal sample: too_few_matches, nothing else set") {
    const auto scene = vmap::test::make_two_view_scene({.points = 10, .outlier_fraction = 0.0});
    const vmap::Matches three(scene.matches.begin(), scene.matches.begin() + 3);
    const auto v = estimator.verify(scene.a, scene.b, three);
    CHECK(v.status == vmap::VerificationStatus::too_few_matches);
    CHECK(v.matches == 3);
    CHECK(v.inliers == 0);
    CHECK(v.inlier_mask.empty());
    CHECK(cv::norm(v.model) == 0.0);
  }
  SUBCASE("a verified result is self-consistent and deterministic") {
    // A plane satisfies both models (F is then one of a family; H is exact).
    const auto scene = vmap::test::make_two_view_scene({.kind = vmap::test::SceneKind::planar, .seed = 3});
    const auto v = estimator.verify(scene.a, scene.b, scene.matches);
    REQUIRE(v.ok());
    CHECK(v.matches == static_cast<int>(scene.matches.size()));
    REQUIRE(v.inlier_mask.size() == scene.matches.size());
    CHECK(v.inliers == std::count(v.inlier_mask.begin(), v.inlier_mask.end(), 1));
    CHECK(v.inliers >= 0.9 * 280);
    const auto again = estimator.verify(scene.a, scene.b, scene.matches);
    CHECK(again.inlier_mask == v.inlier_mask);
    CHECK(cv::norm(again.model - v.model) == 0.0);
  }
  SUBCASE("empty features and no matches") {
    const vmap::Features none;
    const auto v = estimator.verify(none, none, {});
    CHECK(v.status == vmap::VerificationStatus::too_few_matches);
  }
}

TEST_CASE_TEMPLATE("Similarity conformance", S, vmap::InlierRatio, vmap::InlierRatioMin) {
  const S similarity;
  const auto scene = vmap::test::make_two_view_scene({.points = 300, .outlier_fraction = 0.3});
  auto b_fewer = scene.b;  // similarity must handle unequal feature counts
  b_fewer.keypoints.resize(250);
  vmap::Matches m;
  for (const auto& d : scene.matches)
    if (d.trainIdx < 250) m.push_back(d);
  const auto v = vmap::FundamentalEstimator{}.verify(scene.a, b_fewer, m);
  REQUIRE(v.ok());
  const double s = similarity(scene.a, b_fewer, v);
  CHECK(s > 0.0);
  CHECK(s <= 1.0);
  // The raw-match form is an upper bound (verification only removes matches).
  CHECK(similarity.upper_bound(scene.a, b_fewer, static_cast<int>(m.size())) >= s);
  // Symmetric in the two images.
  CHECK(similarity(b_fewer, scene.a, v) == s);
  // A failed verification scores 0.
  vmap::Verification failed = v;
  failed.status = vmap::VerificationStatus::too_few_inliers;
  CHECK(similarity(scene.a, b_fewer, failed) == 0.0);
}
