#pragma once

#include <opencv2/core.hpp>

#include <cstddef>
#include <vector>

namespace vmap {

/// Keypoints and their descriptors for one image. Row i of `descriptors` describes
/// `keypoints[i]`; `norm` (a cv::NormTypes value) is how two descriptors compare, so a
/// matcher never has to guess it from the matrix type.
struct Features {
  std::vector<cv::KeyPoint> keypoints;
  cv::Mat descriptors;
  int norm = cv::NORM_HAMMING;
  cv::Size image_size;

  [[nodiscard]] std::size_t size() const noexcept { return keypoints.size(); }
  [[nodiscard]] bool empty() const noexcept { return keypoints.empty(); }
};

/// Putative correspondences: queryIdx indexes the first Features, trainIdx the second.
using Matches = std::vector<cv::DMatch>;

}  // namespace vmap
