#pragma once

#include <vmap/core/concepts.hpp>
#include <vmap/core/error.hpp>
#include <vmap/core/numeric.hpp>
#include <vmap/features/budget.hpp>
#include <vmap/features/detail/grey.hpp>

#include <opencv2/features2d.hpp>

#include <cmath>
#include <string>

namespace vmap {

/// Options of SIFT (Lowe 2004), OpenCV's defaults except a bounded feature count.
struct SiftOptions {
  int features = 1000;                ///< keypoints kept (best first); 0 keeps all; <= max_keypoint_budget
  int octave_layers = 3;              ///< layers per octave, >= 1
  double contrast_threshold = 0.04;   ///< > 0
  double edge_threshold = 10.0;       ///< > 0
  double sigma = 1.6;                 ///< Gaussian of the first octave, > 0
};

/// SIFT keypoints + 128-float descriptors, compared by L2 distance.
/// Deep copy: a copy owns its own cv::SIFT, re-created from the options, and its own
/// buffers, so per-thread copies run in parallel. One object serves one thread at a time.
class SiftDescriptor {
 public:
  explicit SiftDescriptor(const SiftOptions& options = {}) : options_(options) {
    const auto& o = options_;
    detail::check_keypoint_budget(o.features, 0, "SiftOptions.features");
    detail::check(o.octave_layers >= 1, "SiftOptions.octave_layers must be >= 1");
    detail::check(std::isfinite(o.contrast_threshold) && o.contrast_threshold > 0,
                  "SiftOptions.contrast_threshold must be a finite number > 0");
    detail::check(std::isfinite(o.edge_threshold) && o.edge_threshold > 0,
                  "SiftOptions.edge_threshold must be a finite number > 0");
    detail::check(std::isfinite(o.sigma) && o.sigma > 0, "SiftOptions.sigma must be a finite number > 0");
    sift_ = cv::SIFT::create(o.features, o.octave_layers, o.contrast_threshold, o.edge_threshold,
                             o.sigma);
  }

  /// A copy creates its own OpenCV detector from the options (a cv::Ptr copy would
  /// share one detector, so per-thread copies would race on it) and its own buffers.
  SiftDescriptor(const SiftDescriptor& other) : SiftDescriptor(other.options_) {}
  SiftDescriptor& operator=(const SiftDescriptor& other) {
    if (this != &other) *this = SiftDescriptor(other);
    return *this;
  }
  SiftDescriptor(SiftDescriptor&&) noexcept = default;
  SiftDescriptor& operator=(SiftDescriptor&&) noexcept = default;
  ~SiftDescriptor() = default;

  [[nodiscard]] Features extract(const cv::Mat& image) {
    return detail::detect_and_compute(*sift_, image, grey_, cv::NORM_L2, "SIFT extract");
  }

  [[nodiscard]] const SiftOptions& options() const noexcept { return options_; }

  /// The name and every option (core/concepts.hpp, DescribesItself).
  [[nodiscard]] std::string describe() const {
    const SiftOptions& o = options_;
    return "SiftDescriptor features=" + std::to_string(o.features) + " octave_layers=" +
           std::to_string(o.octave_layers) + " contrast_threshold=" + exact_text(o.contrast_threshold) +
           " edge_threshold=" + exact_text(o.edge_threshold) + " sigma=" + exact_text(o.sigma);
  }

  /// 128 floats, L2.
  [[nodiscard]] static DescriptorLayout layout() noexcept { return {CV_32FC1, 128, cv::NORM_L2}; }

 private:
  SiftOptions options_;
  cv::Ptr<cv::SIFT> sift_;
  cv::Mat grey_;
};

static_assert(Descriptor<SiftDescriptor>);

}  // namespace vmap
