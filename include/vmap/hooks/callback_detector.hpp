#pragma once

// The callback adapter of the object-detector hook (examples/methods.md, sec. 7): any callable
// `std::vector<Detection>(const cv::Mat&)` becomes an ObjectDetector, so a user plugs in
// TensorRT, ONNX Runtime, LibTorch or a ROS service without writing a class.

#include <vmap/hooks/detection.hpp>

#include <opencv2/core.hpp>

#include <concepts>
#include <functional>
#include <type_traits>
#include <utility>
#include <vector>

namespace vmap {

/// A callable that maps an image to its detections.
template <class F>
concept DetectionCallback = std::move_constructible<F>  // held by value
                            && std::invocable<F&, const cv::Mat&>  // called as f(image)
                            && std::convertible_to<std::invoke_result_t<F&, const cv::Mat&>,
                                                   std::vector<Detection>>;  // returns detections

/// Wraps a callable as an ObjectDetector. The callable is held by value and called on
/// every `detect`; thread-safety is the callable's own (one object per thread unless the
/// callable says otherwise).
template <DetectionCallback F>
class CallbackDetector {
 public:
  explicit CallbackDetector(F callback) : callback_(std::move(callback)) {}

  [[nodiscard]] std::vector<Detection> detect(const cv::Mat& image) { return callback_(image); }

  [[nodiscard]] const F& callback() const noexcept { return callback_; }

 private:
  F callback_;
};

/// The type-erased form, for detectors chosen at run time.
using FunctionDetector = CallbackDetector<std::function<std::vector<Detection>(const cv::Mat&)>>;

static_assert(ObjectDetector<FunctionDetector>);

}  // namespace vmap
