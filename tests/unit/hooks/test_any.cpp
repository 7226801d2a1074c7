// Type-erased AnyDetector / AnyDescriptor.
#include <vmap/features/orb.hpp>
#include <vmap/features/sift.hpp>
#include <vmap/hooks/any_descriptor.hpp>
#include <vmap/hooks/any_detector.hpp>

#include <doctest/doctest.h>

#include <memory>
#include <utility>
#include <vector>

namespace {

struct FixedDetector {
  std::shared_ptr<int> calls = std::make_shared<int>(0);
  std::vector<vmap::Detection> detect(const cv::Mat& image) {
    ++*calls;
    return {{7, 0.75f, cv::Rect2f(1, 2, static_cast<float>(image.cols) / 2, 4)}};
  }
};

struct NotADetector {
  int detect(const cv::Mat&) { return 0; }
};

cv::Mat textured(int seed) {
  cv::Mat img(240, 320, CV_8UC1);
  cv::RNG rng(static_cast<std::uint64_t>(seed));
  rng.fill(img, cv::RNG::UNIFORM, 0, 255);
  cv::GaussianBlur(img, img, cv::Size(5, 5), 1.5);
  return img;
}

}  // namespace

static_assert(vmap::ObjectDetector<vmap::AnyDetector>);
static_assert(vmap::Descriptor<vmap::AnyDescriptor>);
static_assert(!std::is_constructible_v<vmap::AnyDetector, NotADetector>);
static_assert(!std::is_constructible_v<vmap::AnyDescriptor, FixedDetector>);
static_assert(!std::is_copy_constructible_v<vmap::AnyDetector>);

TEST_CASE("AnyDetector forwards to the held detector; moved-from is an error") {
  FixedDetector fixed;
  const auto calls = fixed.calls;
  vmap::AnyDetector any(std::move(fixed));
  const auto dets = any.detect(cv::Mat(10, 40, CV_8UC3, cv::Scalar::all(0)));
  REQUIRE(dets.size() == 1);
  CHECK(dets[0].label == 7);
  CHECK(dets[0].score == 0.75f);
  CHECK(dets[0].box.width == 20.0f);
  CHECK(*calls == 1);
  REQUIRE(any.target<FixedDetector>() != nullptr);
  CHECK(*any.target<FixedDetector>()->calls == 1);

  vmap::AnyDetector other = std::move(any);
  CHECK(other.has_value());
  CHECK_FALSE(any.has_value());  // NOLINT(bugprone-use-after-move): the documented moved-from state
  CHECK_THROWS_AS((void)any.detect(cv::Mat(10, 10, CV_8UC3)), vmap::Error);
  (void)other.detect(cv::Mat(10, 10, CV_8UC3, cv::Scalar::all(0)));
  CHECK(*calls == 2);
}

TEST_CASE("AnyDescriptor gives exactly what the held policy gives") {
  const cv::Mat img = textured(3);
  vmap::OrbDescriptor direct({.features = 300});
  const vmap::Features want = direct.extract(img);
  vmap::AnyDescriptor any(vmap::OrbDescriptor({.features = 300}));
  const vmap::Features got = any.extract(img);
  REQUIRE(got.size() == want.size());
  REQUIRE(got.size() > 50);
  CHECK(got.norm == cv::NORM_HAMMING);
  CHECK(cv::norm(got.descriptors, want.descriptors, cv::NORM_L1) == 0.0);
  CHECK(got.keypoints[10].pt == want.keypoints[10].pt);
  CHECK(any.target<vmap::OrbDescriptor>() != nullptr);
  CHECK(any.target<vmap::SiftDescriptor>() == nullptr);

  vmap::AnyDescriptor moved = std::move(any);
  CHECK_THROWS_AS((void)any.extract(img), vmap::Error);  // NOLINT(bugprone-use-after-move)
  CHECK(moved.extract(img).size() == want.size());
}
