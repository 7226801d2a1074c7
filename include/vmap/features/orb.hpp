#pragma once

#include <vmap/core/concepts.hpp>
#include <vmap/core/error.hpp>
#include <vmap/core/numeric.hpp>
#include <vmap/features/budget.hpp>
#include <vmap/features/detail/grey.hpp>

#include <opencv2/features2d.hpp>

#include <algorithm>
#include <cmath>
#include <string>

namespace vmap {

/// ORB on small images. The border where ORB detects nothing is also the side of the
/// patch its descriptor compares (edge_threshold): 31 pixels leave 98 x 58 of a 160 x 120
/// image, and a textureless view keeps a handful of corners at FAST's 20. An image whose
/// shorter side is at most `max_side` pixels is described with a 15-pixel border and
/// patch and a FAST threshold of 10 instead, which on every shared sequence at 160 pixels
/// wide keeps precision at 1.0 and finds more loops and places (examples/results/loops.md,
/// "Small images"; bench_places section 9). At 320 x 240 it helped the shared sequences
/// too, but 15-pixel patches failed the flat-shape synthetic scenes of the tests, so the
/// rule starts below that size.
struct OrbSmallImages {
  int max_side = 200;       ///< a shorter side of at most this many pixels is small; 0: no image is
  int edge_threshold = 15;  ///< border and patch for small images, in pixels
  int fast_threshold = 10;  ///< FAST threshold for small images

  friend bool operator==(const OrbSmallImages&, const OrbSmallImages&) = default;
};

/// Options of the ORB detector/descriptor (Rublee et al. 2011), OpenCV's defaults
/// except the feature count, which follows the visual-map paper's experiments (1000),
/// and small images (OrbSmallImages).
struct OrbOptions {
  int features = 1000;        ///< maximum number of keypoints kept, <= max_keypoint_budget
  float scale_factor = 1.2f;  ///< pyramid decimation ratio, > 1
  int levels = 8;             ///< pyramid levels, >= 1
  int edge_threshold = 31;    ///< border where no keypoint is detected (and patch side), in pixels
  int fast_threshold = 20;    ///< FAST corner threshold (intensity difference)
  OrbSmallImages small{};     ///< the border and FAST threshold of small images
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
    detail::check(o.small.max_side >= 0, "OrbOptions.small.max_side must be >= 0");
    detail::check(o.small.edge_threshold >= 0, "OrbOptions.small.edge_threshold must be >= 0");
    detail::check(o.small.fast_threshold > 0, "OrbOptions.small.fast_threshold must be > 0");
    orb_ = cv::ORB::create(o.features, o.scale_factor, o.levels, o.edge_threshold, 0, 2,
                           cv::ORB::HARRIS_SCORE, o.edge_threshold, o.fast_threshold);
    if (o.small.max_side > 0)
      small_ = cv::ORB::create(o.features, o.scale_factor, o.levels, o.small.edge_threshold, 0, 2,
                               cv::ORB::HARRIS_SCORE, o.small.edge_threshold, o.small.fast_threshold);
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
    cv::ORB& orb = small(image.size()) ? *small_ : *orb_;
    return detail::detect_and_compute(orb, image, grey_, cv::NORM_HAMMING, "ORB extract");
  }

  /// Whether an image of this size is described as a small one (OrbSmallImages).
  [[nodiscard]] bool small(cv::Size size) const noexcept {
    return options_.small.max_side > 0 && std::min(size.width, size.height) <= options_.small.max_side;
  }

  [[nodiscard]] const OrbOptions& options() const noexcept { return options_; }

  /// The name and every option (core/concepts.hpp, DescribesItself). The small-image
  /// options are written only when they are not the defaults, so that the descriptions
  /// memories recorded before them still name this descriptor.
  [[nodiscard]] std::string describe() const {
    const OrbOptions& o = options_;
    std::string d = "OrbDescriptor features=" + std::to_string(o.features) + " scale_factor=" +
                    exact_text(o.scale_factor) + " levels=" + std::to_string(o.levels) +
                    " edge_threshold=" + std::to_string(o.edge_threshold) + " fast_threshold=" +
                    std::to_string(o.fast_threshold);
    if (!(o.small == OrbSmallImages{}))
      d += " small_max_side=" + std::to_string(o.small.max_side) + " small_edge_threshold=" +
           std::to_string(o.small.edge_threshold) + " small_fast_threshold=" + std::to_string(o.small.fast_threshold);
    return d;
  }

  /// 256-bit binary descriptors: 32 bytes, Hamming.
  [[nodiscard]] static DescriptorLayout layout() noexcept { return {CV_8UC1, 32, cv::NORM_HAMMING}; }

 private:
  OrbOptions options_;
  cv::Ptr<cv::ORB> orb_;
  cv::Ptr<cv::ORB> small_;  // for small images; empty when options_.small.max_side is 0
  cv::Mat grey_;  // reused between frames
};

static_assert(Descriptor<OrbDescriptor>);

}  // namespace vmap
