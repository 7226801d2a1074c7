// Estimators on synthetic scenes with known geometry, and their failure values.
#include <vmap/geometry/fundamental.hpp>
#include <vmap/geometry/homography.hpp>
#include <vmap/geometry/similarity.hpp>

#include "support/synthetic.hpp"

#include <doctest/doctest.h>

#include <limits>

namespace {

int recovered_true_inliers(const vmap::test::TwoViewScene& s, const vmap::Verification& v) {
  int n = 0;
  for (std::size_t i = 0; i < s.matches.size(); ++i) n += (s.is_inlier[i] && v.inlier_mask[i]) ? 1 : 0;
  return n;
}

int true_inliers(const vmap::test::TwoViewScene& s) {
  int n = 0;
  for (auto b : s.is_inlier) n += b;
  return n;
}

}  // namespace

TEST_CASE("robust fundamental-matrix methods on a general scene with 30% outliers") {
  // 0.2 px noise per coordinate: sub-pixel keypoints. Plain RANSAC and LMedS keep their
  // best minimal-sample model without refitting, so their accuracy depends on it.
  const auto scene = vmap::test::make_two_view_scene({.points = 400, .outlier_fraction = 0.3, .noise_px = 0.2});
  for (const auto method : {vmap::RobustMethod::magsac, vmap::RobustMethod::ransac, vmap::RobustMethod::lmeds}) {
    CAPTURE(static_cast<int>(method));
    const vmap::FundamentalEstimator est({.method = method});
    const vmap::Verification v = est.verify(scene.a, scene.b, scene.matches);
    REQUIRE(v.ok());
    CHECK(v.matches == 400);
    CHECK(v.inlier_mask.size() == 400);
    CHECK(v.inliers == std::count(v.inlier_mask.begin(), v.inlier_mask.end(), 1));
    CHECK(vmap::test::mean_epipolar_error(scene, v.model) < 0.5);
    CHECK(recovered_true_inliers(scene, v) >= 0.9 * true_inliers(scene));
    // Outliers are random pixel pairs; a few fall near an epipolar line by chance.
    CHECK(v.inliers - recovered_true_inliers(scene, v) < 0.1 * 120);
    CHECK(v.degeneracy == vmap::Degeneracy::none);
  }
}

TEST_CASE("the 8-point method is exact on outlier-free data") {
  const auto scene = vmap::test::make_two_view_scene({.points = 200, .outlier_fraction = 0.0, .noise_px = 0.0});
  const vmap::FundamentalEstimator est({.method = vmap::RobustMethod::eight_point});
  const auto v = est.verify(scene.a, scene.b, scene.matches);
  REQUIRE(v.ok());
  CHECK(v.inliers == 200);  // no robust step: every match counts
  CHECK(vmap::test::mean_epipolar_error(scene, v.model) < 0.01);
  // F is defined up to scale: compare normalised matrices (sign fixed by the largest entry).
  auto normalised = [](cv::Matx33d F) {
    double big = 0;
    for (int i = 0; i < 9; ++i)
      if (std::abs(F.val[i]) > std::abs(big)) big = F.val[i];
    return F * (1.0 / big);
  };
  CHECK(cv::norm(normalised(v.model) - normalised(scene.F_true)) < 1e-4);
}

TEST_CASE("a planar scene and a pure rotation are reported as degenerate") {
  for (const auto kind : {vmap::test::SceneKind::planar, vmap::test::SceneKind::pure_rotation}) {
    CAPTURE(static_cast<int>(kind));
    const auto scene = vmap::test::make_two_view_scene({.outlier_fraction = 0.2, .kind = kind});
    const vmap::FundamentalEstimator est;
    const auto v = est.verify(scene.a, scene.b, scene.matches);
    REQUIRE(v.ok());  // an F fits (a family of them does); the caller must know it is not unique
    CHECK(v.degeneracy == vmap::Degeneracy::homography);
    CHECK(v.homography_inliers >= 0.9 * v.inliers);
    const vmap::HomographyEstimator hest;
    const auto h = hest.verify(scene.a, scene.b, scene.matches);
    REQUIRE(h.ok());
    CHECK(recovered_true_inliers(scene, h) >= 0.95 * true_inliers(scene));
  }
  SUBCASE("and the check can be switched off") {
    const auto scene = vmap::test::make_two_view_scene({.kind = vmap::test::SceneKind::planar});
    const auto v = vmap::FundamentalEstimator({.check_degeneracy = false}).verify(scene.a, scene.b, scene.matches);
    CHECK(v.degeneracy == vmap::Degeneracy::none);
    CHECK(v.homography_inliers == 0);
  }
}

