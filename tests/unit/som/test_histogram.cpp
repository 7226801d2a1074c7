#include <vmap/features/akaze.hpp>
#include <vmap/som/histogram.hpp>
#include <vmap/som/nearest_wall.hpp>
#include <vmap/place/vocabulary.hpp>

#include "support/shared_data.hpp"

#include <doctest/doctest.h>

#include <opencv2/imgcodecs.hpp>

#include <random>
#include <string>
#include <vector>

namespace {

// Binary descriptors (61 bytes, as A-KAZE's) around `centres`, each bit flipped with
// probability p.
cv::Mat noisy_copies(const cv::Mat& centres, int per_centre, double p, unsigned seed) {
  std::mt19937 rng(seed);
  std::bernoulli_distribution flip(p);
  cv::Mat out(centres.rows * per_centre, centres.cols, CV_8UC1);
  for (int c = 0; c < centres.rows; ++c)
    for (int k = 0; k < per_centre; ++k) {
      uchar* row = out.ptr<uchar>(c * per_centre + k);
      for (int b = 0; b < centres.cols; ++b) {
        uchar v = centres.at<uchar>(c, b);
        for (int bit = 0; bit < 8; ++bit)
          if (flip(rng)) v = static_cast<uchar>(v ^ (1u << bit));
        row[b] = v;
      }
    }
  return out;
}

cv::Mat random_centres(int n, unsigned seed) {
  cv::Mat c(n, 61, CV_8UC1);
  cv::RNG rng(seed);
  rng.fill(c, cv::RNG::UNIFORM, 0, 256);
  return c;
}

vmap::Features with_descriptors(const cv::Mat& d) {
  vmap::Features f;
  f.descriptors = d;
  f.keypoints.resize(static_cast<std::size_t>(d.rows));
  f.image_size = {100, 100};
  return f;
}

}  // namespace

TEST_CASE("k-majority recovers the centres of binary clusters, deterministically") {
  const cv::Mat centres = random_centres(4, 7);
  const cv::Mat data = noisy_copies(centres, 200, 0.05, 3);
  // split over "images" as the histogram's fit does
  const std::vector<cv::Mat> sets{data.rowRange(0, 300), data.rowRange(300, 800)};
  const auto v = vmap::BinaryVocabularyTree::learn(sets, {.branching = 4, .depth = 1, .iterations = 10, .seed = 2});
  REQUIRE(v.size() == 4);
  // each true centre has a word within a few bits (majority of 200 copies at 5 % flips)
  for (int c = 0; c < 4; ++c) {
    double best = 1e9;
    for (int w = 0; w < 4; ++w) best = std::min(best, cv::norm(centres.row(c), v.words().row(w), cv::NORM_HAMMING));
    CHECK(best <= 2.0);
  }
  const auto again = vmap::BinaryVocabularyTree::learn(sets, {.branching = 4, .depth = 1, .iterations = 10, .seed = 2});
  CHECK(cv::norm(v.words(), again.words(), cv::NORM_HAMMING) == 0.0);
  // bad input
  CHECK_THROWS_AS(vmap::BinaryVocabularyTree::learn({data.rowRange(0, 3)}, {.branching = 4}), vmap::Error);
  CHECK_THROWS_AS(vmap::BinaryVocabularyTree::learn({data, data.colRange(0, 32).clone()}, {.branching = 4}), vmap::Error);
  CHECK_THROWS_AS(vmap::BinaryVocabularyTree::learn({data}, {.branching = 0}), vmap::Error);
  cv::Mat floats(10, 8, CV_32F, cv::Scalar(1));
  CHECK_THROWS_AS(vmap::BinaryVocabularyTree::learn({floats}, {.branching = 2}), vmap::Error);
}

