#pragma once

#include <vmap/core/concepts.hpp>
#include <vmap/core/error.hpp>
#include <vmap/core/numeric.hpp>
#include <vmap/matching/detail/hamming.hpp>
#include <vmap/matching/hamming.hpp>

#include <opencv2/core.hpp>

#include <cmath>
#include <optional>
#include <string>

namespace vmap {

/// How brute-force matches are filtered.
enum class MatchMode {
  mutual,  ///< keep a -> b only if b's nearest neighbour in a is a (cross-check)
  ratio,   ///< Lowe's ratio test: nearest distance < ratio * second-nearest distance
};

struct BruteForceOptions {
  MatchMode mode = MatchMode::mutual;
  float ratio = 0.8f;  ///< used by MatchMode::ratio, in (0, 1]; Lowe 2004 suggests 0.8
  /// Highest instruction level of the Hamming kernels (binary descriptors); unset: the
  /// environment variable VMAP_HAMMING_LEVEL if set, else the best the CPU has. Levels
  /// the CPU lacks fall back to the best it has; every level gives the same matches.
  std::optional<HammingLevel> hamming_level = std::nullopt;
};

/// Exhaustive nearest-neighbour matching under the norm the Features carry (Hamming
/// for binary descriptors, L2 for float ones). Holds only options: `match` is const
/// and safe to call from several threads at once.
class BruteForceMatcher {
 public:
  explicit BruteForceMatcher(const BruteForceOptions& options = {})
      : options_(options), level_(resolve_hamming_level(options.hamming_level)) {
    detail::check(std::isfinite(options_.ratio) && options_.ratio > 0.0f && options_.ratio <= 1.0f,
                  [&] { return "BruteForceOptions.ratio must be in (0, 1], got " + std::to_string(options_.ratio); });
  }

  /// Buffers `match_into` reuses between calls, so that matching a stream of frames
  /// does not allocate once warm. One per thread.
  struct Scratch {
    detail::HammingScratch packed;
    detail::MutualResult mutual;
    detail::TwoNearestResult two;
    cv::Mat dist, idx;
  };

  /// Empty inputs give empty matches; descriptors of different kinds are an Error.
  [[nodiscard]] Matches match(const Features& a, const Features& b) const {
    Matches out;
    Scratch scratch;
    match_into(a, b, out, scratch);
    return out;
  }

  /// `match` into `out` (its capacity is kept), with the caller's buffers.
  void match_into(const Features& a, const Features& b, Matches& out, Scratch& scratch) const {
    out.clear();
    if (a.descriptors.empty() || b.descriptors.empty()) return;
    check_compatible(a, b);
    cv::Mat& dist = scratch.dist;
    cv::Mat& idx = scratch.idx;
    const int dtype = a.descriptors.depth() == CV_8U ? CV_32S : CV_32F;
    // The Hamming kernels (detail/hamming.hpp) compute each distance once, with the
    // widest popcount the CPU has; NORM_HAMMING2 (ORB with WTA_K 3 or 4) and float
    // descriptors go through OpenCV.
    const bool hamming = a.norm == cv::NORM_HAMMING && dtype == CV_32S;
    if (options_.mode == MatchMode::mutual && hamming) {
      detail::MutualResult& r = scratch.mutual;
      detail::mutual_hamming(a.descriptors, b.descriptors, level_, scratch.packed, r);
      out.reserve(r.best_b.size());
      for (std::size_t i = 0; i < r.best_b.size(); ++i) {
        const int j = r.best_b[i];
        if (j >= 0 && r.best_a[static_cast<std::size_t>(j)] == static_cast<int>(i))
          out.emplace_back(static_cast<int>(i), j, static_cast<float>(r.best_b_dist[i]));
      }
    } else if (options_.mode == MatchMode::mutual) {
      // OpenCV's cross-check (what BFMatcher's crossCheck does, without cloning a
      // matcher per call).
      cv::batchDistance(a.descriptors, b.descriptors, dist, dtype, idx, a.norm, 1, cv::noArray(), 0,
                        true);
      out.reserve(static_cast<std::size_t>(idx.rows));
      for (int i = 0; i < idx.rows; ++i) {
        const int j = idx.at<int>(i, 0);
        if (j < 0) continue;
        out.emplace_back(i, j, distance_at(dist, i, 0));
      }
    } else if (hamming) {
      if (b.descriptors.rows < 2) return;  // no second neighbour to compare with
      detail::TwoNearestResult& r = scratch.two;
      detail::two_nearest_hamming(a.descriptors, b.descriptors, level_, scratch.packed, r);
      out.reserve(r.best.size());
      for (std::size_t i = 0; i < r.best.size(); ++i) {
        if (r.best[i] < 0) continue;
        const float d1 = static_cast<float>(r.best_dist[i]);
        const float d2 = static_cast<float>(r.second_dist[i]);
        if (d1 < options_.ratio * d2) out.emplace_back(static_cast<int>(i), r.best[i], d1);
      }
    } else {
      if (b.descriptors.rows < 2) return;
      cv::batchDistance(a.descriptors, b.descriptors, dist, dtype, idx, a.norm, 2);
      out.reserve(static_cast<std::size_t>(idx.rows));
      for (int i = 0; i < idx.rows; ++i) {
        const int j = idx.at<int>(i, 0);
        if (j < 0) continue;
        const float d1 = distance_at(dist, i, 0);
        const float d2 = distance_at(dist, i, 1);
        if (d1 < options_.ratio * d2) out.emplace_back(i, j, d1);
      }
    }
  }

