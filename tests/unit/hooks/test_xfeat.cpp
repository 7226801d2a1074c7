// XFeat Descriptor policy: Features contract, a synthetic homography pair, errors.
#include <vmap/hooks/any_descriptor.hpp>
#include <vmap/geometry/homography.hpp>
#include <vmap/hooks/xfeat.hpp>
#include <vmap/matching/brute_force.hpp>

#include "support/errors.hpp"
#include "support/shared_data.hpp"

#include <doctest/doctest.h>
#include <opencv2/imgcodecs.hpp>

#include <cmath>
#include <string>
#include <vector>

namespace {

using vmap::test::error_of;

/// Fraction of matches whose b point is within `px` of H applied to the a point.
double fraction_within(const vmap::Features& a, const vmap::Features& b, const vmap::Matches& m,
                       const cv::Matx33d& H, double px) {
  int good = 0;
  for (const auto& d : m) {
    const cv::Point2f p = a.keypoints[static_cast<std::size_t>(d.queryIdx)].pt;
    const cv::Point2f q = b.keypoints[static_cast<std::size_t>(d.trainIdx)].pt;
    const cv::Vec3d w = H * cv::Vec3d(p.x, p.y, 1.0);
    if (std::hypot(w[0] / w[2] - q.x, w[1] / w[2] - q.y) <= px) ++good;
  }
  return m.empty() ? 0.0 : static_cast<double>(good) / static_cast<double>(m.size());
}

}  // namespace

static_assert(vmap::Descriptor<vmap::XFeatDescriptor>);

