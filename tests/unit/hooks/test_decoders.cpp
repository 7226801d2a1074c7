// Decoding of each detector output format on hand-made tensors with known boxes.
#include <vmap/hooks/dnn_detectors.hpp>

#include <doctest/doctest.h>

#include <array>
#include <cmath>
#include <string>

namespace {

cv::Mat zeros3(int a, int b, int c) {
  const int sizes[] = {a, b, c};
  return cv::Mat(3, sizes, CV_32F, cv::Scalar(0));
}

void check_box(const cv::Rect2f& got, const cv::Rect2f& want, double eps = 1e-3) {
  CHECK(got.x == doctest::Approx(want.x).epsilon(eps));
  CHECK(got.y == doctest::Approx(want.y).epsilon(eps));
  CHECK(got.width == doctest::Approx(want.width).epsilon(eps));
  CHECK(got.height == doctest::Approx(want.height).epsilon(eps));
}

}  // namespace

TEST_CASE("YOLOX decoding: grid offset, exp sizes, objectness x class score") {
  // side 64: 8x8 (stride 8) + 4x4 (16) + 2x2 (32) = 84 cells; 3 classes.
  static_assert(vmap::yolox_cells(64) == 84);
  static_assert(vmap::yolox_cells(416) == 3549);
  cv::Mat out = zeros3(1, 84, 8);
  const auto row = [&](int r) { return out.ptr<float>(0, r); };
  // Stride-16 cell (gx 1, gy 2) = row 64 + 2*4 + 1.
  float* p = row(73);
  p[0] = 0.5f;
  p[1] = 0.25f;
  p[2] = std::log(2.0f);
  p[3] = 0.0f;
  p[4] = 0.8f;
  p[5] = 0.1f;
  p[6] = 0.9f;
  p[7] = 0.3f;
  // A stride-8 cell scoring 0.3 x 0.5 = 0.15: below 0.5, above 0.1.
  row(0)[4] = 0.3f;
  row(0)[7] = 0.5f;

  const auto dets = vmap::decode_yolox(out, 64, 0.5f);
  REQUIRE(dets.size() == 1);
  CHECK(dets[0].label == 1);
  CHECK(dets[0].score == doctest::Approx(0.72));
  // centre ((0.5 + 1) 16, (0.25 + 2) 16) = (24, 36), size (2 x 16, 1 x 16)
  check_box(dets[0].box, {8.0f, 28.0f, 32.0f, 16.0f});

  const auto low = vmap::decode_yolox(out, 64, 0.1f);
  REQUIRE(low.size() == 2);
  CHECK(low[0].label == 2);
  CHECK(low[0].score == doctest::Approx(0.15));
  check_box(low[0].box, {-4.0f, -4.0f, 8.0f, 8.0f});  // centre (0, 0), exp(0) x 8

  SUBCASE("a 2-D N x (5 + C) matrix decodes the same") {
    const cv::Mat flat(84, 8, CV_32F, out.ptr<float>());
    const auto again = vmap::decode_yolox(flat, 64, 0.5f);
    REQUIRE(again.size() == 1);
    check_box(again[0].box, dets[0].box);
  }
  SUBCASE("a huge size logit stays finite") {
    row(73)[2] = 1000.0f;
    const auto big = vmap::decode_yolox(out, 64, 0.5f);
    REQUIRE(big.size() == 1);
    CHECK(std::isfinite(big[0].box.width));
  }
}

TEST_CASE("YOLOX decoding rejects tensors of another shape") {
  CHECK_THROWS_AS((void)vmap::decode_yolox(zeros3(1, 83, 8), 64, 0.5f), vmap::Error);
  CHECK_THROWS_AS((void)vmap::decode_yolox(zeros3(1, 84, 5), 64, 0.5f), vmap::Error);
  CHECK_THROWS_AS((void)vmap::decode_yolox(zeros3(1, 84, 8), 60, 0.5f), vmap::Error);
  cv::Mat wrong_type;
  zeros3(1, 84, 8).convertTo(wrong_type, CV_64F);
  CHECK_THROWS_AS((void)vmap::decode_yolox(wrong_type, 64, 0.5f), vmap::Error);
  try {
    (void)vmap::decode_yolox(zeros3(1, 3549, 85), 64, 0.5f);
    FAIL("no error");
  } catch (const vmap::Error& e) {
    CHECK(std::string(e.what()).find("1x3549x85") != std::string::npos);  // names the shape it got
  }
}

