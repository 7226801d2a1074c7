#include <vmap/hooks/callback_detector.hpp>
#include <vmap/hooks/precomputed_detections.hpp>

#include "support/shared_data.hpp"

#include <doctest/doctest.h>

#include <opencv2/core.hpp>

#include <string>
#include <vector>

using vmap::Detection;
using vmap::PrecomputedDetections;

namespace {
bool same(const std::vector<Detection>& a, const std::vector<Detection>& b) {
  if (a.size() != b.size()) return false;
  for (std::size_t k = 0; k < a.size(); ++k)
    if (a[k].label != b[k].label || a[k].score != b[k].score || a[k].box != b[k].box) return false;
  return true;
}
}  // namespace

TEST_CASE("callback detector wraps any callable") {
  int calls = 0;
  auto f = [&calls](const cv::Mat& image) {
    ++calls;
    return std::vector<Detection>{{7, 0.75f, cv::Rect2f(0, 0, static_cast<float>(image.cols), 1)}};
  };
  vmap::CallbackDetector<decltype(f)> d(f);
  static_assert(vmap::ObjectDetector<decltype(d)>);
  const auto out = d.detect(cv::Mat(4, 6, CV_8U, cv::Scalar(0)));
  REQUIRE(out.size() == 1);
  CHECK(out[0].label == 7);
  CHECK(out[0].box.width == 6.0f);
  CHECK(calls == 1);
  vmap::FunctionDetector erased(f);
  CHECK(erased.detect(cv::Mat(1, 1, CV_8U)).size() == 1);
  CHECK(calls == 2);
}

TEST_CASE("precomputed detections: parse, random access and detect() in frame order") {
  const std::string text =
      "# made by hand\n"
      "# frames 5\n"
      "0 56 0.9 10 20 30 40\n"
      "3 0 0.25 1.5 2.5 3 4\n"
      "\n"
      "0 2 0.5\t0 0 5 5\n";
  auto p = PrecomputedDetections::parse(text, "hand.txt");
  CHECK(p.frames() == 5);
  CHECK(p.frames_declared());
  CHECK(p.detections() == 3);
  const auto f0 = p.at(0);
  REQUIRE(f0.size() == 2);
  CHECK(f0[0].label == 56);  // file order kept within a frame
  CHECK(f0[0].box == cv::Rect2f(10, 20, 30, 40));
  CHECK(f0[1].label == 2);
  CHECK(p.at(1).empty());
  CHECK(p.at(4).empty());  // a trailing frame known only from '# frames'
  CHECK_THROWS_AS((void)p.at(5), vmap::Error);
  const cv::Mat img;
  CHECK(p.detect(img).size() == 2);
  CHECK(p.detect(img).empty());
  CHECK(p.detect(img).empty());
  CHECK(p.detect(img)[0].score == 0.25f);
  p.seek(0);
  CHECK(p.cursor() == 0);
  CHECK(p.detect(img).size() == 2);

  const auto undeclared = PrecomputedDetections::parse("2 1 0.5 0 0 1 1\n");
  CHECK(undeclared.frames() == 3);
  CHECK_FALSE(undeclared.frames_declared());
  CHECK(undeclared.at(10).empty());
}

TEST_CASE("precomputed detections: write/read round trip is exact") {
  std::vector<std::vector<Detection>> frames(6);
  frames[0] = {{0, 0.123456789f, cv::Rect2f(1.0f / 3.0f, 2.5f, 100.25f, 7.0f)}};
  frames[2] = {{56, 1.0f, cv::Rect2f(0, 0, 0, 0)}, {79, 0.0f, cv::Rect2f(511.9f, 383.1f, 0.5f, 0.25f)}};
  // frames 3..5 empty: the length must survive the round trip.
  const auto dir = vmap::test::scratch_dir("lcd_detections");
  vmap::save_detections(dir / "labels.txt", frames);
  const auto back = PrecomputedDetections::load(dir / "labels.txt");
  REQUIRE(back.frames() == 6);
  for (std::size_t k = 0; k < frames.size(); ++k) CHECK(same(back.at(k), frames[k]));
  CHECK(PrecomputedDetections::parse(back.to_text()).to_text() == back.to_text());
}

TEST_CASE("precomputed detections: malformed or hostile files are an Error") {
  const auto bad = [](const std::string& t) { return PrecomputedDetections::parse(t, "bad.txt"); };
  CHECK_THROWS_WITH_AS((void)bad("0 1 0.5 0 0 1\n"), doctest::Contains("bad.txt:1"), vmap::Error);  // 6 fields
  CHECK_THROWS_AS((void)bad("0 1 0.5 0 0 1 1 9\n"), vmap::Error);
  CHECK_THROWS_AS((void)bad("-1 1 0.5 0 0 1 1\n"), vmap::Error);
  CHECK_THROWS_AS((void)bad("1.5 1 0.5 0 0 1 1\n"), vmap::Error);
  CHECK_THROWS_AS((void)bad("0 -3 0.5 0 0 1 1\n"), vmap::Error);
  CHECK_THROWS_AS((void)bad("0 1 nan 0 0 1 1\n"), vmap::Error);
  CHECK_THROWS_AS((void)bad("0 1 1.5 0 0 1 1\n"), vmap::Error);
  CHECK_THROWS_AS((void)bad("0 1 0.5 0 0 -1 1\n"), vmap::Error);
  CHECK_THROWS_AS((void)bad("0 1 0.5 inf 0 1 1\n"), vmap::Error);
  CHECK_THROWS_AS((void)bad("0 1 0.5 0 0 1 x\n"), vmap::Error);
  CHECK_THROWS_AS((void)bad("# frames 2\n5 1 0.5 0 0 1 1\n"), vmap::Error);  // beyond the length
  CHECK_THROWS_AS((void)bad("# frames two\n"), vmap::Error);
  CHECK_THROWS_AS((void)bad("# frames 2\n# frames 3\n"), vmap::Error);
  CHECK_THROWS_AS((void)bad("99999999999999999999999 1 0.5 0 0 1 1\n"), vmap::Error);  // overflows
  CHECK_THROWS_AS((void)PrecomputedDetections::load("/nonexistent/labels.txt"), vmap::Error);
  // A huge frame index is only a number: memory follows the detections, not the index.
  const auto far = bad("1000000000000 1 0.5 0 0 1 1\n");
  CHECK(far.frames() == 1000000000001ULL);
  CHECK(far.detections() == 1);
  CHECK(far.at(0).empty());
}