TEST_SUITE("data") {
  TEST_CASE("XFeat: L2 float descriptors, unit length, keypoints inside the input image, deterministic") {
    vmap::XFeatDescriptor xfeat({.model = vmap::test::model_path("xfeat_320x224.onnx"), .top_k = 500});
    CHECK(xfeat.network_size({640, 480}) == cv::Size(320, 224));  // read from the model file
    const cv::Mat img = cv::imread(vmap::test::data_path("tum_fr1_rpy/rgb/1305031253.529706.jpg").string());
    const vmap::Features f = xfeat.extract(img);
    CHECK(f.norm == cv::NORM_L2);
    CHECK(f.image_size == img.size());
    REQUIRE(f.size() == 500);  // a textured office frame has far more than 500 maxima
    CHECK(f.descriptors.type() == CV_32F);
    CHECK(f.descriptors.cols == 64);
    CHECK(f.descriptors.rows == 500);
    for (int i = 0; i < f.descriptors.rows; i += 37) CHECK(cv::norm(f.descriptors.row(i)) == doctest::Approx(1.0).epsilon(1e-4));
    for (std::size_t i = 0; i + 1 < f.size(); ++i) CHECK(f.keypoints[i].response >= f.keypoints[i + 1].response);
    for (const auto& k : f.keypoints) {
      CHECK(k.pt.x >= 0.0f);
      CHECK(k.pt.y >= 0.0f);
      CHECK(k.pt.x < 640.0f);
      CHECK(k.pt.y < 480.0f);
    }
    const vmap::Features again = xfeat.extract(img);
    CHECK(cv::norm(again.descriptors, f.descriptors, cv::NORM_INF) == 0.0);

    SUBCASE("the 256x256 export works as well") {
      vmap::XFeatDescriptor square({.model = vmap::test::model_path("xfeat_256x256.onnx")});
      CHECK(square.network_size({640, 480}) == cv::Size(256, 256));
      CHECK(square.extract(img).size() > 300);
    }
  }

  TEST_CASE("XFeat on a synthetic homography pair: most mutual L2 matches agree with H, MAGSAC recovers H") {
    const cv::Mat frame = cv::imread(vmap::test::data_path("tum_fr1_rpy/rgb/1305031253.529706.jpg").string());
    vmap::XFeatDescriptor xfeat({.model = vmap::test::model_path("xfeat_320x224.onnx")});
    const vmap::BruteForceMatcher matcher({.mode = vmap::MatchMode::mutual});
    // XFeat's keypoints are whole pixels of the network input (320x224 here), so the
    // 3 px test is made at about that size (the frame halved to 320x240); at 640x480 a
    // network pixel is 2 image pixels and the same test uses 6 px.
    for (const double scale : {0.5, 1.0}) {
      CAPTURE(scale);
      cv::Mat img;
      cv::resize(frame, img, cv::Size(), scale, scale, cv::INTER_AREA);
      const double cx = img.cols / 2.0, cy = img.rows / 2.0;
      // A rotation of 8 degrees and a scale of 0.9 about the centre, a shift and a mild
      // perspective term: a real-looking second view whose true correspondence is known.
      const double a = 8.0 * CV_PI / 180.0, s = 0.9, p = 1e-5 / scale;
      const cv::Matx33d T1(1, 0, -cx, 0, 1, -cy, 0, 0, 1), T2(1, 0, cx + 10 * scale, 0, 1, cy - 5 * scale, 0, 0, 1);
      const cv::Matx33d R(s * std::cos(a), -s * std::sin(a), 0, s * std::sin(a), s * std::cos(a), 0, p, 2 * p, 1);
      const cv::Matx33d H = T2 * R * T1;
      cv::Mat warped;
      cv::warpPerspective(img, warped, cv::Mat(H), img.size(), cv::INTER_LINEAR, cv::BORDER_CONSTANT);

      const vmap::Features fa = xfeat.extract(img), fb = xfeat.extract(warped);
      const vmap::Matches m = matcher.match(fa, fb);
      const double tolerance = 6.0 * scale;  // 3 network pixels
      const double within = fraction_within(fa, fb, m, H, tolerance);
      MESSAGE("XFeat homography pair at " << img.cols << "x" << img.rows << ": " << fa.size() << " / " << fb.size()
                                          << " keypoints, " << m.size() << " mutual matches, " << within * 100.0
                                          << " % within " << tolerance << " px");
      CHECK(m.size() > 300);
      CHECK(within > 0.7);

      // The matches determine H: MAGSAC on them maps the image corners where H does.
      const vmap::Verification v = vmap::HomographyEstimator({.threshold_px = tolerance}).verify(fa, fb, m);
      REQUIRE(v.ok());
      CHECK(v.inliers > static_cast<int>(m.size()) / 2);
      for (const cv::Vec3d& corner : {cv::Vec3d(0, 0, 1), cv::Vec3d(img.cols, 0, 1), cv::Vec3d(0, img.rows, 1),
                                     cv::Vec3d(img.cols, img.rows, 1)}) {
        const cv::Vec3d t = H * corner, e = v.model * corner;
        CHECK(std::hypot(t[0] / t[2] - e[0] / e[2], t[1] / t[2] - e[1] / e[2]) < tolerance);
      }
    }

    SUBCASE("behind AnyDescriptor the features are the same") {
      vmap::AnyDescriptor any(vmap::XFeatDescriptor({.model = vmap::test::model_path("xfeat_320x224.onnx")}));
      const vmap::Features g = any.extract(frame), f = xfeat.extract(frame);
      REQUIRE(g.size() == f.size());
      CHECK(cv::norm(g.descriptors, f.descriptors, cv::NORM_INF) == 0.0);
    }
  }

  TEST_CASE("XFeat: wrong models, sizes and options are errors naming the file") {
    std::string e = error_of([] { vmap::XFeatDescriptor x({.model = vmap::test::model_path("yolox_nano.onnx")}); });
    CHECK(e.find("yolox_nano.onnx") != std::string::npos);
    CHECK(e.find("neither a fixed-size nor an any-size XFeat") != std::string::npos);
    MESSAGE(e);
    e = error_of([] {
      vmap::XFeatDescriptor x({.model = vmap::test::model_path("xfeat_320x224.onnx"), .input_size = {256, 256}});
    });
    CHECK(e.find("xfeat_320x224.onnx") != std::string::npos);
    CHECK(e.find("1x3x256x256") != std::string::npos);
    MESSAGE(e);
    for (const char* detector : {"FastestDet.onnx", "nanodet_m_320.onnx"}) {
      e = error_of([&] { vmap::XFeatDescriptor x({.model = vmap::test::model_path(detector)}); });
      CHECK(e.find(detector) != std::string::npos);
      CHECK(e.find("neither a fixed-size nor an any-size XFeat") != std::string::npos);
      MESSAGE(e);
    }
    // The any-size model takes multiples of 32 only.
    e = error_of([] {
      vmap::XFeatDescriptor x({.model = vmap::test::model_path("xfeat_anysize.onnx"), .input_size = {320, 240}});
    });
    CHECK(e.find("xfeat_anysize.onnx") != std::string::npos);
    CHECK(e.find("multiples of 32") != std::string::npos);
    e = error_of([] {
      vmap::XFeatDescriptor x({.model = vmap::test::model_path("xfeat_anysize.onnx")});
      (void)x.extract(cv::Mat(20, 100, CV_8UC1, cv::Scalar(7)));
    });
    CHECK(e.find("smaller than 32x32") != std::string::npos);
    e = error_of([] { vmap::XFeatDescriptor x({.model = "/nonexistent/xfeat.onnx"}); });
    CHECK(e.find("/nonexistent/xfeat.onnx") != std::string::npos);
    CHECK_THROWS_AS(vmap::XFeatDescriptor({.model = "x.onnx", .top_k = 0}), vmap::Error);
    CHECK_THROWS_AS(vmap::XFeatDescriptor({.model = "x.onnx", .input_size = {320, 0}}), vmap::Error);
  }
}