TEST_CASE("BowHistogram counts words exactly and normalises") {
  const cv::Mat words = random_centres(3, 1);
  cv::Mat d;
  cv::vconcat(std::vector<cv::Mat>{words.row(0), words.row(0), words.row(2), words.row(0)}, d);
  const auto f = with_descriptors(d);
  const vmap::BowHistogram l1(vmap::BinaryVocabularyTree::from_words(words), {.norm = vmap::HistogramNorm::l1});
  const Eigen::VectorXf h1 = l1(f);
  REQUIRE(h1.size() == 3);
  CHECK(h1[0] == doctest::Approx(0.75));
  CHECK(h1[1] == 0.0f);
  CHECK(h1[2] == doctest::Approx(0.25));
  const vmap::BowHistogram l2{vmap::BinaryVocabularyTree::from_words(words)};
  const Eigen::VectorXf h2 = l2(f);
  CHECK(h2.norm() == doctest::Approx(1.0));
  CHECK(h2[0] == doctest::Approx(3.0 / std::sqrt(10.0)));
  CHECK(l2(f) == h2);                                  // deterministic
  CHECK(l2(vmap::Features{}).isZero());                // no descriptors: zero vector
  CHECK_THROWS_AS((void)vmap::BowHistogram{}(f), vmap::Error);  // no vocabulary yet

  // fit() learns a vocabulary of the asked size, and is deterministic for a seed
  const cv::Mat data = noisy_copies(random_centres(8, 2), 30, 0.05, 4);
  std::vector<vmap::Features> training{with_descriptors(data.rowRange(0, 120)), with_descriptors(data.rowRange(120, 240))};
  vmap::BowHistogramOptions options;
  options.vocabulary.branching = 8;
  options.vocabulary.seed = 9;
  vmap::BowHistogram a(options), b(options);
  a.fit(training);
  b.fit(training);
  CHECK(a.dimension() == 8);
  CHECK(a(training[0]) == b(training[0]));

  // The histogram's vocabulary is flat: another depth is an Error naming the option.
  options.vocabulary.depth = 2;
  try {
    vmap::BowHistogram deep(options);
    FAIL("a vocabulary of depth 2 was accepted");
  } catch (const vmap::Error& e) {
    CHECK(e.kind() == vmap::ErrorKind::invalid_argument);
    CHECK(std::string(e.what()).find("BowHistogramOptions.vocabulary.depth") != std::string::npos);
  }
}

TEST_CASE("GridHistogram: exact shares and responses per cell") {
  vmap::Features f;
  f.image_size = {100, 50};
  auto kp = [](float x, float y, float r) { return cv::KeyPoint(cv::Point2f(x, y), 1.0f, -1, r); };
  f.keypoints = {kp(10, 10, 1.0f), kp(20, 10, 0.5f), kp(90, 40, 2.0f), kp(99.9f, 49.9f, 1.0f)};
  const vmap::GridHistogram g({.rows = 2, .cols = 2, .norm = vmap::HistogramNorm::l1});
  REQUIRE(g.dimension() == 8);
  const Eigen::VectorXf h = g(f);
  // before normalisation: shares (0.5, 0, 0, 0.5), mean relative responses (0.375, 0, 0, 0.75)
  const float total = 0.5f + 0.5f + 0.375f + 0.75f;
  CHECK(h[0] == doctest::Approx(0.5f / total));
  CHECK(h[3] == doctest::Approx(0.5f / total));
  CHECK(h[4] == doctest::Approx(0.375f / total));
  CHECK(h[7] == doctest::Approx(0.75f / total));
  CHECK(h[1] == 0.0f);
  CHECK(h.lpNorm<1>() == doctest::Approx(1.0));
  CHECK(g(vmap::Features{}).isZero());
  CHECK_THROWS_AS(vmap::GridHistogram({.rows = 0}), vmap::Error);
}

TEST_CASE("nearest_wall counts keypoints per image half") {
  vmap::Features f;
  f.image_size = {100, 50};
  for (float x : {10.f, 20.f, 49.9f, 50.f, 70.f}) f.keypoints.emplace_back(cv::Point2f(x, 5), 1.0f);
  const auto w = vmap::nearest_wall(f);
  CHECK(w.left == 3);
  CHECK(w.right == 2);
  CHECK(w.side == vmap::WallSide::left);
  CHECK_FALSE(w.tie());
  CHECK_THROWS_AS(vmap::nearest_wall(vmap::Features{}), vmap::Error);  // no image size

  // a real photo on the right half, a blank left half: the right wall is nearer
  const cv::Mat photo = cv::imread((vmap::test::source_dir() / "examples/data/tum_fr1_rpy_60/rgb/1305031229.528748.jpg").string());
  REQUIRE_FALSE(photo.empty());
  cv::Mat scene(photo.rows, photo.cols, photo.type(), cv::Scalar::all(128));
  photo(cv::Rect(photo.cols / 2, 0, photo.cols / 2, photo.rows)).copyTo(scene(cv::Rect(photo.cols / 2, 0, photo.cols / 2, photo.rows)));
  vmap::AkazeDescriptor akaze;
  const auto r = vmap::nearest_wall(akaze, scene);
  CHECK(r.side == vmap::WallSide::right);
  CHECK(r.right > 10 * (r.left + 1));
  cv::Mat mirrored;
  cv::flip(scene, mirrored, 1);
  CHECK(vmap::nearest_wall(akaze, mirrored).side == vmap::WallSide::left);
}
