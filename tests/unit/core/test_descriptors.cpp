// Descriptor conformance: every Descriptor model runs the same suite.
#include <vmap/features/akaze.hpp>
#include <vmap/features/orb.hpp>
#include <vmap/features/sift.hpp>

#include "support/images.hpp"

#include <doctest/doctest.h>
#include <opencv2/imgproc.hpp>

#include <algorithm>
#include <cmath>
#include <limits>
#include <string>

namespace {

template <class D>
int expected_norm() {
  return std::is_same_v<D, vmap::SiftDescriptor> ? cv::NORM_L2 : cv::NORM_HAMMING;
}

void check_same_features(const vmap::Features& a, const vmap::Features& b) {
  REQUIRE(a.size() == b.size());
  for (std::size_t i = 0; i < a.size(); ++i) {
    CHECK(a.keypoints[i].pt == b.keypoints[i].pt);
  }
  CHECK(cv::norm(a.descriptors, b.descriptors, cv::NORM_INF) == 0.0);
}

}  // namespace

TEST_CASE_TEMPLATE("Descriptor conformance", D, vmap::OrbDescriptor, vmap::AkazeDescriptor, vmap::SiftDescriptor) {
  D descriptor;
  // 320x240 keeps the suite quick (doctest runs the body once per SUBCASE).
  const cv::Mat grey = vmap::test::textured_image(3, {320, 240});
  const vmap::Features f = descriptor.extract(grey);

  SUBCASE("features are consistent") {
    CHECK(f.size() > 100);
    CHECK(f.descriptors.rows == static_cast<int>(f.size()));
    CHECK(f.norm == expected_norm<D>());
    CHECK(f.image_size == grey.size());
    for (const auto& kp : f.keypoints) {
      CHECK(kp.pt.x >= 0);
      CHECK(kp.pt.y >= 0);
      CHECK(kp.pt.x < grey.cols);
      CHECK(kp.pt.y < grey.rows);
    }
  }

  SUBCASE("deterministic: the same image gives the same features") {
    D other;
    check_same_features(f, other.extract(grey));
    check_same_features(f, descriptor.extract(grey));  // and the same object again
  }

  SUBCASE("BGR, BGRA and 16-bit inputs give exactly the grey result") {
    cv::Mat bgr, bgra, grey16, bgr16;
    cv::cvtColor(grey, bgr, cv::COLOR_GRAY2BGR);
    cv::cvtColor(grey, bgra, cv::COLOR_GRAY2BGRA);
    grey.convertTo(grey16, CV_16U, 257.0);  // 255 -> 65535; /257 maps back exactly
    bgr.convertTo(bgr16, CV_16UC3, 257.0);
    check_same_features(f, descriptor.extract(bgr));
    check_same_features(f, descriptor.extract(bgra));
    check_same_features(f, descriptor.extract(grey16));
    check_same_features(f, descriptor.extract(bgr16));
  }

  SUBCASE("a blank image has no features, which is a value, not an error") {
    const vmap::Features blank = descriptor.extract(cv::Mat(480, 640, CV_8UC1, cv::Scalar(128)));
    CHECK(blank.empty());
    CHECK(blank.descriptors.rows == 0);
  }

  SUBCASE("bad images are errors that say what is wrong") {
    CHECK_THROWS_WITH_AS((void)descriptor.extract(cv::Mat()), doctest::Contains("empty"), vmap::Error);
    CHECK_THROWS_WITH_AS((void)descriptor.extract(cv::Mat(0, 10, CV_8UC1)), doctest::Contains("empty"), vmap::Error);
    CHECK_THROWS_WITH_AS((void)descriptor.extract(cv::Mat(48, 64, CV_8UC2, cv::Scalar::all(3))),
                         doctest::Contains("2 channels"), vmap::Error);
    CHECK_THROWS_WITH_AS((void)descriptor.extract(cv::Mat(48, 64, CV_32FC1, cv::Scalar(0.5))),
                         doctest::Contains("CV_32F"), vmap::Error);
    CHECK_THROWS_WITH_AS((void)descriptor.extract(cv::Mat(48, 64, CV_8SC1, cv::Scalar(1))), doctest::Contains("depth"),
                         vmap::Error);
  }
}

