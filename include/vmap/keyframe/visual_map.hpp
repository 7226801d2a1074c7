#pragma once

// The visual map of García-Pintos et al. 2023: the key images M = {K_1..K_m} chosen from a
// video of n frames, and for each consecutive pair (K_i, K_i+1) the fundamental matrix
// that links them, its inlier count and the similarity (eq. 5).

#include <vmap/core/features.hpp>
#include <vmap/core/verification.hpp>

#include <opencv2/core.hpp>

#include <algorithm>
#include <cstddef>
#include <cstdint>
#include <string>
#include <vector>

namespace vmap {

/// One key image of the map.
struct KeyImage {
  std::size_t frame_index = 0;  ///< position in the input sequence (Frame::index)
  std::string name;             ///< source name (file name, "<video>#<index>")
  double timestamp = 0.0;
  Features features;  ///< the features it was compared with (empty for pair matchers)
  cv::Mat image;      ///< the image, when the selector keeps images (else empty)
  std::int64_t time_ns = 0;  ///< `timestamp` in whole nanoseconds (Frame::time_ns)
};

/// The link between key image i and key image i+1.
struct KeyPair {
  VerificationStatus status = VerificationStatus::too_few_matches;
  cv::Matx33d fundamental = cv::Matx33d::zeros();  ///< x_{i+1}^T F x_i = 0 (zeros unless verified)
  int matches = 0;                                 ///< raw correspondences
  int inliers = 0;                                 ///< verified matches (f_match of eq. 5)
  double similarity = 0.0;                         ///< S(K_i, K_i+1), eq. 5
};

/// How eq. 7 averages the similarities of consecutive key images.
enum class QualityForm {
  /// Q = 1/2 ((1 - m/n) + 1/(m-1) sum_{i<m} S(K_i, K_i+1)): the arithmetic mean over
  /// the m-1 consecutive pairs; the mean term is 0 when m < 2 (no pair). The default.
  mean_over_pairs,
  /// The paper's literal eq. 7, which divides the sum over the m-1 pairs by m.
  paper_literal,
};

/// Summary figures of a map, the columns of the paper's threshold tables.
struct MapStats {
  std::size_t frames = 0;      ///< n
  std::size_t key_images = 0;  ///< m
  int min_matches = 0;         ///< verified matches between consecutive key images (0 if m < 2)
  int max_matches = 0;
  double mean_matches = 0.0;
  double mean_similarity = 0.0;  ///< over the m-1 pairs (0 if m < 2)
  double quality = 0.0;          ///< eq. 7, QualityForm::mean_over_pairs
};

struct VisualMap {
  std::size_t frames = 0;  ///< n: frames the selector saw
  std::vector<KeyImage> keys;
  std::vector<KeyPair> pairs;  ///< pairs[i] links keys[i] and keys[i+1]; size m-1 (0 if m == 0)

  /// Eq. 7 of García-Pintos et al. 2023. The paper calls it a harmonic mean but writes
  /// an arithmetic one; see QualityForm for the two readings. 0 for an empty map.
  [[nodiscard]] double quality(QualityForm form = QualityForm::mean_over_pairs) const noexcept {
    if (frames == 0 || keys.empty()) return 0.0;
    const double m = static_cast<double>(keys.size());
    const double n = static_cast<double>(frames);
    double sum = 0.0;
    for (const auto& p : pairs) sum += p.similarity;
    double mean = 0.0;
    if (form == QualityForm::paper_literal)
      mean = sum / m;
    else if (!pairs.empty())
      mean = sum / static_cast<double>(pairs.size());
    return 0.5 * ((1.0 - m / n) + mean);
  }

  [[nodiscard]] MapStats stats() const noexcept {
    MapStats s;
    s.frames = frames;
    s.key_images = keys.size();
    s.quality = quality();
    if (pairs.empty()) return s;
    s.min_matches = pairs.front().inliers;
    s.max_matches = pairs.front().inliers;
    double sum = 0.0, sim = 0.0;
    for (const auto& p : pairs) {
      s.min_matches = std::min(s.min_matches, p.inliers);
      s.max_matches = std::max(s.max_matches, p.inliers);
      sum += p.inliers;
      sim += p.similarity;
    }
    s.mean_matches = sum / static_cast<double>(pairs.size());
    s.mean_similarity = sim / static_cast<double>(pairs.size());
    return s;
  }

  /// Frame indices of the key images, in order.
  [[nodiscard]] std::vector<std::size_t> key_indices() const {
    std::vector<std::size_t> out;
    out.reserve(keys.size());
    for (const auto& k : keys) out.push_back(k.frame_index);
    return out;
  }
};

}  // namespace vmap