namespace {

/// The TUM frame the XFeat tests share (640x480 colour).
cv::Mat tum_frame() {
  cv::Mat img = cv::imread(vmap::test::data_path("tum_fr1_rpy/rgb/1305031253.529706.jpg").string());
  REQUIRE(img.size() == cv::Size(640, 480));
  return img;
}

/// Fraction of `a`'s keypoints that have a keypoint of `b` within `px` after mapping
/// a's point p to p * s (pixel centres kept: (p + 0.5) s - 0.5).
double repeated(const vmap::Features& a, const vmap::Features& b, double s, double px) {
  int hit = 0;
  for (const auto& k : a.keypoints) {
    const cv::Point2d p((k.pt.x + 0.5) * s - 0.5, (k.pt.y + 0.5) * s - 0.5);
    for (const auto& q : b.keypoints)
      if (std::hypot(q.pt.x - p.x, q.pt.y - p.y) <= px) {
        ++hit;
        break;
      }
  }
  return a.keypoints.empty() ? 0.0 : static_cast<double>(hit) / static_cast<double>(a.keypoints.size());
}

}  // namespace

TEST_SUITE("data") {
  TEST_CASE("XFeat model-size logic: fixed-size files keep their size, the any-size file follows the image") {
    const vmap::XFeatDescriptor small({.model = vmap::test::model_path("xfeat_320x224.onnx")});
    CHECK(small.model_kind() == vmap::XFeatModelKind::fixed_size);
    CHECK(small.declared_size() == cv::Size(320, 224));
    CHECK(small.network_size({640, 480}) == cv::Size(320, 224));
    CHECK(small.network_size({1226, 370}) == cv::Size(320, 224));
    const vmap::XFeatDescriptor vga({.model = vmap::test::model_path("xfeat_640x480.onnx")});
    CHECK(vga.model_kind() == vmap::XFeatModelKind::fixed_size);
    CHECK(vga.network_size({1226, 370}) == cv::Size(640, 480));
    const vmap::XFeatDescriptor kitti({.model = vmap::test::model_path("xfeat_1216x352.onnx")});
    CHECK(kitti.model_kind() == vmap::XFeatModelKind::fixed_size);
    CHECK(kitti.network_size({1226, 370}) == cv::Size(1216, 352));
    // A fixed-size model may be given its own size explicitly.
    const vmap::XFeatDescriptor same(
        {.model = vmap::test::model_path("xfeat_320x224.onnx"), .input_size = {320, 224}});
    CHECK(same.network_size({640, 480}) == cv::Size(320, 224));

    const vmap::XFeatDescriptor any({.model = vmap::test::model_path("xfeat_anysize.onnx")});
    CHECK(any.model_kind() == vmap::XFeatModelKind::any_size);
    CHECK(any.declared_size() == cv::Size(640, 480));
    CHECK(any.network_size({640, 480}) == cv::Size(640, 480));
    CHECK(any.network_size({1226, 370}) == cv::Size(1216, 352));  // largest multiples of 32 not above
    CHECK(any.network_size({100, 63}) == cv::Size(96, 32));
    CHECK(any.network_size({32, 32}) == cv::Size(32, 32));
    CHECK_THROWS_AS((void)any.network_size({31, 480}), vmap::Error);
    const vmap::XFeatDescriptor any_set(
        {.model = vmap::test::model_path("xfeat_anysize.onnx"), .input_size = {320, 224}});
    CHECK(any_set.model_kind() == vmap::XFeatModelKind::any_size);
    CHECK(any_set.network_size({640, 480}) == cv::Size(320, 224));
    CHECK(any_set.network_size({1226, 370}) == cv::Size(320, 224));
  }

  TEST_CASE("XFeat any-size on a KITTI frame: a centred crop, keypoints are exact pixels of the input") {
    const cv::Mat img =
        cv::imread(vmap::test::data_path("kitti07_160/image_0/000000.png").string(), cv::IMREAD_GRAYSCALE);
    REQUIRE(img.size() == cv::Size(1226, 370));
    vmap::XFeatDescriptor any({.model = vmap::test::model_path("xfeat_anysize.onnx"), .top_k = 2000});
    const vmap::Features f = any.extract(img);
    CHECK(f.image_size == img.size());
    // 1226 - 1216 = 10 columns and 370 - 352 = 18 rows are left out, half on each side:
    // the network sees exactly the crop at (5, 9), so its keypoints are the crop's
    // keypoints shifted by whole pixels, with the same descriptors.
    const vmap::Features g = any.extract(img(cv::Rect(5, 9, 1216, 352)).clone());
    REQUIRE(f.size() == 2000);
    REQUIRE(g.size() == f.size());
    int exact = 0;
    for (std::size_t i = 0; i < f.size(); ++i) {
      const cv::Point2f p = f.keypoints[i].pt, q = g.keypoints[i].pt;
      if (p.x == q.x + 5.0f && p.y == q.y + 9.0f) ++exact;
      CHECK(p.x == std::round(p.x));  // whole pixels of the input image
      CHECK(p.y == std::round(p.y));
    }
    CHECK(exact == static_cast<int>(f.size()));
    CHECK(cv::norm(f.descriptors, g.descriptors, cv::NORM_INF) == 0.0);
  }

  TEST_CASE("XFeat any-size equals the fixed-size files at their sizes") {
    const cv::Mat img = tum_frame();
    for (const auto& [file, size] : {std::pair{"xfeat_640x480.onnx", cv::Size(0, 0)},
                                     std::pair{"xfeat_320x224.onnx", cv::Size(320, 224)}}) {
      CAPTURE(file);
      vmap::XFeatDescriptor fixed({.model = vmap::test::model_path(file)});
      vmap::XFeatDescriptor any({.model = vmap::test::model_path("xfeat_anysize.onnx"), .input_size = size});
      const vmap::Features a = any.extract(img), b = fixed.extract(img);
      REQUIRE(a.size() == b.size());
      // The outputs agree within 2e-4 (models README): the same keypoints at the same
      // positions, except where that moves a score across the top-k cut.
      const double same = repeated(a, b, 1.0, 0.0);
      MESSAGE(file << ": " << same * 100.0 << " % of the any-size keypoints at the fixed-size positions");
      CHECK(same > 0.98);
    }
  }

  TEST_CASE("XFeat any-size at two sizes: the same keypoints on the same image content up to scaling") {
    const cv::Mat img = tum_frame();
    cv::Mat half;
    cv::resize(img, half, cv::Size(320, 240), 0, 0, cv::INTER_AREA);
    vmap::XFeatDescriptor any({.model = vmap::test::model_path("xfeat_anysize.onnx"), .top_k = 300});
    CHECK(any.network_size(half.size()) == cv::Size(320, 224));  // 8 rows cropped at top and bottom
    const vmap::Features small = any.extract(half);
    vmap::XFeatDescriptor dense({.model = vmap::test::model_path("xfeat_anysize.onnx"), .top_k = 4800});
    const vmap::Features full = dense.extract(img);
    REQUIRE(small.size() == 300);
    // The strongest 300 keypoints found at 320x240, scaled by 2, against every keypoint
    // found at 640x480: within one pixel of the small image (2 px here).
    const double rep = repeated(small, full, 2.0, 2.0);
    MESSAGE("any-size 320x224 vs 640x480: " << rep * 100.0 << " % of the keypoints repeated within 2 px");
    CHECK(rep > 0.6);
  }

  TEST_CASE("XFeat at native resolution on a synthetic homography pair: most correct matches within 1 px") {
    const cv::Mat img = tum_frame();
    const double cx = img.cols / 2.0, cy = img.rows / 2.0;
    const double a = 8.0 * CV_PI / 180.0, s = 0.9, p = 1e-5;
    const cv::Matx33d T1(1, 0, -cx, 0, 1, -cy, 0, 0, 1), T2(1, 0, cx + 10, 0, 1, cy - 5, 0, 0, 1);
    const cv::Matx33d R(s * std::cos(a), -s * std::sin(a), 0, s * std::sin(a), s * std::cos(a), 0, p, 2 * p, 1);
    const cv::Matx33d H = T2 * R * T1;
    cv::Mat warped;
    cv::warpPerspective(img, warped, cv::Mat(H), img.size(), cv::INTER_LINEAR, cv::BORDER_CONSTANT);
    const vmap::BruteForceMatcher matcher({.mode = vmap::MatchMode::mutual});
    double native1 = 0.0;
    for (const std::string file : {"xfeat_anysize.onnx", "xfeat_320x224.onnx"}) {
      CAPTURE(file);
      vmap::XFeatDescriptor xfeat({.model = vmap::test::model_path(file)});
      const vmap::Features fa = xfeat.extract(img), fb = xfeat.extract(warped);
      const vmap::Matches m = matcher.match(fa, fb);
      const double within1 = fraction_within(fa, fb, m, H, 1.0), within3 = fraction_within(fa, fb, m, H, 3.0);
      MESSAGE(file << " on 640x480: " << m.size() << " mutual matches, " << within1 * 100.0 << " % within 1 px, "
                   << within3 * 100.0 << " % within 3 px");
      if (file == "xfeat_anysize.onnx") {
        CHECK(xfeat.network_size(img.size()) == img.size());
        CHECK(m.size() > 500);
        // Whole-pixel keypoints (no sub-pixel refinement, as XFeat's detectAndCompute):
        // of the matches that are right (within 3 px), most are within 1 px.
        CHECK(within3 > 0.75);
        CHECK(within1 / within3 > 0.5);
        native1 = within1;
      } else {
        CHECK(within1 * 3.0 < native1);  // keypoints 2 image px apart cannot be as exact
      }
    }
  }
}
