// PairMatcher hook: coarse-matrix decoding on synthetic matrices with known answers,
// the callback adapter, and the cv::dnn adapter's errors.
#include <vmap/geometry/fundamental.hpp>
#include <vmap/hooks/pair_matcher_adapters.hpp>
#include <vmap/keyframe/front_end.hpp>

#include "support/shared_data.hpp"

#include <doctest/doctest.h>

#include <string>

namespace {

// Image a: 4 x 3 cells over 320 x 240 (cell centres (c + 0.5) 80, (r + 0.5) 80);
// image b: 2 x 2 cells over 100 x 100 (centres 25 / 75).
const vmap::CoarseGrid grid_a{{4, 3}, {320, 240}};
const vmap::CoarseGrid grid_b{{2, 2}, {100, 100}};

cv::Mat synthetic_confidence() {
  cv::Mat m(12, 4, CV_32F, cv::Scalar(0.01));
  m.at<float>(0, 3) = 0.9f;   // mutual: a cell 0 (40, 40) <-> b cell 3 (75, 75)
  m.at<float>(5, 0) = 0.6f;   // row 5's best is column 0, but column 0's best is row 6
  m.at<float>(6, 0) = 0.7f;   // mutual: a cell 6 (200, 120) <-> b cell 0 (25, 25)
  m.at<float>(11, 1) = 0.15f; // mutual but below the 0.2 threshold: a (280, 200) <-> b (75, 25)
  return m;
}

}  // namespace

TEST_CASE("coarse decoding: mutual nearest neighbours above the threshold, cell centres in pixels") {
  const cv::Mat m = synthetic_confidence();
  const vmap::Correspondences c = vmap::decode_coarse_matches(m, grid_a, grid_b, 0.2f);
  CHECK(c.cells == 12);  // eq. 5 denominator: max(12, 4)
  REQUIRE(c.size() == 2);
  REQUIRE(c.points_b.size() == 2);
  REQUIRE(c.confidence.size() == 2);
  CHECK(c.points_a[0] == cv::Point2f(40, 40));
  CHECK(c.points_b[0] == cv::Point2f(75, 75));
  CHECK(c.confidence[0] == doctest::Approx(0.9));
  CHECK(c.points_a[1] == cv::Point2f(200, 120));
  CHECK(c.points_b[1] == cv::Point2f(25, 25));
  CHECK(c.confidence[1] == doctest::Approx(0.7));

  SUBCASE("a lower threshold admits the weak mutual match") {
    const auto low = vmap::decode_coarse_matches(m, grid_a, grid_b, 0.1f);
    REQUIRE(low.size() == 3);
    CHECK(low.points_a[2] == cv::Point2f(280, 200));
    CHECK(low.points_b[2] == cv::Point2f(75, 25));
  }
  SUBCASE("the network's 1 x N0 x N1 layout decodes the same") {
    const int sizes[] = {1, 12, 4};
    const cv::Mat three(3, sizes, CV_32F, const_cast<float*>(m.ptr<float>()));
    const auto again = vmap::decode_coarse_matches(three, grid_a, grid_b, 0.2f);
    REQUIRE(again.size() == 2);
    CHECK(again.points_a[1] == c.points_a[1]);
  }
  SUBCASE("a threshold of 1 keeps nothing; an all-equal matrix keeps only the lowest-index tie") {
    CHECK(vmap::decode_coarse_matches(m, grid_a, grid_b, 1.0f).size() == 0);
    const cv::Mat flat(12, 4, CV_32F, cv::Scalar(0.5));
    const auto ties = vmap::decode_coarse_matches(flat, grid_a, grid_b, 0.2f);
    REQUIRE(ties.size() == 1);  // row 0 -> column 0, and column 0's first best is row 0
    CHECK(ties.points_a[0] == cv::Point2f(40, 40));
    CHECK(ties.points_b[0] == cv::Point2f(25, 25));
  }
}

TEST_CASE("coarse decoding: a stride-8 grid over a resized image maps centres to the original pixels") {
  // A 640 x 480 network input at stride 8 is 80 x 60 cells; the images were 1280 x 960.
  const vmap::CoarseGrid a{{80, 60}, {1280, 960}};
  cv::Mat m(4800, 4800, CV_32F, cv::Scalar(0));
  const int i = 10 * 80 + 20, j = 30 * 80 + 5;  // a cell (20, 10), b cell (5, 30)
  m.at<float>(i, j) = 0.8f;
  const auto c = vmap::decode_coarse_matches(m, a, a, 0.2f);
  REQUIRE(c.size() == 1);
  CHECK(c.cells == 4800);
  CHECK(c.points_a[0] == cv::Point2f((20 + 0.5f) * 16, (10 + 0.5f) * 16));
  CHECK(c.points_b[0] == cv::Point2f((5 + 0.5f) * 16, (30 + 0.5f) * 16));
}

