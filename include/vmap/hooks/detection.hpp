#pragma once

// The object-detector hook (examples/methods.md, sec. 7): LFM-LCD tags every key frame with the
// labels a detector finds. vmap runs networks, it does not train them; any runtime fits
// behind this concept (cv::dnn adapters, a callback over TensorRT/ONNX Runtime/ROS, a
// file of precomputed detections).

#include <opencv2/core.hpp>

#include <concepts>
#include <vector>

namespace vmap {

/// One detected object: class id (e.g. a COCO-80 index), confidence in [0, 1], and its
/// box in the input image's pixels (x, y = top-left corner).
struct Detection {
  int label = -1;
  float score = 0.0f;
  cv::Rect2f box;
};

/// `d.detect(image)` returns the objects found in one image. Not required to be const:
/// network runtimes keep buffers, so one detector object serves one thread at a time.
template <class D>
concept DetectsObjects = requires(D& d, const cv::Mat& image) {
  { d.detect(image) } -> std::same_as<std::vector<Detection>>;
};

template <class D>
concept ObjectDetector = std::move_constructible<D>  // held by value
                         && DetectsObjects<D>;       // std::vector<Detection> detect(const cv::Mat&)

}  // namespace vmap
