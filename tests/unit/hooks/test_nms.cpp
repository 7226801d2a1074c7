#include <vmap/hooks/nms.hpp>

#include <doctest/doctest.h>

#include <vector>

using vmap::Detection;

TEST_CASE("iou of hand-made boxes") {
  const cv::Rect2f a(0, 0, 10, 10);
  CHECK(vmap::iou(a, a) == doctest::Approx(1.0));
  CHECK(vmap::iou(a, cv::Rect2f(5, 0, 10, 10)) == doctest::Approx(50.0 / 150.0));
  CHECK(vmap::iou(a, cv::Rect2f(5, 5, 10, 10)) == doctest::Approx(25.0 / 175.0));
  CHECK(vmap::iou(a, cv::Rect2f(10, 0, 10, 10)) == 0.0f);  // touching, no overlap
  CHECK(vmap::iou(a, cv::Rect2f(2, 2, 0, 0)) == 0.0f);     // no area
  CHECK(vmap::iou(cv::Rect2f(0, 0, 0, 0), cv::Rect2f(0, 0, 0, 0)) == 0.0f);
}

TEST_CASE("class-wise NMS keeps the best box of each cluster and of each class") {
  const std::vector<Detection> in = {
      {1, 0.6f, {0, 0, 10, 10}},     // suppressed by the 0.9 box (IoU 0.68 > 0.45)
      {1, 0.9f, {1, 0, 10, 10}},     // kept
      {2, 0.8f, {0, 0, 10, 10}},     // other class: kept despite the overlap
      {1, 0.7f, {100, 100, 10, 10}}, // same class, far away: kept
      {1, 0.5f, {6, 0, 10, 10}},     // IoU with 0.9 box = 50/150 = 0.33 < 0.45: kept
  };
  const auto out = vmap::nms(in, {.iou_threshold = 0.45f, .max_detections = 100});
  REQUIRE(out.size() == 4);
  CHECK(out[0].score == 0.9f);
  CHECK(out[0].label == 1);
  CHECK(out[1].score == 0.8f);
  CHECK(out[1].label == 2);
  CHECK(out[2].score == 0.7f);
  CHECK(out[3].score == 0.5f);
  CHECK(out[3].box.x == 6.0f);

  SUBCASE("a stricter IoU threshold suppresses the partial overlap too") {
    const auto strict = vmap::nms(in, {.iou_threshold = 0.3f});
    CHECK(strict.size() == 3);
  }
  SUBCASE("max_detections keeps the highest scores") {
    const auto two = vmap::nms(in, {.iou_threshold = 0.45f, .max_detections = 2});
    REQUIRE(two.size() == 2);
    CHECK(two[0].score == 0.9f);
    CHECK(two[1].score == 0.8f);
  }
  SUBCASE("the result does not depend on the input order") {
    std::vector<Detection> reversed(in.rbegin(), in.rend());
    const auto again = vmap::nms(reversed);
    REQUIRE(again.size() == out.size());
    for (std::size_t i = 0; i < out.size(); ++i) {
      CHECK(again[i].label == out[i].label);
      CHECK(again[i].box == out[i].box);
    }
  }
}

TEST_CASE("NMS of nothing is nothing; invalid options are errors") {
  CHECK(vmap::nms({}).empty());
  CHECK_THROWS_AS((void)vmap::nms({}, {.iou_threshold = 1.5f}), vmap::Error);
  CHECK_THROWS_AS((void)vmap::nms({}, {.iou_threshold = -0.1f}), vmap::Error);
  CHECK_THROWS_AS((void)vmap::nms({}, {.max_detections = 0}), vmap::Error);
}
