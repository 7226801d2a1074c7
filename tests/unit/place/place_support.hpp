#pragma once

// Synthetic data for the place tests: descriptors in a two-level cluster hierarchy
// (groups of leaf clusters), random bag-of-words vectors, a brute-force ranking.

#include <vmap/place/bow.hpp>
#include <vmap/place/database.hpp>

#include "support/errors.hpp"
#include "support/shared_data.hpp"

#include <opencv2/core.hpp>

#include <algorithm>
#include <random>
#include <vector>

namespace vmap::test {

struct HierarchicalClusters {
  std::vector<cv::Mat> images;  ///< the descriptors split over 8 images, interleaved
  cv::Mat all;                  ///< every descriptor, cluster by cluster
  std::vector<int> cluster;     ///< leaf cluster of each row of `all`
};

inline HierarchicalClusters split_images(cv::Mat all, std::vector<int> cluster) {
  HierarchicalClusters h;
  h.images.resize(8);
  for (int r = 0; r < all.rows; ++r) h.images[static_cast<std::size_t>(r % 8)].push_back(all.row(r));
  h.all = std::move(all);
  h.cluster = std::move(cluster);
  return h;
}

/// 256-bit descriptors: `groups` random centres, each with `per_group` sub-centres (10 %
/// of the bits flipped), each with `per_leaf` descriptors (2 % flipped).
inline HierarchicalClusters binary_clusters(int groups, int per_group, int per_leaf, unsigned seed) {
  std::mt19937 rng(seed);
  auto flip = [&](const cv::Mat& c, double p) {
    std::bernoulli_distribution f(p);
    cv::Mat out = c.clone();
    for (int b = 0; b < out.cols; ++b)
      for (int bit = 0; bit < 8; ++bit)
        if (f(rng)) out.at<uchar>(0, b) = static_cast<uchar>(out.at<uchar>(0, b) ^ (1U << bit));
    return out;
  };
  cv::Mat all;
  std::vector<int> cluster;
  for (int g = 0; g < groups; ++g) {
    cv::Mat top(1, 32, CV_8UC1);
    for (int b = 0; b < 32; ++b) top.at<uchar>(0, b) = static_cast<uchar>(rng() & 0xFFU);
    for (int s = 0; s < per_group; ++s) {
      const cv::Mat sub = flip(top, 0.10);
      for (int i = 0; i < per_leaf; ++i) {
        all.push_back(flip(sub, 0.02));
        cluster.push_back(g * per_group + s);
      }
    }
  }
  return split_images(all, cluster);
}

/// 64-d float descriptors: group centres N(0, 10), sub-centres +N(0, 2), descriptors +N(0, 0.2).
inline HierarchicalClusters float_clusters(int groups, int per_group, int per_leaf, unsigned seed) {
  std::mt19937 rng(seed);
  std::normal_distribution<float> n(0.0f, 1.0f);
  auto around = [&](const cv::Mat& c, float sigma) {
    cv::Mat out = c.clone();
    for (int i = 0; i < out.cols; ++i) out.at<float>(0, i) += sigma * n(rng);
    return out;
  };
  cv::Mat all;
  std::vector<int> cluster;
  for (int g = 0; g < groups; ++g) {
    const cv::Mat top = around(cv::Mat::zeros(1, 64, CV_32FC1), 10.0f);
    for (int s = 0; s < per_group; ++s) {
      const cv::Mat sub = around(top, 2.0f);
      for (int i = 0; i < per_leaf; ++i) {
        all.push_back(around(sub, 0.2f));
        cluster.push_back(g * per_group + s);
      }
    }
  }
  return split_images(all, cluster);
}

/// A random bag of words: `entries` distinct words below `words`, weights in (0, 1],
/// L1-normalised.
inline BowVector random_bow(std::size_t words, std::size_t entries, std::mt19937& rng) {
  std::vector<std::uint32_t> w(words);
  for (std::size_t i = 0; i < words; ++i) w[i] = static_cast<std::uint32_t>(i);
  std::shuffle(w.begin(), w.end(), rng);
  w.resize(entries);
  std::sort(w.begin(), w.end());
  std::uniform_real_distribution<float> u(0.01f, 1.0f);
  BowVector v;
  double total = 0.0;
  for (auto x : w) {
    v.entries.push_back({x, u(rng)});
    total += v.entries.back().weight;
  }
  for (auto& e : v.entries) e.weight = static_cast<float>(e.weight / total);
  return v;
}

/// The top `n` of scoring every vector with bow_score (score > 0 only), best first,
/// equal scores by id.
inline std::vector<PlaceMatch<std::uint32_t>> brute_force_top(const std::vector<BowVector>& db,
                                                              const std::vector<bool>& present, const BowVector& q,
                                                              std::size_t n, BowScoring s,
                                                              const std::vector<bool>* allowed = nullptr) {
  std::vector<PlaceMatch<std::uint32_t>> all;
  for (std::size_t i = 0; i < db.size(); ++i) {
    if (!present[i] || (allowed && !(*allowed)[i])) continue;
    const double sc = bow_score(q, db[i], s);
    if (sc > 0.0) all.push_back({static_cast<std::uint32_t>(i), sc});
  }
  std::sort(all.begin(), all.end(), [](const auto& a, const auto& b) {
    return a.score != b.score ? a.score > b.score : a.id < b.id;
  });
  if (all.size() > n) all.resize(n);
  return all;
}

/// Checks that `got` is `want` up to rounding: same length, scores within 1e-5 rank by
/// rank, and the same ids wherever the scores around a rank are not within 1e-5 (a
/// near-tie may order either way).
inline void check_same_ranking(const std::vector<PlaceMatch<std::uint32_t>>& got,
                               const std::vector<PlaceMatch<std::uint32_t>>& want) {
  REQUIRE(got.size() == want.size());
  for (std::size_t i = 0; i < got.size(); ++i) {
    CHECK(got[i].score == doctest::Approx(want[i].score).epsilon(1e-5));
    const bool tie_before = i > 0 && std::abs(want[i - 1].score - want[i].score) < 1e-5;
    const bool tie_after = i + 1 < want.size() && std::abs(want[i + 1].score - want[i].score) < 1e-5;
    if (!tie_before && !tie_after) CHECK(got[i].id == want[i].id);
  }
}

}  // namespace vmap::test
