#pragma once

#include <vmap/core/concepts.hpp>
#include <vmap/core/error.hpp>
#include <vmap/core/numeric.hpp>
#include <vmap/features/detail/grey.hpp>

#include <opencv2/features2d.hpp>

#include <cmath>
#include <string>

namespace vmap {

/// Options of A-KAZE (Alcantarilla et al. 2013) with the binary M-LDB descriptor.
struct AkazeOptions {
  float threshold = 0.001f;  ///< detector response threshold, > 0
  int octaves = 4;           ///< maximum octave evolution, >= 1
  int octave_layers = 4;     ///< sublevels per octave, >= 1
};

/// A-KAZE keypoints + 486-bit M-LDB descriptors, compared by Hamming distance; the
/// feature of the GCS localization paper (Trujillo-Romero 2024).
/// Deep copy: a copy owns its own cv::AKAZE, re-created from the options, and its own
/// buffers, so per-thread copies run in parallel. One object serves one thread at a time.
class AkazeDescriptor {
 public:
  explicit AkazeDescriptor(const AkazeOptions& options = {}) : options_(options) {
    const auto& o = options_;
    detail::check(std::isfinite(o.threshold) && o.threshold > 0.0f,
                  "AkazeOptions.threshold must be a finite number > 0, got " + std::to_string(o.threshold));
    detail::check(o.octaves >= 1, "AkazeOptions.octaves must be >= 1, got " + std::to_string(o.octaves));
    detail::check(o.octave_layers >= 1,
                  "AkazeOptions.octave_layers must be >= 1, got " + std::to_string(o.octave_layers));
    akaze_ = cv::AKAZE::create(cv::AKAZE::DESCRIPTOR_MLDB, 0, 3, o.threshold, o.octaves,
                               o.octave_layers, cv::KAZE::DIFF_PM_G2);
  }

  /// A copy creates its own OpenCV detector from the options (a cv::Ptr copy would
  /// share one detector, so per-thread copies would race on it) and its own buffers.
  AkazeDescriptor(const AkazeDescriptor& other) : AkazeDescriptor(other.options_) {}
  AkazeDescriptor& operator=(const AkazeDescriptor& other) {
    if (this != &other) *this = AkazeDescriptor(other);
    return *this;
  }
  AkazeDescriptor(AkazeDescriptor&&) noexcept = default;
  AkazeDescriptor& operator=(AkazeDescriptor&&) noexcept = default;
  ~AkazeDescriptor() = default;

  [[nodiscard]] Features extract(const cv::Mat& image) {
    return detail::detect_and_compute(*akaze_, image, grey_, cv::NORM_HAMMING, "A-KAZE extract");
  }

  [[nodiscard]] const AkazeOptions& options() const noexcept { return options_; }

  /// The name and every option (core/concepts.hpp, DescribesItself).
  [[nodiscard]] std::string describe() const {
    const AkazeOptions& o = options_;
    return "AkazeDescriptor threshold=" + exact_text(o.threshold) + " octaves=" + std::to_string(o.octaves) +
           " octave_layers=" + std::to_string(o.octave_layers);
  }

  /// Full M-LDB over 3 channels: 486 bits in 61 bytes, Hamming.
  [[nodiscard]] static DescriptorLayout layout() noexcept { return {CV_8UC1, 61, cv::NORM_HAMMING}; }

 private:
  AkazeOptions options_;
  cv::Ptr<cv::AKAZE> akaze_;
  cv::Mat grey_;
};

static_assert(Descriptor<AkazeDescriptor>);

}  // namespace vmap