TEST_CASE("NanoDet decoding: distribution over bins, expected distance x stride from the cell centre") {
  // side 32: 4x4 cells at stride 8, 2x2 at 16, 1x1 at 32; 2 classes, 8 bins per side.
  std::array<cv::Mat, 3> cls{zeros3(1, 16, 2), zeros3(1, 4, 2), zeros3(1, 1, 2)};
  std::array<cv::Mat, 3> dis{zeros3(1, 16, 32), zeros3(1, 4, 32), zeros3(1, 1, 32)};
  // Stride 8, cell (x 2, y 1) = index 6, centre (20, 12). One-hot bins: left 1, top 2,
  // right 0, bottom 3 -> distances 8, 16, 0, 24.
  cls[0].ptr<float>(0, 6)[1] = 0.9f;
  float* d = dis[0].ptr<float>(0, 6);
  d[0 * 8 + 1] = 60.0f;
  d[1 * 8 + 2] = 60.0f;
  d[2 * 8 + 0] = 60.0f;
  d[3 * 8 + 3] = 60.0f;
  // Stride 32, the single cell (centre (16, 16)), uniform bins: expected bin 3.5 -> 112.
  cls[2].ptr<float>(0, 0)[0] = 0.7f;

  const auto dets = vmap::decode_nanodet(cls, dis, 32, 0.5f);
  REQUIRE(dets.size() == 2);
  CHECK(dets[0].label == 1);
  CHECK(dets[0].score == doctest::Approx(0.9));
  check_box(dets[0].box, {12.0f, -4.0f, 8.0f, 40.0f});
  CHECK(dets[1].label == 0);
  CHECK(dets[1].score == doctest::Approx(0.7));
  check_box(dets[1].box, {16.0f - 112.0f, 16.0f - 112.0f, 224.0f, 224.0f});
  CHECK(vmap::decode_nanodet(cls, dis, 32, 0.95f).empty());

  SUBCASE("outputs of another shape are errors") {
    auto bad = dis;
    bad[1] = zeros3(1, 4, 30);  // not 4 x bins
    CHECK_THROWS_AS((void)vmap::decode_nanodet(cls, bad, 32, 0.5f), vmap::Error);
    auto few = cls;
    few[0] = zeros3(1, 15, 2);  // not 4x4 cells
    CHECK_THROWS_AS((void)vmap::decode_nanodet(few, dis, 32, 0.5f), vmap::Error);
  }
}

TEST_CASE("FastestDet decoding: obj^0.6 cls^0.4, tanh offsets, sigmoid sizes relative to the image") {
  const int sizes[] = {1, 7, 2, 3};  // 2 classes on a 3 x 2 grid
  cv::Mat out(4, sizes, CV_32F, cv::Scalar(0));
  const auto at = [&](int c, int y, int x) -> float& { return out.ptr<float>(0, c, y)[x]; };
  at(0, 1, 2) = 0.81f;                           // objectness
  at(1, 1, 2) = std::atanh(0.5f);                // x offset 0.5
  at(2, 1, 2) = 0.0f;                            // y offset 0
  at(3, 1, 2) = 0.0f;                            // width = sigmoid(0) = 0.5
  at(4, 1, 2) = std::log(0.25f / 0.75f);         // height = 0.25
  at(5, 1, 2) = 0.2f;
  at(6, 1, 2) = 0.8f;
  at(0, 0, 0) = 0.1f;  // another cell, low score
  at(5, 0, 0) = 1.0f;

  const auto dets = vmap::decode_fastestdet(out, cv::Size(300, 200), 0.5f);
  REQUIRE(dets.size() == 1);
  CHECK(dets[0].label == 1);
  CHECK(dets[0].score == doctest::Approx(std::pow(0.81, 0.6) * std::pow(0.8, 0.4)));
  // centre ((0.5 + 2) / 3 x 300, (0 + 1) / 2 x 200) = (250, 100), size (150, 50)
  check_box(dets[0].box, {175.0f, 75.0f, 150.0f, 50.0f});

  const auto low = vmap::decode_fastestdet(out, cv::Size(300, 200), 0.2f);
  CHECK(low.size() == 2);  // 0.1^0.6 = 0.25 >= 0.2

  CHECK_THROWS_AS((void)vmap::decode_fastestdet(zeros3(1, 85, 22), cv::Size(300, 200), 0.5f), vmap::Error);
  CHECK_THROWS_AS((void)vmap::decode_fastestdet(out, cv::Size(0, 200), 0.5f), vmap::Error);
}

TEST_CASE("detector names parse; unknown names are errors listing the choices") {
  CHECK(vmap::parse_detector_format("yolox") == vmap::DetectorFormat::yolox);
  CHECK(vmap::parse_detector_format("nanodet") == vmap::DetectorFormat::nanodet);
  CHECK(vmap::parse_detector_format("fastestdet") == vmap::DetectorFormat::fastestdet);
  try {
    (void)vmap::parse_detector_format("yolov8");
    FAIL("no error");
  } catch (const vmap::Error& e) {
    CHECK(std::string(e.what()).find("yolox, nanodet or fastestdet") != std::string::npos);
  }
}

TEST_CASE("detector options are checked before the model is touched") {
  CHECK_THROWS_AS(vmap::YoloxDetector({.model = "x.onnx", .score_threshold = 1.5f}), vmap::Error);
  CHECK_THROWS_AS(vmap::NanoDetDetector({.model = "x.onnx", .nms = {.iou_threshold = 2.0f}}), vmap::Error);
  try {
    vmap::FastestDetDetector d({});
    FAIL("no error");
  } catch (const vmap::Error& e) {
    CHECK(std::string(e.what()).find("no model file") != std::string::npos);
  }
  try {
    vmap::YoloxDetector d({.model = "/nonexistent/dir/yolox.onnx"});
    FAIL("no error");
  } catch (const vmap::Error& e) {
    CHECK(std::string(e.what()).find("/nonexistent/dir/yolox.onnx") != std::string::npos);
  }
}
