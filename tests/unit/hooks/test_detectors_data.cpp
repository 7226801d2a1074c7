// The three cv::dnn detector adapters on a real frame whose content was checked by eye,
// and their errors for missing, foreign and corrupt model files.
#include <vmap/hooks/class_names.hpp>
#include <vmap/hooks/dnn_detectors.hpp>
#include <vmap/hooks/precomputed_detections.hpp>

#include "support/errors.hpp"
#include "support/shared_data.hpp"

#include <doctest/doctest.h>
#include <opencv2/imgcodecs.hpp>

#include <algorithm>
#include <cmath>
#include <fstream>
#include <iterator>
#include <string>
#include <vector>

namespace {

// tum_fr1_rpy frame 1305031253.529706: a man in a white T-shirt sits behind the desk
// (box drawn by hand: x 265-385, y 30-215), an empty office chair stands on the left
// (x 75-230, y 98-238), a white cup stands on the desk in front of the monitor
// (x 357-406, y 362-429), a large monitor fills the lower right.
const cv::Rect2f person_truth(265, 30, 120, 185);
const cv::Rect2f chair_truth(75, 98, 155, 140);
const cv::Rect2f cup_truth(357, 362, 49, 67);
constexpr int person = 0, cup = 41, chair = 56;

cv::Mat office_frame() {
  const cv::Mat img = cv::imread(vmap::test::data_path("tum_fr1_rpy/rgb/1305031253.529706.jpg").string());
  REQUIRE(img.size() == cv::Size(640, 480));
  return img;
}

/// Best IoU of a detection of `label` with `truth` (0 if none).
float best_iou(const std::vector<vmap::Detection>& dets, int label, const cv::Rect2f& truth) {
  float best = 0.0f;
  for (const auto& d : dets)
    if (d.label == label) best = std::max(best, vmap::iou(d.box, truth));
  return best;
}

void check_inside_image(const std::vector<vmap::Detection>& dets, cv::Size size) {
  for (const auto& d : dets) {
    CHECK(d.score >= 0.5f);
    CHECK(d.score <= 1.0f);
    CHECK(d.label >= 0);
    CHECK(d.label < 80);
    CHECK(d.box.x >= 0.0f);
    CHECK(d.box.y >= 0.0f);
    CHECK(d.box.x + d.box.width <= static_cast<float>(size.width) + 1e-3f);
    CHECK(d.box.y + d.box.height <= static_cast<float>(size.height) + 1e-3f);
  }
}

using vmap::test::error_of;

template <class D>
const char* model_file();
template <>
const char* model_file<vmap::YoloxDetector>() { return "yolox_nano.onnx"; }
template <>
const char* model_file<vmap::NanoDetDetector>() { return "nanodet_m_320.onnx"; }
template <>
const char* model_file<vmap::FastestDetDetector>() { return "FastestDet.onnx"; }

}  // namespace

