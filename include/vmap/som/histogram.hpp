#pragma once

// Image feature vectors for the GCS map ("BuildHistos" of Trujillo-Romero 2024,
// examples/methods.md, sec. 3 step 3): a fixed-length vector from an image's A-KAZE keypoints
// and descriptors. Two policies:
//  - BowHistogram: bag of binary words over a vocabulary learned from the training
//    images (k-majority: the flat, depth-1 place/vocabulary.hpp tree), L1- or
//    L2-normalised word counts;
//  - GridHistogram: a cheaper spatial grid of keypoint counts and mean responses,
//    nothing to learn.

#include <vmap/core/error.hpp>
#include <vmap/core/features.hpp>
#include <vmap/place/vocabulary.hpp>
#include <vmap/som/options.hpp>

#include <Eigen/Core>

#include <algorithm>
#include <concepts>
#include <cstddef>
#include <cstdint>
#include <string>
#include <vector>

namespace vmap {

/// A histogram policy: `fit(training features)` learns what it needs (may be nothing),
/// then `h(features)` gives a vector of `h.dimension()` floats. `h(features)` is const
/// and thread-safe.
template <class H>
concept FeatureHistogram =
    std::move_constructible<H>  // held by value
    && requires(H& h, const std::vector<Features>& training) { h.fit(training); }  // learn from the training set
    && requires(const H& h, const Features& f) {
         { h(f) } -> std::same_as<Eigen::VectorXf>;                // the vector of one image
         { h.dimension() } -> std::convertible_to<std::size_t>;  // its length (0 before fit)
       };

namespace detail {
inline void normalise(Eigen::VectorXf& v, HistogramNorm n) {
  const float s = n == HistogramNorm::l1 ? v.lpNorm<1>() : v.norm();
  if (s > 0.0f) v /= s;
}
}  // namespace detail

namespace detail {
/// BowHistogramOptions a histogram can learn with, or an Error naming the option.
inline void check_bow_histogram_options(const BowHistogramOptions& o) {
  check(o.vocabulary.depth == 1, [&] {
    return "BowHistogramOptions.vocabulary.depth must be 1 (the histogram's vocabulary is flat), got " +
           std::to_string(o.vocabulary.depth);
  });
  try {
    check_vocabulary_tree_options(o.vocabulary);
  } catch (const Error& e) {
    fail(e.kind(), std::string("BowHistogramOptions.vocabulary: ") + e.what());
  }
}
}  // namespace detail

/// Bag of binary words: counts of each vocabulary word among the image's descriptors,
/// normalised. An image without descriptors gives the zero vector.
class BowHistogram {
 public:
  explicit BowHistogram(const BowHistogramOptions& options = {}) : options_(options) {
    detail::check_bow_histogram_options(options_);
  }
  /// Over a vocabulary already learned (a loaded map): the options' vocabulary is only
  /// used by a later fit(), which checks it.
  BowHistogram(BinaryVocabularyTree vocabulary, const BowHistogramOptions& options = {})
      : options_(options), vocabulary_(std::move(vocabulary)) {}

  /// Learns the vocabulary from the training images' descriptors.
  void fit(const std::vector<Features>& training) {
    detail::check_bow_histogram_options(options_);
    std::vector<cv::Mat> d;
    d.reserve(training.size());
    for (const auto& f : training) d.push_back(f.descriptors);
    vocabulary_ = BinaryVocabularyTree::learn(d, options_.vocabulary);
  }

  [[nodiscard]] Eigen::VectorXf operator()(const Features& f) const {
    detail::check(vocabulary_.size() > 0, "BowHistogram: no vocabulary (call fit() with training features first)");
    Eigen::VectorXf h = Eigen::VectorXf::Zero(static_cast<Eigen::Index>(vocabulary_.size()));
    for (std::uint32_t w : vocabulary_.assign(f.descriptors)) h[static_cast<Eigen::Index>(w)] += 1.0f;
    detail::normalise(h, options_.norm);
    return h;
  }

  [[nodiscard]] std::size_t dimension() const noexcept { return static_cast<std::size_t>(vocabulary_.size()); }
  [[nodiscard]] const BinaryVocabularyTree& vocabulary() const noexcept { return vocabulary_; }

 private:
  BowHistogramOptions options_;
  BinaryVocabularyTree vocabulary_;
};

struct GridHistogramOptions {
  int rows = 4;  ///< grid rows, >= 1
  int cols = 6;  ///< grid columns, >= 1
  HistogramNorm norm = HistogramNorm::l2;
};

/// Spatial grid: per cell the share of the image's keypoints in it and their mean
/// response (relative to the image's strongest), 2 * rows * cols values, normalised.
/// Needs Features::image_size.
class GridHistogram {
 public:
  explicit GridHistogram(const GridHistogramOptions& options = {}) : options_(options) {
    detail::check(options_.rows >= 1 && options_.cols >= 1, "GridHistogramOptions: rows and cols must be >= 1");
  }

  /// Nothing to learn: the grid is fixed.
  void fit(const std::vector<Features>&) {}

  [[nodiscard]] Eigen::VectorXf operator()(const Features& f) const {
    const int cells = options_.rows * options_.cols;
    Eigen::VectorXf h = Eigen::VectorXf::Zero(2 * cells);
    if (f.keypoints.empty()) return h;
    detail::check(f.image_size.width > 0 && f.image_size.height > 0,
                  "GridHistogram: the features carry no image size");
    float strongest = 0.0f;
    for (const auto& k : f.keypoints) strongest = std::max(strongest, k.response);
    for (const auto& k : f.keypoints) {
      const int c = std::clamp(static_cast<int>(k.pt.x * static_cast<float>(options_.cols) / static_cast<float>(f.image_size.width)), 0, options_.cols - 1);
      const int r = std::clamp(static_cast<int>(k.pt.y * static_cast<float>(options_.rows) / static_cast<float>(f.image_size.height)), 0, options_.rows - 1);
      const int cell = r * options_.cols + c;
      h[cell] += 1.0f;
      h[cells + cell] += strongest > 0.0f ? k.response / strongest : 0.0f;
    }
    for (int c = 0; c < cells; ++c)
      if (h[c] > 0.0f) h[cells + c] /= h[c];
    h.head(cells) /= static_cast<float>(f.keypoints.size());
    detail::normalise(h, options_.norm);
    return h;
  }

  [[nodiscard]] std::size_t dimension() const noexcept { return static_cast<std::size_t>(2 * options_.rows * options_.cols); }

 private:
  GridHistogramOptions options_;
};

static_assert(FeatureHistogram<BowHistogram>);
static_assert(FeatureHistogram<GridHistogram>);

}  // namespace vmap