TEST_CASE("a general scene is not degenerate for the homography test") {
  const auto scene = vmap::test::make_two_view_scene({.outlier_fraction = 0.0});
  const auto v = vmap::FundamentalEstimator{}.verify(scene.a, scene.b, scene.matches);
  REQUIRE(v.ok());
  CHECK(v.degeneracy == vmap::Degeneracy::none);
  CHECK(v.homography_inliers < 0.9 * v.inliers);
}

TEST_CASE("seeded estimation is reproducible") {
  const auto scene = vmap::test::make_two_view_scene({.outlier_fraction = 0.4, .noise_px = 0.2, .seed = 9});
  for (const auto method : {vmap::RobustMethod::magsac, vmap::RobustMethod::ransac}) {
    for (const std::uint64_t seed : {0ull, 17ull}) {
      const vmap::FundamentalEstimator est({.method = method, .seed = seed});
      const auto v1 = est.verify(scene.a, scene.b, scene.matches);
      const auto v2 = est.verify(scene.a, scene.b, scene.matches);
      CHECK(v1.inlier_mask == v2.inlier_mask);
      CHECK(cv::norm(v1.model - v2.model) == 0.0);
      CHECK(recovered_true_inliers(scene, v1) >= 0.9 * true_inliers(scene));
    }
  }
}

TEST_CASE("too few matches and unusable points are values, never exceptions") {
  const auto scene = vmap::test::make_two_view_scene({.points = 50, .outlier_fraction = 0.0});
  const vmap::FundamentalEstimator est;
  for (std::size_t n : {0u, 1u, 6u, 7u}) {
    CAPTURE(n);
    const vmap::Matches few(scene.matches.begin(), scene.matches.begin() + static_cast<long>(n));
    const auto v = est.verify(scene.a, scene.b, few);
    CHECK(v.status == vmap::VerificationStatus::too_few_matches);
    CHECK(v.matches == static_cast<int>(n));
    CHECK(v.inliers == 0);
    CHECK_FALSE(v.ok());
  }
  SUBCASE("exactly eight matches is enough for every method") {
    const vmap::Matches eight(scene.matches.begin(), scene.matches.begin() + 8);
    for (const auto method : {vmap::RobustMethod::magsac, vmap::RobustMethod::ransac, vmap::RobustMethod::lmeds,
                              vmap::RobustMethod::eight_point}) {
      const auto v = vmap::FundamentalEstimator({.method = method, .min_inliers = 0}).verify(scene.a, scene.b, eight);
      CAPTURE(static_cast<int>(method));
      CHECK(v.status != vmap::VerificationStatus::too_few_matches);
      CHECK(v.inlier_mask.size() == (v.status == vmap::VerificationStatus::no_model ? 0u : 8u));
    }
  }
  SUBCASE("identical points") {
    vmap::Features same;
    same.keypoints.assign(30, cv::KeyPoint(cv::Point2f(100.f, 100.f), 5.f));
    vmap::Matches m;
    for (int i = 0; i < 30; ++i) m.emplace_back(i, i, 0.f);
    for (const auto method : {vmap::RobustMethod::magsac, vmap::RobustMethod::ransac, vmap::RobustMethod::lmeds,
                              vmap::RobustMethod::eight_point}) {
      CAPTURE(static_cast<int>(method));
      const auto v = vmap::FundamentalEstimator({.method = method}).verify(same, same, m);
      CHECK_FALSE(v.ok());
      CHECK((v.status == vmap::VerificationStatus::no_model || v.status == vmap::VerificationStatus::too_few_inliers));
    }
    const auto h = vmap::HomographyEstimator{}.verify(same, same, m);
    CHECK_FALSE(h.ok());
  }
  SUBCASE("a minimum-inlier floor turns a weak model into too_few_inliers") {
    const auto v = vmap::FundamentalEstimator({.min_inliers = 1000}).verify(scene.a, scene.b, scene.matches);
    CHECK(v.status == vmap::VerificationStatus::too_few_inliers);
    CHECK(v.inliers > 40);  // the count is still reported
  }
}

