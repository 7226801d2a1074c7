#pragma once

// The whole method of Trujillo-Romero 2024 (DESIGN.md sec. 1.3) as one object: images
// -> A-KAZE features -> histogram ("BuildHistos") -> GCS -> a pose per neuron; then
// one or two query images -> position.

#include <vmap/core/concepts.hpp>
#include <vmap/core/error.hpp>
#include <vmap/features/akaze.hpp>
#include <vmap/geometry/pose2.hpp>
#include <vmap/som/gcs.hpp>
#include <vmap/som/histogram.hpp>
#include <vmap/som/pose_map.hpp>

#include <opencv2/core.hpp>

#include <chrono>
#include <optional>
#include <string>
#include <utility>
#include <vector>

namespace vmap {

/// Time spent in each stage of training (seconds).
struct LocalizerTrainReport {
  GcsTrainStats gcs;
  double feature_seconds = 0.0;    ///< descriptor extraction
  double histogram_seconds = 0.0;  ///< histogram fit (vocabulary) + vectors
  double gcs_seconds = 0.0;        ///< network training: the paper's "training time"
  double pose_seconds = 0.0;       ///< Algorithm 4
};

/// Not thread-safe (the descriptor keeps scratch state); after train(), localize_vectors
/// on a const object is.
template <Descriptor D = AkazeDescriptor, FeatureHistogram H = BowHistogram, class Network = GcsXf>
class GcsLocalizer {
 public:
  using Vector = typename Network::Vector;

  GcsLocalizer(D descriptor, H histogram, const GcsOptions& gcs = {})
      : descriptor_(std::move(descriptor)), histogram_(std::move(histogram)), gcs_options_(gcs) {}

  /// Learns the map from training images and their poses (one each).
  LocalizerTrainReport train(const std::vector<cv::Mat>& images, const std::vector<Pose2>& poses) {
    detail::check(!images.empty(), "GcsLocalizer::train: the training set is empty");
    detail::check(images.size() == poses.size(), "GcsLocalizer::train: " + std::to_string(images.size()) +
                                                     " images but " + std::to_string(poses.size()) + " poses");
    using clock = std::chrono::steady_clock;
    LocalizerTrainReport r;
    auto t0 = clock::now();
    std::vector<Features> features;
    features.reserve(images.size());
    for (std::size_t i = 0; i < images.size(); ++i) {
      detail::check(!images[i].empty(), "GcsLocalizer::train: training image " + std::to_string(i) + " is empty");
      features.push_back(descriptor_.extract(images[i]));
    }
    auto t1 = clock::now();
    histogram_.fit(features);
    std::vector<Vector> vectors;
    vectors.reserve(features.size());
    for (const auto& f : features) vectors.push_back(histogram_(f).template cast<typename Vector::Scalar>());
    auto t2 = clock::now();
    Network net(gcs_options_);
    r.gcs = net.train(vectors);
    auto t3 = clock::now();
    map_.emplace(std::move(net), vectors, poses);
    auto t4 = clock::now();
    auto sec = [](auto a, auto b) { return std::chrono::duration<double>(b - a).count(); };
    r.feature_seconds = sec(t0, t1);
    r.histogram_seconds = sec(t1, t2);
    r.gcs_seconds = sec(t2, t3);
    r.pose_seconds = sec(t3, t4);
    return r;
  }

  /// The vector of one image under the trained histogram.
  [[nodiscard]] Vector vector_of(const cv::Mat& image) {
    detail::check(!image.empty(), "GcsLocalizer: a query image is empty");
    return histogram_(descriptor_.extract(image)).template cast<typename Vector::Scalar>();
  }

  /// Position from one or two (or more) query images (Algorithm 5).
  [[nodiscard]] Localization localize(const std::vector<cv::Mat>& images) {
    check_trained();
    std::vector<Vector> v;
    for (const auto& im : images) v.push_back(vector_of(im));
    return map_->localize(v);
  }

  [[nodiscard]] Localization localize_vectors(const std::vector<Vector>& vectors) const {
    check_trained();
    return map_->localize(vectors);
  }

  [[nodiscard]] const PoseMap<Network>& map() const {
    check_trained();
    return *map_;
  }
  [[nodiscard]] bool trained() const noexcept { return map_.has_value(); }

 private:
  void check_trained() const {
    if (!map_) detail::fail("GcsLocalizer: not trained (call train() first)");
  }

  D descriptor_;
  H histogram_;
  GcsOptions gcs_options_;
  std::optional<PoseMap<Network>> map_;
};

using AkazeBowLocalizer = GcsLocalizer<AkazeDescriptor, BowHistogram>;
using AkazeGridLocalizer = GcsLocalizer<AkazeDescriptor, GridHistogram>;

}  // namespace vmap
