// Real images (suite "data"): the whole extract -> match -> verify -> similarity chain on
// TUM fr1_rpy frames, checked against the same steps written with plain OpenCV calls.
#include <vmap/features/orb.hpp>
#include <vmap/geometry/fundamental.hpp>
#include <vmap/geometry/similarity.hpp>
#include <vmap/io/frame_source.hpp>
#include <vmap/matching/brute_force.hpp>

#include "support/shared_data.hpp"

#include <doctest/doctest.h>
#include <opencv2/calib3d.hpp>
#include <opencv2/features2d.hpp>
#include <opencv2/imgcodecs.hpp>

#include <algorithm>
#include <map>

namespace {

/// Eq. 5 with OpenCV alone, as ../shared/baselines/keyframes_opencv.cpp computes it.
double opencv_similarity(const cv::Mat& g1, const cv::Mat& g2) {
  auto orb = cv::ORB::create(1000);
  std::vector<cv::KeyPoint> k1, k2;
  cv::Mat d1, d2;
  orb->detectAndCompute(g1, cv::noArray(), k1, d1);
  orb->detectAndCompute(g2, cv::noArray(), k2, d2);
  cv::BFMatcher bf(cv::NORM_HAMMING, true);
  std::vector<cv::DMatch> m;
  bf.match(d1, d2, m);
  if (m.size() < 8) return 0.0;
  std::vector<cv::Point2f> p, q;
  for (const auto& x : m) {
    p.push_back(k1[static_cast<std::size_t>(x.queryIdx)].pt);
    q.push_back(k2[static_cast<std::size_t>(x.trainIdx)].pt);
  }
  cv::Mat mask;
  const cv::Mat F = cv::findFundamentalMat(p, q, cv::USAC_MAGSAC, 1.0, 0.99, mask);
  if (F.empty()) return 0.0;
  return static_cast<double>(cv::countNonZero(mask)) / static_cast<double>(std::max(k1.size(), k2.size()));
}

}  // namespace

TEST_SUITE("data") {
  TEST_CASE("similarity of consecutive tum_fr1_rpy frames is well above that of distant ones") {
    const auto list = vmap::test::data_path("tum_fr1_rpy/rgb.txt");
    auto source = vmap::FrameSource::open(list, {.grey = true});
    std::map<std::size_t, cv::Mat> frames;
    const std::size_t wanted[] = {100, 101, 300, 301, 500, 501, 650};
    while (auto f = source.next()) {
      if (std::find(std::begin(wanted), std::end(wanted), f->index) != std::end(wanted)) frames[f->index] = f->image;
      if (f->index > 650) break;
    }
    REQUIRE(frames.size() == std::size(wanted));

    vmap::OrbDescriptor orb;
    const vmap::BruteForceMatcher matcher;
    const vmap::FundamentalEstimator estimator;
    const vmap::InlierRatio similarity;
    auto vmap_similarity = [&](std::size_t i, std::size_t j) {
      const auto a = orb.extract(frames[i]);
      const auto b = orb.extract(frames[j]);
      const auto v = estimator.verify(a, b, matcher.match(a, b));
      return similarity(a, b, v);
    };
    for (const auto& [i, j] : {std::pair<std::size_t, std::size_t>{100, 101}, {300, 301}, {500, 501}}) {
      CAPTURE(i);
      const double near = vmap_similarity(i, j);
      // The same steps with plain OpenCV calls give the same number: same ORB, the same
      // mutual matches in the same order, and the same deterministic MAGSAC draws.
      CHECK(near == doctest::Approx(opencv_similarity(frames[i], frames[j])).epsilon(1e-12));
      CHECK(near > 0.2);
      const double far = vmap_similarity(i, 650);
      CHECK(far < 0.5 * near);
    }
  }

  TEST_CASE("frame source reads the TUM list in order with timestamps") {
    auto source = vmap::FrameSource::open(vmap::test::data_path("tum_fr1_rpy/rgb.txt"), {.end = 3});
    CHECK(source.kind() == vmap::SourceKind::tum_rgb);
    REQUIRE(source.total().has_value());
    CHECK(*source.total() == 723);
    auto f = source.next();
    REQUIRE(f);
    CHECK(f->index == 0);
    CHECK(f->name == "1305031229.528748.jpg");
    CHECK(f->timestamp == doctest::Approx(1305031229.528748));
    CHECK(f->image.size() == cv::Size(640, 480));
    CHECK(f->image.type() == CV_8UC3);
    CHECK(source.next());
    CHECK(source.next());
    CHECK_FALSE(source.next());
  }
}