TEST_CASE("estimator options and inputs are validated") {
  const double nan = std::numeric_limits<double>::quiet_NaN();
  CHECK_THROWS_WITH_AS(vmap::FundamentalEstimator({.threshold_px = nan}), doctest::Contains("threshold_px"), vmap::Error);
  CHECK_THROWS_WITH_AS(vmap::FundamentalEstimator({.threshold_px = 0}), doctest::Contains("threshold_px"), vmap::Error);
  CHECK_THROWS_WITH_AS(vmap::FundamentalEstimator({.confidence = 1.0}), doctest::Contains("confidence"), vmap::Error);
  CHECK_THROWS_WITH_AS(vmap::FundamentalEstimator({.confidence = nan}), doctest::Contains("confidence"), vmap::Error);
  CHECK_THROWS_WITH_AS(vmap::FundamentalEstimator({.max_iterations = 0}), doctest::Contains("max_iterations"), vmap::Error);
  CHECK_THROWS_WITH_AS(vmap::FundamentalEstimator({.min_inliers = -1}), doctest::Contains("min_inliers"), vmap::Error);
  CHECK_THROWS_WITH_AS(vmap::FundamentalEstimator({.degeneracy_ratio = nan}), doctest::Contains("degeneracy_ratio"),
                       vmap::Error);
  CHECK_THROWS_WITH_AS(vmap::HomographyEstimator({.method = vmap::RobustMethod::eight_point}),
                       doctest::Contains("eight_point"), vmap::Error);
  const auto scene = vmap::test::make_two_view_scene({.points = 20});
  vmap::Matches bad = scene.matches;
  bad[3].trainIdx = 999;
  CHECK_THROWS_WITH_AS((void)vmap::FundamentalEstimator{}.verify(scene.a, scene.b, bad), doctest::Contains("outside"),
                       vmap::Error);
}

TEST_CASE("homography estimator recovers a known homography") {
  const cv::Matx33d H(1.05, 0.02, 12, -0.01, 0.98, -7, 1e-5, 2e-5, 1);
  cv::RNG rng(4);
  vmap::Features a, b;
  vmap::Matches m;
  for (int i = 0; i < 200; ++i) {
    const cv::Point2f p(rng.uniform(0.f, 640.f), rng.uniform(0.f, 480.f));
    cv::Point2f q;
    if (i < 150) {
      const cv::Vec3d x = H * cv::Vec3d(p.x, p.y, 1);
      q = cv::Point2f(static_cast<float>(x[0] / x[2]), static_cast<float>(x[1] / x[2]));
    } else {
      q = cv::Point2f(rng.uniform(0.f, 640.f), rng.uniform(0.f, 480.f));
    }
    a.keypoints.emplace_back(p, 5.f);
    b.keypoints.emplace_back(q, 5.f);
    m.emplace_back(i, i, 0.f);
  }
  for (const auto method : {vmap::RobustMethod::magsac, vmap::RobustMethod::ransac, vmap::RobustMethod::lmeds}) {
    CAPTURE(static_cast<int>(method));
    const auto v = vmap::HomographyEstimator({.method = method}).verify(a, b, m);
    REQUIRE(v.ok());
    CHECK(v.inliers >= 150);
    CHECK(v.inliers <= 155);
    const cv::Matx33d Hn = v.model * (1.0 / v.model(2, 2));
    CHECK(cv::norm(Hn - H) < 1e-3 * cv::norm(H));
  }
}

TEST_CASE("InlierRatio is eq. 5 and its raw-match form bounds it") {
  vmap::Features a, b;
  a.keypoints.resize(400);
  b.keypoints.resize(250);
  vmap::Verification v;
  v.status = vmap::VerificationStatus::verified;
  v.inliers = 100;
  CHECK(vmap::InlierRatio{}(a, b, v) == doctest::Approx(100.0 / 400.0));
  CHECK(vmap::InlierRatioMin{}(a, b, v) == doctest::Approx(100.0 / 250.0));
  CHECK(vmap::InlierRatio{}.upper_bound(a, b, 180) == doctest::Approx(180.0 / 400.0));
  CHECK(vmap::InlierRatioMin{}.upper_bound(a, b, 180) == doctest::Approx(180.0 / 250.0));
  v.status = vmap::VerificationStatus::too_few_inliers;
  CHECK(vmap::InlierRatio{}(a, b, v) == 0.0);  // a failed verification verifies no match
  CHECK(vmap::InlierRatioMin{}(a, b, v) == 0.0);
  const vmap::Features none;
  CHECK(vmap::InlierRatio{}(none, none, v) == 0.0);
  CHECK(vmap::InlierRatio{}.upper_bound(none, none, 0) == 0.0);
}
