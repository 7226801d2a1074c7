#pragma once

#include <opencv2/core.hpp>

#include <cstddef>
#include <cstring>
#include <string>
#include <tuple>
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

/// What each descriptor row of a Descriptor looks like: its OpenCV type (CV_8UC1 for
/// binary, CV_32FC1 for float), its width in elements, and the norm that compares two.
struct DescriptorLayout {
  int type = CV_8UC1;
  int cols = 0;
  int norm = cv::NORM_HAMMING;

  friend bool operator==(const DescriptorLayout&, const DescriptorLayout&) = default;
};

/// The layout of `f`'s descriptors (their type, width and norm).
[[nodiscard]] inline DescriptorLayout layout_of(const Features& f) {
  return {f.descriptors.type(), f.descriptors.cols, f.norm};
}

/// "8U x 32, Hamming": a layout as it reads in a message.
[[nodiscard]] inline std::string to_string(const DescriptorLayout& l) {
  const char* norm = l.norm == cv::NORM_HAMMING ? "Hamming" : l.norm == cv::NORM_L2 ? "L2" : "another norm";
  return cv::typeToString(l.type) + " x " + std::to_string(l.cols) + ", " + norm;
}

/// Putative correspondences: queryIdx indexes the first Features, trainIdx the second.
using Matches = std::vector<cv::DMatch>;

namespace detail {

/// An order of features by their content (descriptor count and shape, the descriptors'
/// bytes, the keypoints' positions): which of two images a verification takes as its
/// query when its answer must be the pair's, not the asker's (VisualMemory::link_pair).
/// Equal content compares equal, and then either order gives the same answer.
[[nodiscard]] inline bool features_before(const Features& a, const Features& b) {
  const cv::Mat& x = a.descriptors;
  const cv::Mat& y = b.descriptors;
  const auto shape = [](const Features& f) {
    return std::tuple(f.keypoints.size(), f.descriptors.rows, f.descriptors.cols, f.descriptors.type());
  };
  if (shape(a) != shape(b)) return shape(a) < shape(b);
  const std::size_t row = static_cast<std::size_t>(x.cols) * x.elemSize();
  for (int r = 0; r < x.rows; ++r)
    if (const int c = std::memcmp(x.ptr(r), y.ptr(r), row); c != 0) return c < 0;
  for (std::size_t i = 0; i < a.keypoints.size(); ++i) {
    const cv::Point2f p = a.keypoints[i].pt, q = b.keypoints[i].pt;
    if (p.x != q.x) return p.x < q.x;
    if (p.y != q.y) return p.y < q.y;
  }
  return false;
}

}  // namespace detail

}  // namespace vmap
