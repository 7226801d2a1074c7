#pragma once

// Mutual nearest neighbours under the Hamming distance in one pass over the distance
// matrix. OpenCV's cross-check (batchDistance with crosscheck=true, what BFMatcher
// uses) computes the matrix twice, once per direction; here each distance is computed
// once and updates both the row's and the column's best. Ties keep the first (lowest)
// index in both directions, as OpenCV does, so the matches are identical.
//
// The popcount uses the POPCNT instruction when the CPU has it (checked once at run
// time), without compiling the library for a particular -march.

#include <opencv2/core.hpp>

#include <cstdint>
#include <cstring>
#include <limits>
#include <vector>

namespace vmap::detail {

struct MutualResult {
  std::vector<int> best_b;       // for each row of a: nearest row of b
  std::vector<int> best_b_dist;  // its distance
  std::vector<int> best_a;       // for each row of b: nearest row of a
  std::vector<int> best_a_dist;
};

#if defined(__GNUC__)
#define VMAP_DETAIL_ALWAYS_INLINE inline __attribute__((always_inline))
#else
#define VMAP_DETAIL_ALWAYS_INLINE inline
#endif

VMAP_DETAIL_ALWAYS_INLINE int hamming_bytes(const std::uint8_t* x, const std::uint8_t* y, int bytes) {
  int d = 0;
  int k = 0;
  for (; k + 8 <= bytes; k += 8) {
    std::uint64_t u, v;
    std::memcpy(&u, x + k, 8);
    std::memcpy(&v, y + k, 8);
    d += __builtin_popcountll(u ^ v);
  }
  for (; k < bytes; ++k) d += __builtin_popcount(static_cast<unsigned>(x[k] ^ y[k]));
  return d;
}

VMAP_DETAIL_ALWAYS_INLINE void mutual_hamming_kernel(const cv::Mat& a, const cv::Mat& b, MutualResult& r) {
  const int na = a.rows, nb = b.rows, bytes = a.cols;
  constexpr int none = std::numeric_limits<int>::max();
  r.best_b.assign(static_cast<std::size_t>(na), -1);
  r.best_b_dist.assign(static_cast<std::size_t>(na), none);
  r.best_a.assign(static_cast<std::size_t>(nb), -1);
  r.best_a_dist.assign(static_cast<std::size_t>(nb), none);
  int* const col_best = r.best_a.data();
  int* const col_dist = r.best_a_dist.data();
  for (int i = 0; i < na; ++i) {
    const std::uint8_t* ai = a.ptr<std::uint8_t>(i);
    int row_best = -1, row_dist = none;
    for (int j = 0; j < nb; ++j) {
      const int d = hamming_bytes(ai, b.ptr<std::uint8_t>(j), bytes);
      if (d < row_dist) {  // strict: the first minimum wins, as in OpenCV
        row_dist = d;
        row_best = j;
      }
      if (d < col_dist[j]) {  // rows are visited in increasing i: first minimum again
        col_dist[j] = d;
        col_best[j] = i;
      }
    }
    r.best_b[static_cast<std::size_t>(i)] = row_best;
    r.best_b_dist[static_cast<std::size_t>(i)] = row_dist;
  }
}

#if defined(__GNUC__) && (defined(__x86_64__) || defined(__i386__))
__attribute__((target("popcnt"))) inline void mutual_hamming_popcnt(const cv::Mat& a, const cv::Mat& b,
                                                                    MutualResult& r) {
  mutual_hamming_kernel(a, b, r);
}
inline bool cpu_has_popcnt() {
  static const bool has = __builtin_cpu_supports("popcnt");
  return has;
}
#endif

/// Nearest neighbours both ways between two binary descriptor matrices (CV_8U, same
/// width, continuous rows not required).
inline void mutual_hamming(const cv::Mat& a, const cv::Mat& b, MutualResult& r) {
#if defined(__GNUC__) && (defined(__x86_64__) || defined(__i386__))
  if (cpu_has_popcnt()) {
    mutual_hamming_popcnt(a, b, r);
    return;
  }
#endif
  mutual_hamming_kernel(a, b, r);
}

#undef VMAP_DETAIL_ALWAYS_INLINE

}  // namespace vmap::detail
