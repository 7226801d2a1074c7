#pragma once

// Greedy class-wise non-maximum suppression for the detector adapters: the networks
// predict one box per grid cell, so one object yields several overlapping boxes.

#include <vmap/core/error.hpp>
#include <vmap/hooks/detection.hpp>

#include <opencv2/core.hpp>

#include <algorithm>
#include <cmath>
#include <string>
#include <vector>

namespace vmap {

/// Intersection over union of two boxes; 0 when either box has no area.
[[nodiscard]] inline float iou(const cv::Rect2f& a, const cv::Rect2f& b) noexcept {
  const float ix = std::max(0.0f, std::min(a.x + a.width, b.x + b.width) - std::max(a.x, b.x));
  const float iy = std::max(0.0f, std::min(a.y + a.height, b.y + b.height) - std::max(a.y, b.y));
  const float inter = ix * iy;
  const float uni = a.width * a.height + b.width * b.height - inter;
  return uni > 0.0f ? inter / uni : 0.0f;
}

struct NmsOptions {
  float iou_threshold = 0.45f;  ///< a box overlapping a kept box of its class by more is dropped, in [0, 1]
  int max_detections = 100;     ///< at most this many boxes are kept (highest scores), >= 1
};

/// Class-wise greedy NMS: boxes are visited by decreasing score (ties: lower label,
/// then smaller x, y, so the result does not depend on the input order); a box is kept
/// unless it overlaps an already kept box of the same label by more than
/// `iou_threshold`. Boxes of different labels never suppress each other (a person on a
/// chair keeps both). Returns the kept boxes by decreasing score.
[[nodiscard]] inline std::vector<Detection> nms(std::vector<Detection> detections, const NmsOptions& options = {}) {
  detail::check(std::isfinite(options.iou_threshold) && options.iou_threshold >= 0.0f && options.iou_threshold <= 1.0f,
                "NmsOptions.iou_threshold must be in [0, 1], got " + std::to_string(options.iou_threshold));
  detail::check(options.max_detections >= 1,
                "NmsOptions.max_detections must be >= 1, got " + std::to_string(options.max_detections));
  std::sort(detections.begin(), detections.end(), [](const Detection& a, const Detection& b) {
    if (a.score != b.score) return a.score > b.score;
    if (a.label != b.label) return a.label < b.label;
    if (a.box.x != b.box.x) return a.box.x < b.box.x;
    return a.box.y < b.box.y;
  });
  std::vector<Detection> kept;
  for (const Detection& d : detections) {
    if (static_cast<int>(kept.size()) >= options.max_detections) break;
    const bool suppressed = std::any_of(kept.begin(), kept.end(), [&](const Detection& k) {
      return k.label == d.label && iou(k.box, d.box) > options.iou_threshold;
    });
    if (!suppressed) kept.push_back(d);
  }
  return kept;
}

}  // namespace vmap