  /// The Hamming kernel level this matcher runs at (its option resolved against the CPU).
  [[nodiscard]] HammingLevel hamming_level() const noexcept { return level_; }

  [[nodiscard]] const BruteForceOptions& options() const noexcept { return options_; }

  /// The name and the options that change the matches (core/concepts.hpp,
  /// DescribesItself); the Hamming kernel level gives the same matches at every level.
  [[nodiscard]] std::string describe() const {
    return std::string("BruteForceMatcher mode=") + (options_.mode == MatchMode::mutual ? "mutual" : "ratio") +
           " ratio=" + exact_text(options_.ratio);
  }

 private:
  static float distance_at(const cv::Mat& dist, int row, int col) {
    return dist.depth() == CV_32S ? static_cast<float>(dist.at<int>(row, col)) : dist.at<float>(row, col);
  }

  static void check_compatible(const Features& a, const Features& b) {
    if (a.descriptors.type() != b.descriptors.type() || a.descriptors.cols != b.descriptors.cols)
      detail::fail("BruteForceMatcher: descriptors differ in kind (" + cv::typeToString(a.descriptors.type()) +
                   " x " + std::to_string(a.descriptors.cols) + " vs " + cv::typeToString(b.descriptors.type()) +
                   " x " + std::to_string(b.descriptors.cols) + "); were both extracted by the same Descriptor?");
    if (a.norm != b.norm)
      detail::fail("BruteForceMatcher: the two Features carry different norms (" + std::to_string(a.norm) +
                   " vs " + std::to_string(b.norm) + ")");
    const bool binary = a.descriptors.depth() == CV_8U;
    const bool hamming = a.norm == cv::NORM_HAMMING || a.norm == cv::NORM_HAMMING2;
    if (binary != hamming)
      detail::fail("BruteForceMatcher: norm " + std::to_string(a.norm) + " does not fit descriptors of type " +
                   cv::typeToString(a.descriptors.type()) + " (binary descriptors need Hamming, float ones L1/L2)");
    if (a.descriptors.rows != static_cast<int>(a.keypoints.size()) ||
        b.descriptors.rows != static_cast<int>(b.keypoints.size()))
      detail::fail("BruteForceMatcher: descriptor rows and keypoint count differ");
  }

  BruteForceOptions options_;
  HammingLevel level_;
};

static_assert(Matcher<BruteForceMatcher>);

}  // namespace vmap