TEST_SUITE("data") {
  // One conformance suite that every cv::dnn ObjectDetector runs.
  TEST_CASE_TEMPLATE("ObjectDetector conformance of the cv::dnn adapters", D, vmap::YoloxDetector,
                     vmap::NanoDetDetector, vmap::FastestDetDetector) {
    static_assert(vmap::ObjectDetector<D>);
    D first({.model = vmap::test::model_path(model_file<D>()), .score_threshold = 0.3f});
    for (const char* file : {"tum_fr1_rpy/rgb/1305031253.529706.jpg", "rtabmap_loop/images/20.jpg"}) {
      CAPTURE(file);
      const cv::Mat img = cv::imread(vmap::test::data_path(file).string());
      const auto dets = first.detect(img);
      REQUIRE_FALSE(dets.empty());
      for (std::size_t i = 0; i < dets.size(); ++i) {
        const auto& d = dets[i];
        CHECK(d.score >= 0.3f);
        CHECK(d.score <= 1.0f);
        CHECK(d.label >= 0);
        CHECK(d.label < first.classes());
        CHECK(d.box.width > 0.0f);
        CHECK(d.box.height > 0.0f);
        CHECK(d.box.x >= 0.0f);
        CHECK(d.box.y >= 0.0f);
        CHECK(d.box.x + d.box.width <= static_cast<float>(img.cols) + 1e-3f);
        CHECK(d.box.y + d.box.height <= static_cast<float>(img.rows) + 1e-3f);
        if (i > 0) CHECK(dets[i - 1].score >= d.score);  // NMS returns them by decreasing score
      }
      // Held by value: a moved detector gives the same answer, and a second call too.
      D moved(std::move(first));
      const auto again = moved.detect(img);
      REQUIRE(again.size() == dets.size());
      for (std::size_t i = 0; i < dets.size(); ++i) {
        CHECK(again[i].label == dets[i].label);
        CHECK(again[i].score == dets[i].score);
        CHECK(again[i].box == dets[i].box);
      }
      first = std::move(moved);
    }
  }


  TEST_CASE("YOLOX-nano finds the person, the chair and the cup where they are") {
    const cv::Mat img = office_frame();
    vmap::YoloxDetector yolox({.model = vmap::test::model_path("yolox_nano.onnx")});
    CHECK(yolox.classes() == 80);
    const auto dets = yolox.detect(img);
    check_inside_image(dets, img.size());
    CHECK(best_iou(dets, person, person_truth) > 0.75f);
    CHECK(best_iou(dets, chair, chair_truth) > 0.7f);
    CHECK(best_iou(dets, cup, cup_truth) > 0.6f);
    const auto names = vmap::read_class_names(vmap::test::model_path("coco80.names"));
    for (const auto& d : dets) MESSAGE("yolox: " << vmap::class_name(names, d.label) << " " << d.score);

    SUBCASE("grey and 16-bit inputs are accepted and see the same person") {
      cv::Mat grey, deep;
      cv::cvtColor(img, grey, cv::COLOR_BGR2GRAY);
      CHECK(best_iou(yolox.detect(grey), person, person_truth) > 0.6f);
      img.convertTo(deep, CV_16UC3, 257.0);
      CHECK(best_iou(yolox.detect(deep), person, person_truth) > 0.75f);
    }
    SUBCASE("behind AnyDetector the result is the same") {
      vmap::AnyDetector any =
          vmap::make_dnn_detector(vmap::DetectorFormat::yolox, {.model = vmap::test::model_path("yolox_nano.onnx")});
      const auto again = any.detect(img);
      REQUIRE(again.size() == dets.size());
      for (std::size_t i = 0; i < dets.size(); ++i) {
        CHECK(again[i].label == dets[i].label);
        CHECK(again[i].box == dets[i].box);
      }
    }
    SUBCASE("a bad image is an error") {
      CHECK_THROWS_AS((void)yolox.detect(cv::Mat()), vmap::Error);
      CHECK_THROWS_AS((void)yolox.detect(cv::Mat(10, 10, CV_32FC3)), vmap::Error);
    }
  }

  TEST_CASE("YOLOX-nano on a desk view finds the keyboard, the cup and the monitor where they are") {
    // tum_fr1_rpy frame 1305031241.529758, looking down at the desk: a white keyboard on
    // the right (by eye x 380-632, y 165-310), a white cup behind it (x 333-380,
    // y 117-187), the monitor cut by the top edge (x 330-640, y 0-110).
    const cv::Mat img = cv::imread(vmap::test::data_path("tum_fr1_rpy/rgb/1305031241.529758.jpg").string());
    vmap::YoloxDetector yolox({.model = vmap::test::model_path("yolox_nano.onnx")});
    const auto dets = yolox.detect(img);
    check_inside_image(dets, img.size());
    constexpr int keyboard = 66, tv = 62;
    CHECK(best_iou(dets, keyboard, cv::Rect2f(380, 165, 252, 145)) > 0.75f);
    CHECK(best_iou(dets, cup, cv::Rect2f(333, 117, 47, 70)) > 0.6f);
    CHECK(best_iou(dets, tv, cv::Rect2f(330, 0, 310, 110)) > 0.6f);
  }

  TEST_CASE("NanoDet-m finds the person and the chair where they are") {
    const cv::Mat img = office_frame();
    vmap::NanoDetDetector nanodet({.model = vmap::test::model_path("nanodet_m_320.onnx")});
    CHECK(nanodet.classes() == 80);
    const auto dets = nanodet.detect(img);
    check_inside_image(dets, img.size());
    CHECK(best_iou(dets, person, person_truth) > 0.75f);
    CHECK(best_iou(dets, chair, chair_truth) > 0.7f);
  }

  TEST_CASE("FastestDet finds the person, the chair and the cup where they are") {
    const cv::Mat img = office_frame();
    vmap::FastestDetDetector fastest({.model = vmap::test::model_path("FastestDet.onnx")});
    CHECK(fastest.classes() == 80);
    const auto dets = fastest.detect(img);
    check_inside_image(dets, img.size());
    CHECK(best_iou(dets, person, person_truth) > 0.75f);
    CHECK(best_iou(dets, chair, chair_truth) > 0.6f);
    CHECK(best_iou(dets, cup, cup_truth) > 0.6f);
  }

  TEST_CASE("the stored YOLOX-nano label files match the adapter and cover their sequences") {
    const auto rtab = vmap::PrecomputedDetections::load(vmap::test::source_dir() / "examples/data/rtabmap_loop_yolox.txt");
    CHECK(rtab.frames_declared());
    CHECK(rtab.frames() == 84);
    const auto cabinet =
        vmap::PrecomputedDetections::load(vmap::test::source_dir() / "examples/data/tum_fr3_cabinet_kf_yolox.txt");
    CHECK(cabinet.frames() == 58);
    // Frame 19 is images/20.jpg (frame k = (k+1).jpg), run again with the same floor.
    vmap::YoloxDetector yolox({.model = vmap::test::model_path("yolox_nano.onnx"), .score_threshold = 0.1f});
    const auto live = yolox.detect(cv::imread(vmap::test::data_path("rtabmap_loop/images/20.jpg").string()));
    const auto stored = rtab.at(19);
    REQUIRE(live.size() == stored.size());
    REQUIRE_FALSE(live.empty());
    for (std::size_t i = 0; i < live.size(); ++i) {
      CHECK(stored[i].label == live[i].label);
      CHECK(stored[i].score == doctest::Approx(live[i].score).epsilon(1e-3));
      CHECK(std::abs(stored[i].box.x - live[i].box.x) < 0.06f);  // stored with one decimal
      CHECK(std::abs(stored[i].box.height - live[i].box.height) < 0.06f);
    }
  }

  TEST_CASE("detectors: a model of another format is an error naming the file and the mismatch") {
    const auto nanodet_file = vmap::test::model_path("nanodet_m_320.onnx");
    const auto yolox_file = vmap::test::model_path("yolox_nano.onnx");
    const auto xfeat_file = vmap::test::model_path("xfeat_320x224.onnx");

    std::string e = error_of([&] { vmap::YoloxDetector d({.model = nanodet_file}); });
    CHECK(e.find("nanodet_m_320.onnx") != std::string::npos);
    MESSAGE(e);
    e = error_of([&] { vmap::NanoDetDetector d({.model = yolox_file}); });
    CHECK(e.find("yolox_nano.onnx") != std::string::npos);
    CHECK(e.find("cls_pred_stride") != std::string::npos);
    MESSAGE(e);
    e = error_of([&] { vmap::FastestDetDetector d({.model = xfeat_file}); });
    CHECK(e.find("xfeat_320x224.onnx") != std::string::npos);
    MESSAGE(e);
    e = error_of([&] { vmap::FastestDetDetector d({.model = yolox_file}); });
    CHECK(e.find("yolox_nano.onnx") != std::string::npos);
    MESSAGE(e);
  }

  TEST_CASE("detectors: a corrupt or non-ONNX file is an error, not a crash") {
    const auto dir = vmap::test::scratch_dir("hooks_bad_models");
    const auto text = dir / "names.onnx";
    std::ofstream(text) << "person\nbicycle\n";
    std::string e = error_of([&] { vmap::YoloxDetector d({.model = text}); });
    CHECK(e.find("names.onnx") != std::string::npos);
    MESSAGE(e);

    std::ifstream in(vmap::test::model_path("yolox_nano.onnx"), std::ios::binary);
    const std::string bytes((std::istreambuf_iterator<char>(in)), std::istreambuf_iterator<char>());
    const auto cut = dir / "truncated.onnx";
    std::ofstream(cut, std::ios::binary) << bytes.substr(0, bytes.size() / 3);
    e = error_of([&] { vmap::YoloxDetector d({.model = cut}); });
    CHECK(e.find("truncated.onnx") != std::string::npos);
    MESSAGE(e);

    e = error_of([&] { vmap::NanoDetDetector d({.model = dir}); });  // a folder
    CHECK(e.find("is a folder, expected a file") != std::string::npos);
  }
}
