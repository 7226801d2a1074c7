#pragma once

// Synthetic loop-closure scenes shared by the loop-detector tests: textured "places"
// (random filled shapes, distinct per seed) visited on two laps, the second lap seeing
// each place slightly rotated and scaled, so that lap-2 frame k closes a loop with
// frame k - places.

#include <opencv2/core.hpp>
#include <opencv2/imgproc.hpp>

#include <cstdint>

namespace vmap::test {

inline cv::Mat place_image(std::uint64_t seed) {
  cv::RNG rng(seed);
  cv::Mat img(240, 320, CV_8U, cv::Scalar(rng.uniform(40, 200)));
  for (int k = 0; k < 70; ++k) {
    const cv::Point c(rng.uniform(0, 320), rng.uniform(0, 240));
    const cv::Scalar colour(rng.uniform(0, 256));
    if (k % 2 == 0)
      cv::circle(img, c, rng.uniform(4, 25), colour, cv::FILLED);
    else
      cv::rectangle(img, cv::Rect(c, cv::Size(rng.uniform(6, 40), rng.uniform(6, 40))), colour, cv::FILLED);
  }
  return img;
}

/// Frame k of two laps over `places` places whose images use seeds seed0 + place.
inline cv::Mat lap_frame(int k, int places, std::uint64_t seed0) {
  const cv::Mat base = place_image(seed0 + static_cast<std::uint64_t>(k % places));
  if (k < places) return base;
  const cv::Mat warp = cv::getRotationMatrix2D(cv::Point2f(160, 120), 4.0, 1.03);
  cv::Mat out;
  cv::warpAffine(base, out, warp, base.size(), cv::INTER_LINEAR, cv::BORDER_REFLECT);
  return out;
}

}  // namespace vmap::test
