// Matcher conformance and exact results on hand-made descriptors.
#include <vmap/features/akaze.hpp>
#include <vmap/features/orb.hpp>
#include <vmap/features/sift.hpp>
#include <vmap/matching/brute_force.hpp>

#include "support/images.hpp"

#include <doctest/doctest.h>

#include <limits>
#include <set>

namespace {

/// Features with the given binary descriptor rows (one byte each, padded to 32 bytes).
vmap::Features binary_features(const std::vector<std::uint8_t>& first_bytes) {
  vmap::Features f;
  f.norm = cv::NORM_HAMMING;
  f.descriptors = cv::Mat::zeros(static_cast<int>(first_bytes.size()), 32, CV_8U);
  for (std::size_t i = 0; i < first_bytes.size(); ++i) {
    f.descriptors.at<std::uint8_t>(static_cast<int>(i), 0) = first_bytes[i];
    f.keypoints.emplace_back(cv::Point2f(static_cast<float>(i), 0.f), 1.f);
  }
  return f;
}

vmap::Features float_features(const std::vector<float>& values) {
  vmap::Features f;
  f.norm = cv::NORM_L2;
  f.descriptors = cv::Mat::zeros(static_cast<int>(values.size()), 4, CV_32F);
  for (std::size_t i = 0; i < values.size(); ++i) {
    f.descriptors.at<float>(static_cast<int>(i), 0) = values[i];
    f.keypoints.emplace_back(cv::Point2f(static_cast<float>(i), 0.f), 1.f);
  }
  return f;
}

}  // namespace

TEST_CASE("mutual nearest neighbours on hand-made binary descriptors") {
  // a: 0b0000'0000, 0b0000'1111, 0b1111'1111; b: 0b0000'0001, 0b1111'1110, 0b0011'1111
  // Hamming a->b: a0: {1, 7, 6} -> b0; a1: {3, 5, 2} -> b2; a2: {7, 1, 2} -> b1.
  // b->a: b0: {1, 3, 7} -> a0; b1: {7, 5, 1} -> a2; b2: {6, 2, 2} -> a1 (first of a tie).
  const auto a = binary_features({0x00, 0x0F, 0xFF});
  const auto b = binary_features({0x01, 0xFE, 0x3F});
  const vmap::Matches m = vmap::BruteForceMatcher{}.match(a, b);
  REQUIRE(m.size() == 3);
  CHECK(m[0].queryIdx == 0);
  CHECK(m[0].trainIdx == 0);
  CHECK(m[0].distance == 1.0f);
  CHECK(m[1].queryIdx == 1);
  CHECK(m[1].trainIdx == 2);
  CHECK(m[1].distance == 2.0f);
  CHECK(m[2].queryIdx == 2);
  CHECK(m[2].trainIdx == 1);
  CHECK(m[2].distance == 1.0f);
}

TEST_CASE("mutual mode drops one-sided matches") {
  // b0 is nearest for both a0 (d=0) and a1 (d=1) but prefers a0; b1's nearest is a1
  // (7 bits) while a1 prefers b0: only a0 <-> b0 is mutual.
  const auto a = binary_features({0x00, 0x01});
  const auto b = binary_features({0x00, 0xFF});
  const auto m = vmap::BruteForceMatcher{}.match(a, b);
  REQUIRE(m.size() == 1);
  CHECK(m[0].queryIdx == 0);
  CHECK(m[0].trainIdx == 0);
  CHECK(m[0].distance == 0.0f);
}

TEST_CASE("ratio test keeps only distinctive matches") {
  // L2 on one coordinate: a0 = 0 has b = {0.1, 5}: 0.1 < 0.8 * 5 -> kept;
  // a1 = 10 has b at distance 4.9 and 9.9... b = {0.1, 5}: d = {9.9, 5}: 5 < 0.8*9.9 -> kept (-> b1);
  // a2 = 2.55 has d = {2.45, 2.45}: a tie -> dropped.
  const auto a = float_features({0.0f, 10.0f, 2.55f});
  const auto b = float_features({0.1f, 5.0f});
  const vmap::BruteForceMatcher ratio({.mode = vmap::MatchMode::ratio, .ratio = 0.8f});
  const auto m = ratio.match(a, b);
  REQUIRE(m.size() == 2);
  CHECK(m[0].queryIdx == 0);
  CHECK(m[0].trainIdx == 0);
  CHECK(m[0].distance == doctest::Approx(0.1f));
  CHECK(m[1].queryIdx == 1);
  CHECK(m[1].trainIdx == 1);
  CHECK(m[1].distance == doctest::Approx(5.0f));
}

TEST_CASE_TEMPLATE("Matcher conformance on real descriptors", D, vmap::OrbDescriptor, vmap::SiftDescriptor) {
  D descriptor;
  const auto f = descriptor.extract(vmap::test::textured_image(3, {320, 240}));
  const auto g = descriptor.extract(vmap::test::textured_image(4, {320, 240}));
  for (const auto mode : {vmap::MatchMode::mutual, vmap::MatchMode::ratio}) {
    const vmap::BruteForceMatcher matcher({.mode = mode});
    CAPTURE(static_cast<int>(mode));
    SUBCASE("self-matching is the identity") {
      const auto m = matcher.match(f, f);
      REQUIRE(f.size() > 100);
      CHECK(m.size() >= f.size() * 95 / 100);  // exact duplicates of descriptors tie
      for (const auto& d : m) CHECK(d.distance == 0.0f);
    }
    SUBCASE("each query and each train index appears at most once in mutual mode") {
      const auto m = matcher.match(f, g);
      std::set<int> q, t;
      for (const auto& d : m) {
        q.insert(d.queryIdx);
        t.insert(d.trainIdx);
      }
      CHECK(q.size() == m.size());
      if (mode == vmap::MatchMode::mutual) CHECK(t.size() == m.size());
    }
    SUBCASE("empty inputs give empty matches") {
      const vmap::Features none;
      CHECK(matcher.match(none, f).empty());
      CHECK(matcher.match(f, none).empty());
      CHECK(matcher.match(none, none).empty());
    }
  }
}