TEST_CASE("coarse decoding rejects matrices that do not fit the grids") {
  CHECK_THROWS_AS((void)vmap::decode_coarse_matches(cv::Mat(12, 5, CV_32F, cv::Scalar(0)), grid_a, grid_b, 0.2f),
                  vmap::Error);
  CHECK_THROWS_AS((void)vmap::decode_coarse_matches(cv::Mat(12, 4, CV_64F, cv::Scalar(0)), grid_a, grid_b, 0.2f),
                  vmap::Error);
  CHECK_THROWS_AS((void)vmap::decode_coarse_matches(synthetic_confidence(), grid_a, grid_b, 1.5f), vmap::Error);
  CHECK_THROWS_AS((void)vmap::decode_coarse_matches(synthetic_confidence(), {{0, 3}, {320, 240}}, grid_b, 0.2f),
                  vmap::Error);
}

template <class F>
concept Wrappable = requires { typename vmap::CallbackPairMatcher<F>; };
namespace {
auto wrong_result = [](const cv::Mat&, const cv::Mat&) { return 0; };
auto wrong_arity = [](const cv::Mat&) { return vmap::Correspondences{}; };
auto right = [](const cv::Mat&, const cv::Mat&) { return vmap::Correspondences{}; };
}  // namespace
static_assert(Wrappable<decltype(right)>);
static_assert(!Wrappable<decltype(wrong_result)>);
static_assert(!Wrappable<decltype(wrong_arity)>);
static_assert(vmap::PairMatcher<vmap::CallbackPairMatcher<decltype(right)>>);
// Every member of the adapter compiles (STYLE.md: explicit instantiation, as Sophus does).
struct EmptyPairCallback {
  vmap::Correspondences operator()(const cv::Mat&, const cv::Mat&) const { return {}; }
};
template class vmap::CallbackPairMatcher<EmptyPairCallback>;

// Both adapters plug into the key-image selector's pair front end (examples/methods.md, sec. 5).
static_assert(vmap::KeyframeFrontEnd<vmap::PairFrontEnd<vmap::DnnPairMatcher, vmap::FundamentalEstimator>>);
static_assert(
    vmap::KeyframeFrontEnd<vmap::PairFrontEnd<vmap::CallbackPairMatcher<decltype(right)>, vmap::FundamentalEstimator>>);

TEST_CASE("callback PairMatcher passes valid results through and rejects broken ones") {
  int calls = 0;
  auto good = [&calls](const cv::Mat& a, const cv::Mat&) {
    ++calls;
    return vmap::decode_coarse_matches(synthetic_confidence(), {{4, 3}, a.size()}, grid_b, 0.2f);
  };
  vmap::CallbackPairMatcher matcher(good);
  static_assert(vmap::PairMatcher<decltype(matcher)>);
  const cv::Mat img(240, 320, CV_8UC1, cv::Scalar(0));
  const auto c = matcher.match_pair(img, img);
  CHECK(calls == 1);
  CHECK(c.size() == 2);
  CHECK(c.cells == 12);

  const auto broken = [&](vmap::Correspondences bad, const std::string& part) {
    vmap::CallbackPairMatcher m([bad](const cv::Mat&, const cv::Mat&) { return bad; });
    try {
      (void)m.match_pair(img, img);
      FAIL("no error");
    } catch (const vmap::Error& e) {
      CHECK(std::string(e.what()).find(part) != std::string::npos);
    }
  };
  broken({{{1, 1}}, {}, {0.5f}, 10}, "differ in length");
  broken({{{1, 1}, {2, 2}}, {{1, 1}, {2, 2}}, {0.5f, 0.5f}, 1}, "eq. 5 denominator");
  broken({{{1, 1}}, {{1, 1}}, {1.5f}, 10}, "outside [0, 1]");
}

TEST_CASE("DnnPairMatcher options are checked") {
  CHECK_THROWS_AS(vmap::DnnPairMatcher({.model = "m.onnx", .input_size = {630, 480}}), vmap::Error);
  CHECK_THROWS_AS(vmap::DnnPairMatcher({.model = "m.onnx", .threshold = -1.0f}), vmap::Error);
  CHECK_THROWS_AS(vmap::DnnPairMatcher({.model = "/nonexistent/loftr.onnx"}), vmap::Error);
}

TEST_CASE("DnnPairMatcher: a model of the wrong shape is an error naming the file" * doctest::test_suite("data")) {
  const auto yolox = vmap::test::model_path("yolox_nano.onnx");
  const auto expect_error = [&](const vmap::DnnPairMatcherOptions& o) {
    try {
      vmap::DnnPairMatcher m(o);
      FAIL("no error");
    } catch (const vmap::Error& e) {
      const std::string what = e.what();
      CHECK(what.find("yolox_nano.onnx") != std::string::npos);
      MESSAGE(what);
    }
  };
  // LoFTR's input names: YOLOX has one input called "images".
  expect_error({.model = yolox, .input_size = {416, 416}});
  // Its own input name, but grey LoFTR-style inputs where YOLOX wants 3 channels.
  expect_error({.model = yolox, .input_size = {416, 416}, .input_names = {"images", "images"}});
}
