#pragma once

// Poses attached to the neurons of a trained GCS (Trujillo-Romero 2024, Algorithm 4) and
// localization from one or two query vectors (Algorithm 5; examples/methods.md, sec. 3 steps
// 5-6).

#include <vmap/core/error.hpp>
#include <vmap/geometry/pose2.hpp>
#include <vmap/som/gcs.hpp>
#include <vmap/som/results.hpp>

#include <Eigen/Core>

#include <cmath>
#include <cstddef>
#include <limits>
#include <string>
#include <utility>
#include <vector>

namespace vmap {

/// What a neuron knows about where it is.
struct NeuronPose {
  Pose2 mean;                                           ///< mean of the poses of the images it wins
  Eigen::Vector2d spread = Eigen::Vector2d::Zero();     ///< standard deviation of x and y (metres)
  std::size_t count = 0;                                ///< training images it wins; 0 = no pose
  [[nodiscard]] bool has_pose() const noexcept { return count > 0; }
};

/// A trained network plus a pose per neuron. Queries are const and thread-safe.
template <class Network>
class PoseMap {
 public:
  using Vector = typename Network::Vector;

  /// Algorithm 4: each neuron gets the mean of the poses of the training vectors it
  /// wins. `vectors` and `poses` are the training set, one pose per vector.
  PoseMap(Network network, const std::vector<Vector>& vectors, const std::vector<Pose2>& poses)
      : network_(std::move(network)) {
    detail::check(!network_.empty(), "PoseMap: the network is not trained");
    detail::check(vectors.size() == poses.size(), "PoseMap: " + std::to_string(vectors.size()) + " vectors but " +
                                                      std::to_string(poses.size()) + " poses");
    std::vector<std::size_t> winners;
    winners.reserve(vectors.size());
    for (const auto& v : vectors) winners.push_back(network_.bmu(v).cell);
    assign(winners, poses);
  }

  /// The same from given winners (winners[i] = neuron of training pose i).
  static PoseMap from_assignments(Network network, const std::vector<std::size_t>& winners,
                                  const std::vector<Pose2>& poses) {
    detail::check(!network.empty(), "PoseMap: the network is not trained");
    detail::check(winners.size() == poses.size(), "PoseMap: " + std::to_string(winners.size()) + " winners but " +
                                                      std::to_string(poses.size()) + " poses");
    PoseMap m(std::move(network));
    m.assign(winners, poses);
    return m;
  }

  /// Algorithm 5: the best matching neuron of each query (one or more; the paper uses
  /// one or two), the estimate is the mean of their poses. A winner without a pose is
  /// replaced by the nearest neuron that has one (QueryMatch::substituted).
  [[nodiscard]] Localization localize(const std::vector<Vector>& queries) const {
    detail::check(!queries.empty(), "PoseMap::localize: no query vector given");
    Localization out;
    std::vector<Pose2> poses;
    for (const auto& q : queries) {
      QueryMatch m;
      const auto best = network_.bmu(q);
      if (cells_[best.cell].has_pose()) {
        m = {best.cell, best.distance, false, cells_[best.cell].mean};
      } else {
        for (const auto& c : network_.k_nearest(q, network_.size()))
          if (cells_[c.cell].has_pose()) {
            m = {c.cell, c.distance, true, cells_[c.cell].mean};
            break;
          }
      }
      poses.push_back(m.pose);
      out.matches.push_back(m);
    }
    out.pose = mean_pose(poses);
    return out;
  }

  [[nodiscard]] const Network& network() const noexcept { return network_; }
  [[nodiscard]] const std::vector<NeuronPose>& neurons() const noexcept { return cells_; }
  [[nodiscard]] std::size_t neurons_with_pose() const noexcept {
    std::size_t n = 0;
    for (const auto& c : cells_) n += c.has_pose() ? 1 : 0;
    return n;
  }

 private:
  explicit PoseMap(Network network) : network_(std::move(network)) {}

  void assign(const std::vector<std::size_t>& winners, const std::vector<Pose2>& poses) {
    detail::check(!poses.empty(), "PoseMap: the training set is empty");
    std::vector<std::vector<Pose2>> per(network_.size());
    for (std::size_t i = 0; i < winners.size(); ++i) {
      detail::check(winners[i] < network_.size(), "PoseMap: winner " + std::to_string(winners[i]) + " of pose " +
                                                       std::to_string(i) + " is not a neuron (network has " +
                                                       std::to_string(network_.size()) + ")");
      per[winners[i]].push_back(poses[i]);
    }
    cells_.assign(network_.size(), {});
    for (std::size_t c = 0; c < per.size(); ++c) {
      if (per[c].empty()) continue;
      NeuronPose& n = cells_[c];
      n.mean = mean_pose(per[c]);
      n.count = per[c].size();
      Eigen::Vector2d var = Eigen::Vector2d::Zero();
      for (const auto& p : per[c]) var += (p.translation() - n.mean.translation()).cwiseAbs2();
      n.spread = (var / static_cast<double>(per[c].size())).cwiseSqrt();
    }
  }

  Network network_;
  std::vector<NeuronPose> cells_;
};

}  // namespace vmap