TEST_CASE("mutual matches agree with an independent cross-check") {
  vmap::OrbDescriptor orb;
  const auto f = orb.extract(vmap::test::textured_image(5));
  cv::Mat shifted;
  cv::warpAffine(vmap::test::textured_image(5), shifted, cv::Matx23d(1, 0, 7, 0, 1, -4), cv::Size(640, 480));
  const auto g = orb.extract(shifted);
  const auto m = vmap::BruteForceMatcher{}.match(f, g);
  // Reference: nearest neighbours both ways by plain loops.
  auto nearest = [](const cv::Mat& from, const cv::Mat& to, int i) {
    int best = -1;
    double bd = std::numeric_limits<double>::max();
    for (int j = 0; j < to.rows; ++j) {
      const double d = cv::norm(from.row(i), to.row(j), cv::NORM_HAMMING);
      if (d < bd) {
        bd = d;
        best = j;
      }
    }
    return best;
  };
  std::size_t expected = 0;
  for (int i = 0; i < f.descriptors.rows; ++i) {
    const int j = nearest(f.descriptors, g.descriptors, i);
    if (nearest(g.descriptors, f.descriptors, j) == i) ++expected;
  }
  CHECK(m.size() == expected);
  CHECK(m.size() > 300);
}

TEST_CASE("matcher errors") {
  CHECK_THROWS_WITH_AS(vmap::BruteForceMatcher({.ratio = 0.0f}), doctest::Contains("ratio"), vmap::Error);
  CHECK_THROWS_WITH_AS(vmap::BruteForceMatcher({.ratio = std::numeric_limits<float>::quiet_NaN()}),
                       doctest::Contains("ratio"), vmap::Error);
  CHECK_THROWS_WITH_AS(vmap::BruteForceMatcher({.ratio = 1.5f}), doctest::Contains("ratio"), vmap::Error);
  const auto bin = binary_features({1, 2});
  const auto flt = float_features({1.f, 2.f});
  CHECK_THROWS_WITH_AS((void)vmap::BruteForceMatcher{}.match(bin, flt), doctest::Contains("differ in kind"),
                       vmap::Error);
  auto wrong_norm = bin;
  wrong_norm.norm = cv::NORM_L2;
  CHECK_THROWS_WITH_AS((void)vmap::BruteForceMatcher{}.match(wrong_norm, wrong_norm), doctest::Contains("norm"),
                       vmap::Error);
}

TEST_CASE_TEMPLATE("mutual Hamming matches are identical to OpenCV's BFMatcher cross-check", D, vmap::OrbDescriptor,
                   vmap::AkazeDescriptor) {
  D descriptor;  // ORB: 32-byte rows; A-KAZE: 61-byte rows (exercises the byte tail)
  const auto f = descriptor.extract(vmap::test::textured_image(21));
  cv::Mat warped;
  cv::warpAffine(vmap::test::textured_image(21), warped, cv::getRotationMatrix2D({320, 240}, 8.0, 1.05),
                 cv::Size(640, 480));
  const auto g = descriptor.extract(warped);
  std::vector<cv::DMatch> reference;
  cv::BFMatcher(cv::NORM_HAMMING, true).match(f.descriptors, g.descriptors, reference);
  const auto m = vmap::BruteForceMatcher{}.match(f, g);
  REQUIRE(m.size() == reference.size());
  for (std::size_t k = 0; k < m.size(); ++k) {
    CHECK(m[k].queryIdx == reference[k].queryIdx);
    CHECK(m[k].trainIdx == reference[k].trainIdx);
    CHECK(m[k].distance == reference[k].distance);
  }
}

TEST_CASE("ties are broken like OpenCV: the first minimum in both directions") {
  // Many equal descriptors: every a_i is at the same distance to several b_j.
  cv::RNG rng(5);
  vmap::Features a, b;
  a.norm = b.norm = cv::NORM_HAMMING;
  a.descriptors = cv::Mat(60, 32, CV_8U);
  b.descriptors = cv::Mat(70, 32, CV_8U);
  for (int i = 0; i < 60; ++i) a.descriptors.row(i).setTo(cv::Scalar(rng.uniform(0, 4)));
  for (int j = 0; j < 70; ++j) b.descriptors.row(j).setTo(cv::Scalar(rng.uniform(0, 4)));
  a.keypoints.resize(60);
  b.keypoints.resize(70);
  std::vector<cv::DMatch> reference;
  cv::BFMatcher(cv::NORM_HAMMING, true).match(a.descriptors, b.descriptors, reference);
  const auto m = vmap::BruteForceMatcher{}.match(a, b);
  REQUIRE(m.size() == reference.size());
  for (std::size_t k = 0; k < m.size(); ++k) {
    CHECK(m[k].queryIdx == reference[k].queryIdx);
    CHECK(m[k].trainIdx == reference[k].trainIdx);
  }
}
