#pragma once

// The detector-free matcher hook (examples/methods.md, sec. 5 and 7): a LoFTR-style network matches an
// image pair directly. It yields correspondences and its own denominator for eq. 5
// (its number of coarse cells), so a key-image selector can use it instead of
// Descriptor + Matcher.

#include <opencv2/core.hpp>

#include <concepts>
#include <vector>

namespace vmap {

/// Correspondences between image a and image b: points_a[i] <-> points_b[i].
struct Correspondences {
  std::vector<cv::Point2f> points_a;
  std::vector<cv::Point2f> points_b;
  std::vector<float> confidence;  ///< one per correspondence, in [0, 1]
  int cells = 0;                  ///< eq. 5 denominator: the matcher's number of coarse cells

  [[nodiscard]] std::size_t size() const noexcept { return points_a.size(); }
};

template <class P>
concept MatchesImagePairs = requires(P& p, const cv::Mat& a, const cv::Mat& b) {
  { p.match_pair(a, b) } -> std::same_as<Correspondences>;
};

template <class P>
concept PairMatcher = std::move_constructible<P>  // held by value
                      && MatchesImagePairs<P>;    // Correspondences match_pair(a, b)

}  // namespace vmap
