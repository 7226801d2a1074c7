#pragma once

// A detector chosen at run time (a command-line flag, a config file) behind one type.
// Type erasure costs one indirect call per image; decoding, NMS and every per-box loop
// run inside the concrete adapter, statically dispatched.

#include <vmap/core/error.hpp>
#include <vmap/hooks/detection.hpp>

#include <opencv2/core.hpp>

#include <concepts>
#include <memory>
#include <type_traits>
#include <utility>
#include <vector>

namespace vmap {

/// Holds any ObjectDetector by value. Move-only: it may hold a detector that cannot be
/// copied (a CallbackDetector around a move-only runtime session), so it promises no
/// copy. For one detector per thread, copy the concrete adapter (the cv::dnn ones
/// deep-copy) before erasing it, or call make_dnn_detector once per thread. A moved-from
/// AnyDetector is empty and `detect` on it is an Error. One object serves one thread at
/// a time.
class AnyDetector {
 public:
  template <ObjectDetector D>
    requires(!std::same_as<std::remove_cvref_t<D>, AnyDetector>)
  explicit AnyDetector(D detector) : self_(std::make_unique<Model<D>>(std::move(detector))) {}

  AnyDetector(AnyDetector&&) noexcept = default;
  AnyDetector& operator=(AnyDetector&&) noexcept = default;

  [[nodiscard]] std::vector<Detection> detect(const cv::Mat& image) {
    detail::check(self_ != nullptr, "AnyDetector: detect() on an empty (moved-from) detector");
    return self_->detect(image);
  }

  [[nodiscard]] bool has_value() const noexcept { return self_ != nullptr; }

  /// The held detector if it is a D, else nullptr.
  template <ObjectDetector D>
  [[nodiscard]] D* target() noexcept {
    auto* m = dynamic_cast<Model<D>*>(self_.get());
    return m ? &m->detector : nullptr;
  }

 private:
  struct Interface {
    virtual ~Interface() = default;
    virtual std::vector<Detection> detect(const cv::Mat& image) = 0;
  };
  template <class D>
  struct Model final : Interface {
    explicit Model(D d) : detector(std::move(d)) {}
    std::vector<Detection> detect(const cv::Mat& image) override { return detector.detect(image); }
    D detector;
  };
  std::unique_ptr<Interface> self_;
};

static_assert(ObjectDetector<AnyDetector>);

}  // namespace vmap
