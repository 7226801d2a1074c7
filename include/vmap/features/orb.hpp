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

/// Options of the ORB detector/descriptor (Rublee et al. 2011), OpenCV's defaults
/// except the feature count, which follows the visual-map paper's experiments (1000).
struct OrbOptions {
  int features = 1000;        ///< maximum number of keypoints kept, <= max_keypoint_budget
  float scale_factor = 1.2f;  ///< pyramid decimation ratio, > 1
  int levels = 8;             ///< pyramid levels, >= 1
  int edge_threshold = 31;    ///< border where no keypoint is detected, in pixels
  int fast_threshold = 20;    ///< FAST corner threshold (intensity difference)
};

/// ORB keypoints + 256-bit binary descriptors, compared by Hamming distance.
/// Deep copy: a copy owns its own cv::ORB, re-created from the options (cheap), and
/// its own buffers, so per-thread copies (e.g. a std::vector of them) run in parallel.
/// One object serves one thread at a time.
class OrbDescriptor {
 public:
  explicit OrbDescriptor(const OrbOptions& options = {}) : options_(options) {
    const auto& o = options_;
    detail::check_keypoint_budget(o.features, 1, "OrbOptions.features");
    detail::check(std::isfinite(o.scale_factor) && o.scale_factor > 1.0f,
                  "OrbOptions.scale_factor must be a finite number > 1, got " + std::to_string(o.scale_factor));
    detail::check(o.levels >= 1, "OrbOptions.levels must be >= 1, got " + std::to_string(o.levels));
    detail::check(o.edge_threshold >= 0, "OrbOptions.edge_threshold must be >= 0");
    detail::check(o.fast_threshold > 0, "OrbOptions.fast_threshold must be > 0");
    orb_ = cv::ORB::create(o.features, o.scale_factor, o.levels, o.edge_threshold, 0, 2,
                           cv::ORB::HARRIS_SCORE, o.edge_threshold, o.fast_threshold);
  }

  /// A copy creates its own OpenCV detector from the options (a cv::Ptr copy would
  /// share one detector, so per-thread copies would race on it) and its own buffers.
  OrbDescriptor(const OrbDescriptor& other) : OrbDescriptor(other.options_) {}
  OrbDescriptor& operator=(const OrbDescriptor& other) {
    if (this != &other) *this = OrbDescriptor(other);
    return *this;
  }
  OrbDescriptor(OrbDescriptor&&) noexcept = default;
  OrbDescriptor& operator=(OrbDescriptor&&) noexcept = default;
  ~OrbDescriptor() = default;

  [[nodiscard]] Features extract(const cv::Mat& image) {
    return detail::detect_and_compute(*orb_, image, grey_, cv::NORM_HAMMING, "ORB extract");
  }

  [[nodiscard]] const OrbOptions& options() const noexcept { return options_; }

  /// The name and every option (core/concepts.hpp, DescribesItself).
  [[nodiscard]] std::string describe() const {
    const OrbOptions& o = options_;
    return "OrbDescriptor features=" + std::to_string(o.features) + " scale_factor=" + exact_text(o.scale_factor) +
           " levels=" + std::to_string(o.levels) + " edge_threshold=" + std::to_string(o.edge_threshold) +
           " fast_threshold=" + std::to_string(o.fast_threshold);
  }

  /// 256-bit binary descriptors: 32 bytes, Hamming.
  [[nodiscard]] static DescriptorLayout layout() noexcept { return {CV_8UC1, 32, cv::NORM_HAMMING}; }

 private:
  OrbOptions options_;
  cv::Ptr<cv::ORB> orb_;
  cv::Mat grey_;  // reused between frames
};

static_assert(Descriptor<OrbDescriptor>);

}  // namespace vmap