TEST_CASE("descriptor options are validated") {
  const float nan = std::numeric_limits<float>::quiet_NaN();
  CHECK_THROWS_WITH_AS(vmap::OrbDescriptor({.features = 0}), doctest::Contains("features"), vmap::Error);
  CHECK_THROWS_WITH_AS(vmap::OrbDescriptor({.scale_factor = nan}), doctest::Contains("scale_factor"), vmap::Error);
  CHECK_THROWS_WITH_AS(vmap::OrbDescriptor({.scale_factor = 1.0f}), doctest::Contains("scale_factor"), vmap::Error);
  CHECK_THROWS_WITH_AS(vmap::OrbDescriptor({.levels = 0}), doctest::Contains("levels"), vmap::Error);
  CHECK_THROWS_WITH_AS(vmap::AkazeDescriptor({.threshold = nan}), doctest::Contains("threshold"), vmap::Error);
  CHECK_THROWS_WITH_AS(vmap::AkazeDescriptor({.threshold = -1.0f}), doctest::Contains("threshold"), vmap::Error);
  CHECK_THROWS_WITH_AS(vmap::AkazeDescriptor({.octaves = 0}), doctest::Contains("octaves"), vmap::Error);
  CHECK_THROWS_WITH_AS(vmap::SiftDescriptor({.features = -1}), doctest::Contains("features"), vmap::Error);
  CHECK_THROWS_WITH_AS(vmap::SiftDescriptor({.sigma = std::nan("")}), doctest::Contains("sigma"), vmap::Error);
}

TEST_CASE("ORB options reach the detector") {
  const cv::Mat grey = vmap::test::textured_image();
  vmap::OrbDescriptor few({.features = 100});
  vmap::OrbDescriptor many({.features = 2000});
  const auto a = few.extract(grey);
  const auto b = many.extract(grey);
  // OpenCV's ORB splits the budget over pyramid levels and rounds per level, so it can
  // return a few more keypoints than asked.
  CHECK(a.size() <= 105);
  CHECK(a.size() >= 90);
  CHECK(b.size() > a.size());
  CHECK(a.descriptors.cols == 32);  // 256 bits
}

TEST_CASE("ORB describes small images with a smaller border and FAST threshold") {
  vmap::OrbDescriptor orb;
  CHECK(orb.small({160, 120}));
  CHECK(orb.small({640, 200}));  // the shorter side decides
  CHECK_FALSE(orb.small({320, 240}));
  CHECK_FALSE(vmap::OrbDescriptor({.small = {.max_side = 0}}).small({160, 120}));
  // The border of 31 pixels leaves 98 x 58 of a 160 x 120 image: the rule's 15 pixels
  // find keypoints nearer the edges, and more of them.
  const cv::Mat small = vmap::test::textured_image(3, {160, 120});
  vmap::OrbDescriptor before({.small = {.max_side = 0}});
  const auto with_rule = orb.extract(small), without = before.extract(small);
  CHECK(with_rule.size() > without.size());
  const auto nearest_edge = [](const vmap::Features& f) {
    float d = 1e9f;
    for (const cv::KeyPoint& k : f.keypoints) d = std::min({d, k.pt.x, k.pt.y, 159.0f - k.pt.x, 119.0f - k.pt.y});
    return d;
  };
  CHECK(nearest_edge(without) >= 30.0f);
  CHECK(nearest_edge(with_rule) < 30.0f);
  CHECK(nearest_edge(with_rule) >= 14.0f);
  // A large image is described as before.
  const cv::Mat large = vmap::test::textured_image();
  CHECK(orb.extract(large).keypoints.size() == before.extract(large).keypoints.size());
  // The default rule is not written, so memories recorded before name the same descriptor.
  CHECK(orb.describe() ==
        "OrbDescriptor features=1000 scale_factor=1.2000000476837158 levels=8 edge_threshold=31 fast_threshold=20");
  CHECK(before.describe() ==
        "OrbDescriptor features=1000 scale_factor=1.2000000476837158 levels=8 edge_threshold=31 fast_threshold=20 "
        "small_max_side=0 small_edge_threshold=15 small_fast_threshold=10");
  CHECK_THROWS_WITH_AS(vmap::OrbDescriptor({.small = {.max_side = -1}}), doctest::Contains("small.max_side"), vmap::Error);
  CHECK_THROWS_WITH_AS(vmap::OrbDescriptor({.small = {.fast_threshold = 0}}), doctest::Contains("small.fast_threshold"),
                       vmap::Error);
}
