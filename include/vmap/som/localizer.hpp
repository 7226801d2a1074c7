#pragma once

// The whole method of Trujillo-Romero 2024 (examples/methods.md, sec. 3) as one object: images
// -> A-KAZE features -> histogram ("BuildHistos") -> GCS -> a pose per neuron; then
// one or two query images -> position.

#include <vmap/core/concepts.hpp>
#include <vmap/core/error.hpp>
#include <vmap/core/features.hpp>
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

/// What train_pose_map() makes: the trained network with a pose per neuron, the neuron
/// each training item won (Algorithm 4), and each stage's statistics and time.
template <class Network>
struct PoseMapTraining {
  PoseMap<Network> map;
  std::vector<std::size_t> winners;  ///< winners[i]: the neuron training item i won
  GcsTrainStats gcs;
  double histogram_seconds = 0.0;  ///< histogram fit (vocabulary) + vectors
  double gcs_seconds = 0.0;        ///< network training: the paper's "training time"
  double pose_seconds = 0.0;       ///< Algorithm 4
};

/// The method from features on: `histogram` learns from the training features (fit),
/// each becomes a vector ("BuildHistos"), the network trains on them (Algorithm 1) and
/// each neuron gets the mean pose of the items it wins (Algorithm 4). The one training
/// routine of GcsLocalizer (which extracts the features first) and of the visual memory
/// (whose key images hold theirs). Deterministic (GcsOptions::seed).
template <class Network, FeatureHistogram H>
PoseMapTraining<Network> train_pose_map(H& histogram, const GcsOptions& options, const std::vector<Features>& features,
                                        const std::vector<Pose2>& poses) {
  using Vector = typename Network::Vector;
  detail::check(features.size() == poses.size(), "train_pose_map: " + std::to_string(features.size()) +
                                                     " feature sets but " + std::to_string(poses.size()) + " poses");
  using clock = std::chrono::steady_clock;
  const auto sec = [](auto a, auto b) { return std::chrono::duration<double>(b - a).count(); };
  const auto t0 = clock::now();
  histogram.fit(features);
  std::vector<Vector> vectors;
  vectors.reserve(features.size());
  for (const auto& f : features) vectors.push_back(histogram(f).template cast<typename Vector::Scalar>());
  const auto t1 = clock::now();
  Network net(options);
  const GcsTrainStats stats = net.train(vectors);
  const auto t2 = clock::now();
  std::vector<std::size_t> winners;
  winners.reserve(vectors.size());
  for (const auto& v : vectors) winners.push_back(net.bmu(v).cell);
  PoseMap<Network> map = PoseMap<Network>::from_assignments(std::move(net), winners, poses);
  const auto t3 = clock::now();
  return {std::move(map), std::move(winners), stats, sec(t0, t1), sec(t1, t2), sec(t2, t3)};
}

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
    PoseMapTraining<Network> t = train_pose_map<Network>(histogram_, gcs_options_, features, poses);
    map_.emplace(std::move(t.map));
    r.gcs = t.gcs;
    r.feature_seconds = std::chrono::duration<double>(t1 - t0).count();
    r.histogram_seconds = t.histogram_seconds;
    r.gcs_seconds = t.gcs_seconds;
    r.pose_seconds = t.pose_seconds;
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
