#pragma once

// Deterministic textured test images (no files needed).

#include <opencv2/core.hpp>
#include <opencv2/imgproc.hpp>

#include <cstdint>

namespace vmap::test {

/// A 640x480 grey image of random blobs, boxes and lines: plenty of corners at every scale.
inline cv::Mat textured_image(std::uint64_t seed = 3, cv::Size size = {640, 480}) {
  cv::RNG rng(seed);
  cv::Mat img(size, CV_8UC1, cv::Scalar(90));
  for (int i = 0; i < 400; ++i) {
    const cv::Point c(rng.uniform(0, size.width), rng.uniform(0, size.height));
    const cv::Scalar v(rng.uniform(0, 256));
    switch (rng.uniform(0, 3)) {
      case 0: cv::circle(img, c, rng.uniform(3, 25), v, -1); break;
      case 1: cv::rectangle(img, c, c + cv::Point(rng.uniform(4, 40), rng.uniform(4, 40)), v, -1); break;
      default: cv::line(img, c, c + cv::Point(rng.uniform(-60, 60), rng.uniform(-60, 60)), v, rng.uniform(1, 4)); break;
    }
  }
  cv::GaussianBlur(img, img, cv::Size(3, 3), 0.8);
  return img;
}

/// Frame k of a test sequence: a 64x48 textured image (seed `seed + k`) whose top-left
/// pixel encodes k.
inline cv::Mat numbered_image(int k, std::uint64_t seed) {
  cv::Mat img = textured_image(static_cast<std::uint64_t>(k) + seed, {64, 48});
  img.at<std::uint8_t>(0, 0) = static_cast<std::uint8_t>(k);
  return img;
}

}  // namespace vmap::test
