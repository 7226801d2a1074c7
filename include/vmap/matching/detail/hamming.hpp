#pragma once

// Hamming-distance kernels for binary descriptors (ORB: 32 bytes, A-KAZE: 61 bytes, any
// width) and the two reductions the matcher needs on top of them, in one pass over the
// distance matrix:
//  - mutual: each row's nearest column and each column's nearest row (OpenCV's
//    cross-check computes the matrix twice, once per direction);
//  - two nearest: each row's nearest column and the two smallest distances (Lowe's ratio
//    test), with OpenCV's batchDistance(K = 2) rule: the second distance is the second
//    smallest value counting repeats.
// Ties keep the first (lowest) index in both directions, as OpenCV does, so the matches
// are identical to BFMatcher's.
//
// Descriptors are first copied into zero-padded 64-bit words (a zero word adds nothing to
// a distance), so one code path serves every width, and the vector levels read the train
// descriptors interleaved: word k of L consecutive descriptors is contiguous, the even
// ones first and the odd ones second, so that one XOR + popcount per word gives L
// distances in L lanes with no horizontal sum, and packing the two halves' 64-bit sums
// into 32-bit lanes leaves them in index order. The train side is processed in column
// blocks of about 16 KB that stay in L1 while every query row passes over them.
//
// Levels (vmap/matching/hamming.hpp) are compiled with GCC target attributes, so the
// library needs no -march; the matcher picks one at run time.

#include <vmap/matching/hamming.hpp>

#include <opencv2/core.hpp>

#include <algorithm>
#include <array>
#include <climits>
#include <cstdint>
#include <cstring>
#include <vector>

#if defined(__GNUC__) && (defined(__x86_64__) || defined(__i386__))
#define VMAP_DETAIL_HAMMING_X86 1
#include <immintrin.h>
#endif

namespace vmap::detail {

struct MutualResult {
  std::vector<int> best_b;       // for each row of a: nearest row of b
  std::vector<int> best_b_dist;  // its distance
  std::vector<int> best_a;       // for each row of b: nearest row of a
  std::vector<int> best_a_dist;
};

struct TwoNearestResult {
  std::vector<int> best;         // for each row of a: nearest row of b (first of a tie)
  std::vector<int> best_dist;    // its distance
  std::vector<int> second_dist;  // the second smallest distance (INT_MAX when b has one row)
};

/// Packed copies reused between calls (one per thread).
struct HammingScratch {
  std::vector<std::uint64_t> a, b;
};

#if defined(__GNUC__)
#define VMAP_DETAIL_ALWAYS_INLINE inline __attribute__((always_inline))
#else
#define VMAP_DETAIL_ALWAYS_INLINE inline
#endif

inline constexpr int kNoDistance = INT_MAX;  // also the distance of padding lanes: never a minimum

/// Rows of `m` as `words` 64-bit words each, zero-padded.
inline void pack_rows(const cv::Mat& m, int words, std::vector<std::uint64_t>& out) {
  out.assign(static_cast<std::size_t>(m.rows) * static_cast<std::size_t>(words), 0);
  for (int i = 0; i < m.rows; ++i)
    std::memcpy(out.data() + static_cast<std::size_t>(i) * static_cast<std::size_t>(words), m.ptr<std::uint8_t>(i),
                static_cast<std::size_t>(m.cols));
}

/// Rows of `m` in blocks of `lanes`: in block t, word k of row t * lanes + l sits at
/// (t * words + k) * lanes + (l % 2) * lanes / 2 + l / 2. Missing rows are zero.
inline void pack_interleaved(const cv::Mat& m, int words, int lanes, std::vector<std::uint64_t>& out) {
  const int blocks = (m.rows + lanes - 1) / lanes;
  out.assign(static_cast<std::size_t>(blocks) * static_cast<std::size_t>(words * lanes), 0);
  const int half = lanes / 2;
  for (int j = 0; j < m.rows; ++j) {
    const std::uint8_t* p = m.ptr<std::uint8_t>(j);
    const int t = j / lanes, l = j % lanes;
    const std::size_t slot = static_cast<std::size_t>((l % 2) * half + l / 2);
    for (int k = 0; k < words; ++k) {
      std::uint64_t w = 0;
      std::memcpy(&w, p + 8 * k, static_cast<std::size_t>(std::min(8, m.cols - 8 * k)));
      out[static_cast<std::size_t>(t * words + k) * static_cast<std::size_t>(lanes) + slot] = w;
    }
  }
}

/// Train descriptors per column block: about 16 KB of words, a whole number of lane blocks.
inline int column_block(int words, int lanes) {
  const int rows = std::max(lanes, (16384 / (8 * words)) / lanes * lanes);
  return rows;
}

/// Running (nearest, its distance, second distance) of one row: `o` covers columns
/// after `r`'s, or the same columns with the tie decided by index.
struct Nearest2 {
  int d1 = kNoDistance, i1 = -1, d2 = kNoDistance;
};
VMAP_DETAIL_ALWAYS_INLINE Nearest2 merge(const Nearest2& r, const Nearest2& o) {
  Nearest2 m;
  const bool take = o.d1 < r.d1 || (o.d1 == r.d1 && o.i1 >= 0 && (r.i1 < 0 || o.i1 < r.i1));
  m.d1 = std::min(r.d1, o.d1);
  m.i1 = take ? o.i1 : r.i1;
  m.d2 = std::min(std::max(r.d1, o.d1), std::min(r.d2, o.d2));  // second smallest of both pairs
  return m;
}

// ---- scalar levels (portable, popcnt): row-major words ----------------------------------

template <int W>
VMAP_DETAIL_ALWAYS_INLINE int distance_words(const std::uint64_t* x, const std::uint64_t* y, int words) {
  const int n = W > 0 ? W : words;
  int d = 0;
  for (int k = 0; k < n; ++k) d += __builtin_popcountll(x[k] ^ y[k]);
  return d;
}

template <int W>
VMAP_DETAIL_ALWAYS_INLINE void mutual_scalar(const std::uint64_t* a, int na, const std::uint64_t* b, int nb,
                                             int words, MutualResult& r) {
  const std::size_t w = static_cast<std::size_t>(words);
  const int cb = column_block(words, 1);
  for (int j0 = 0; j0 < nb; j0 += cb) {
    const int j1 = std::min(nb, j0 + cb);
    for (int i = 0; i < na; ++i) {
      const std::uint64_t* ai = a + static_cast<std::size_t>(i) * w;
      int row_best = -1, row_dist = kNoDistance;
      for (int j = j0; j < j1; ++j) {
        const int d = distance_words<W>(ai, b + static_cast<std::size_t>(j) * w, words);
        if (d < row_dist) {  // strict: the first minimum wins, as in OpenCV
          row_dist = d;
          row_best = j;
        }
        if (d < r.best_a_dist[static_cast<std::size_t>(j)]) {  // rows come in increasing i: first minimum
          r.best_a_dist[static_cast<std::size_t>(j)] = d;
          r.best_a[static_cast<std::size_t>(j)] = i;
        }
      }
      if (row_dist < r.best_b_dist[static_cast<std::size_t>(i)]) {  // earlier blocks hold lower columns
        r.best_b_dist[static_cast<std::size_t>(i)] = row_dist;
        r.best_b[static_cast<std::size_t>(i)] = row_best;
      }
    }
  }
}

template <int W>
VMAP_DETAIL_ALWAYS_INLINE void two_nearest_scalar(const std::uint64_t* a, int na, const std::uint64_t* b, int nb,
                                                  int words, TwoNearestResult& r) {
  const std::size_t w = static_cast<std::size_t>(words);
  const int cb = column_block(words, 1);
  for (int j0 = 0; j0 < nb; j0 += cb) {
    const int j1 = std::min(nb, j0 + cb);
    for (int i = 0; i < na; ++i) {
      const std::uint64_t* ai = a + static_cast<std::size_t>(i) * w;
      const std::size_t si = static_cast<std::size_t>(i);
      int d1 = r.best_dist[si], i1 = r.best[si], d2 = r.second_dist[si];
      for (int j = j0; j < j1; ++j) {
        const int d = distance_words<W>(ai, b + static_cast<std::size_t>(j) * w, words);
        if (d < d2) {  // batchDistance's insertion into a sorted pair: equal values go after
          if (d < d1) {
            d2 = d1;
            d1 = d;
            i1 = j;
          } else {
            d2 = d;
          }
        }
      }
      r.best_dist[si] = d1;
      r.best[si] = i1;
      r.second_dist[si] = d2;
    }
  }
}

template <int W>
void mutual_portable(const std::uint64_t* a, int na, const std::uint64_t* b, int nb, int words, MutualResult& r) {
  mutual_scalar<W>(a, na, b, nb, words, r);
}
template <int W>
void two_nearest_portable(const std::uint64_t* a, int na, const std::uint64_t* b, int nb, int words,
                          TwoNearestResult& r) {
  two_nearest_scalar<W>(a, na, b, nb, words, r);
}

#if defined(VMAP_DETAIL_HAMMING_X86)

template <int W>
__attribute__((target("popcnt"))) void mutual_popcnt(const std::uint64_t* a, int na, const std::uint64_t* b, int nb,
                                                     int words, MutualResult& r) {
  mutual_scalar<W>(a, na, b, nb, words, r);
}
template <int W>
__attribute__((target("popcnt"))) void two_nearest_popcnt(const std::uint64_t* a, int na, const std::uint64_t* b,
                                                          int nb, int words, TwoNearestResult& r) {
  two_nearest_scalar<W>(a, na, b, nb, words, r);
}

// ---- AVX2: 8 train descriptors a block, popcount by nibble table (no VPOPCNT) ----------

__attribute__((target("avx2"))) inline __m256i popcount_bytes_avx2(__m256i x) {
  const __m256i table = _mm256_setr_epi8(0, 1, 1, 2, 1, 2, 2, 3, 1, 2, 2, 3, 2, 3, 3, 4,  //
                                         0, 1, 1, 2, 1, 2, 2, 3, 1, 2, 2, 3, 2, 3, 3, 4);
  const __m256i low = _mm256_set1_epi8(0x0f);
  const __m256i lo = _mm256_and_si256(x, low);
  const __m256i hi = _mm256_and_si256(_mm256_srli_epi16(x, 4), low);
  return _mm256_add_epi8(_mm256_shuffle_epi8(table, lo), _mm256_shuffle_epi8(table, hi));
}

/// Distances from one query row (`words` words) to the 8 descriptors of a block, as 8
/// 32-bit lanes in index order.
template <int W>
__attribute__((target("avx2"))) inline __m256i block_distances_avx2(const std::uint64_t* ai, const std::uint64_t* blk,
                                                                   int words) {
  const int n = W > 0 ? W : words;
  const __m256i zero = _mm256_setzero_si256();
  __m256i sum_even = zero, sum_odd = zero;
  for (int k0 = 0; k0 < n; k0 += 31) {  // byte counters hold <= 31 words of 8 bits each
    __m256i acc_even = zero, acc_odd = zero;
    const int k1 = std::min(n, k0 + 31);
    for (int k = k0; k < k1; ++k) {
      const __m256i x = _mm256_set1_epi64x(static_cast<long long>(ai[k]));
      const __m256i* p = reinterpret_cast<const __m256i*>(blk + 8 * k);
      acc_even = _mm256_add_epi8(acc_even, popcount_bytes_avx2(_mm256_xor_si256(x, _mm256_loadu_si256(p))));
      acc_odd = _mm256_add_epi8(acc_odd, popcount_bytes_avx2(_mm256_xor_si256(x, _mm256_loadu_si256(p + 1))));
    }
    sum_even = _mm256_add_epi64(sum_even, _mm256_sad_epu8(acc_even, zero));
    sum_odd = _mm256_add_epi64(sum_odd, _mm256_sad_epu8(acc_odd, zero));
  }
  return _mm256_or_si256(sum_even, _mm256_slli_epi64(sum_odd, 32));
}

/// Lanes at or beyond `valid` of the last block get kNoDistance.
__attribute__((target("avx2"))) inline __m256i padding_avx2(int valid) {
  const __m256i ids = _mm256_setr_epi32(0, 1, 2, 3, 4, 5, 6, 7);
  return _mm256_and_si256(_mm256_cmpgt_epi32(ids, _mm256_set1_epi32(valid - 1)), _mm256_set1_epi32(kNoDistance));
}

template <int W>
__attribute__((target("avx2"))) void mutual_avx2(const std::uint64_t* a, int na, const std::uint64_t* b, int nb,
                                                 int words, MutualResult& r) {
  constexpr int L = 8;
  const std::size_t w = static_cast<std::size_t>(W > 0 ? W : words);
  const int blocks = (nb + L - 1) / L;
  const int cbb = column_block(static_cast<int>(w), L) / L;
  const __m256i ids = _mm256_setr_epi32(0, 1, 2, 3, 4, 5, 6, 7);
  const int valid_last = nb - (blocks - 1) * L;
  const __m256i pad = padding_avx2(valid_last);
  int* const col_dist = r.best_a_dist.data();
  int* const col_best = r.best_a.data();
  for (int t0 = 0; t0 < blocks; t0 += cbb) {
    const int t1 = std::min(blocks, t0 + cbb);
    for (int i = 0; i < na; ++i) {
      const std::uint64_t* ai = a + static_cast<std::size_t>(i) * w;
      const __m256i iv = _mm256_set1_epi32(i);
      __m256i row_dist = _mm256_set1_epi32(kNoDistance), row_best = _mm256_set1_epi32(-1);
      for (int t = t0; t < t1; ++t) {
        __m256i d = block_distances_avx2<W>(ai, b + static_cast<std::size_t>(t) * w * L, static_cast<int>(w));
        if (t == blocks - 1) d = _mm256_or_si256(d, pad);
        const __m256i jv = _mm256_add_epi32(_mm256_set1_epi32(t * L), ids);
        const __m256i closer = _mm256_cmpgt_epi32(row_dist, d);  // strict: first minimum per lane
        row_dist = _mm256_min_epi32(row_dist, d);
        row_best = _mm256_blendv_epi8(row_best, jv, closer);
        __m256i* cd = reinterpret_cast<__m256i*>(col_dist + t * L);
        __m256i* cb = reinterpret_cast<__m256i*>(col_best + t * L);
        const __m256i c = _mm256_loadu_si256(cd);
        const __m256i col_closer = _mm256_cmpgt_epi32(c, d);
        _mm256_storeu_si256(cd, _mm256_min_epi32(c, d));
        _mm256_storeu_si256(cb, _mm256_blendv_epi8(_mm256_loadu_si256(cb), iv, col_closer));
      }
      alignas(32) std::array<int, L> dl, bl;
      _mm256_store_si256(reinterpret_cast<__m256i*>(dl.data()), row_dist);
      _mm256_store_si256(reinterpret_cast<__m256i*>(bl.data()), row_best);
      const std::size_t si = static_cast<std::size_t>(i);
      for (int l = 0; l < L; ++l) {
        const int d = dl[static_cast<std::size_t>(l)], j = bl[static_cast<std::size_t>(l)];
        if (d < r.best_b_dist[si] || (d == r.best_b_dist[si] && j >= 0 && j < r.best_b[si])) {
          r.best_b_dist[si] = d;
          r.best_b[si] = j;
        }
      }
    }
  }
}

template <int W>
__attribute__((target("avx2"))) void two_nearest_avx2(const std::uint64_t* a, int na, const std::uint64_t* b, int nb,
                                                      int words, TwoNearestResult& r) {
  constexpr int L = 8;
  const std::size_t w = static_cast<std::size_t>(W > 0 ? W : words);
  const int blocks = (nb + L - 1) / L;
  const int cbb = column_block(static_cast<int>(w), L) / L;
  const __m256i ids = _mm256_setr_epi32(0, 1, 2, 3, 4, 5, 6, 7);
  const __m256i pad = padding_avx2(nb - (blocks - 1) * L);
  for (int t0 = 0; t0 < blocks; t0 += cbb) {
    const int t1 = std::min(blocks, t0 + cbb);
    for (int i = 0; i < na; ++i) {
      const std::uint64_t* ai = a + static_cast<std::size_t>(i) * w;
      __m256i d1 = _mm256_set1_epi32(kNoDistance), d2 = d1, i1 = _mm256_set1_epi32(-1);
      for (int t = t0; t < t1; ++t) {
        __m256i d = block_distances_avx2<W>(ai, b + static_cast<std::size_t>(t) * w * L, static_cast<int>(w));
        if (t == blocks - 1) d = _mm256_or_si256(d, pad);
        const __m256i jv = _mm256_add_epi32(_mm256_set1_epi32(t * L), ids);
        const __m256i closer = _mm256_cmpgt_epi32(d1, d);
        d2 = _mm256_blendv_epi8(_mm256_min_epi32(d2, d), d1, closer);
        d1 = _mm256_min_epi32(d1, d);
        i1 = _mm256_blendv_epi8(i1, jv, closer);
      }
      alignas(32) std::array<int, L> a1, b1, a2;
      _mm256_store_si256(reinterpret_cast<__m256i*>(a1.data()), d1);
      _mm256_store_si256(reinterpret_cast<__m256i*>(b1.data()), i1);
      _mm256_store_si256(reinterpret_cast<__m256i*>(a2.data()), d2);
      const std::size_t si = static_cast<std::size_t>(i);
      Nearest2 m{r.best_dist[si], r.best[si], r.second_dist[si]};
      for (std::size_t l = 0; l < L; ++l) m = merge(m, {a1[l], b1[l], a2[l]});
      r.best_dist[si] = m.d1;
      r.best[si] = m.i1;
      r.second_dist[si] = m.d2;
    }
  }
}

// ---- AVX-512 VPOPCNTDQ: 16 train descriptors a block -------------------------------------
// The same loops as the AVX2 ones with 16 lanes and mask registers. They are written
// out per level because GCC cannot share one template body between them: a target
// attribute cannot depend on a template parameter, and a function without the
// attribute may not inline the level's intrinsics.

// GCC 12's unmasked _mm512_min_epi32 and _mm512_slli_epi64 start from an "undefined"
// register that -Wmaybe-uninitialized reports once inlined; the zero-masked forms with
// every lane selected are the same instructions without it.
__attribute__((target("avx512f"))) inline __m512i min_epi32_avx512(__m512i x, __m512i y) {
  return _mm512_maskz_min_epi32(static_cast<__mmask16>(0xffff), x, y);
}
__attribute__((target("avx512f"))) inline __m512i high_half_avx512(__m512i x) {
  return _mm512_maskz_slli_epi64(static_cast<__mmask8>(0xff), x, 32);
}

template <int W>
__attribute__((target("avx512f,avx512vpopcntdq"))) inline __m512i block_distances_avx512(const std::uint64_t* ai,
                                                                                         const std::uint64_t* blk,
                                                                                         int words) {
  const int n = W > 0 ? W : words;
  __m512i sum_even = _mm512_setzero_si512(), sum_odd = _mm512_setzero_si512();
  for (int k = 0; k < n; ++k) {
    const __m512i x = _mm512_set1_epi64(static_cast<long long>(ai[k]));
    const std::uint64_t* p = blk + 16 * k;
    sum_even = _mm512_add_epi64(sum_even, _mm512_popcnt_epi64(_mm512_xor_si512(x, _mm512_loadu_si512(p))));
    sum_odd = _mm512_add_epi64(sum_odd, _mm512_popcnt_epi64(_mm512_xor_si512(x, _mm512_loadu_si512(p + 8))));
  }
  return _mm512_or_si512(sum_even, high_half_avx512(sum_odd));
}

/// Lanes at or beyond `valid` of the last block.
inline __mmask16 padding_avx512(int valid) {
  return static_cast<__mmask16>(~((1u << static_cast<unsigned>(valid)) - 1u) & 0xffffu);
}

template <int W>
__attribute__((target("avx512f,avx512vpopcntdq"))) void mutual_avx512(const std::uint64_t* a, int na,
                                                                      const std::uint64_t* b, int nb, int words,
                                                                      MutualResult& r) {
  constexpr int L = 16;
  const std::size_t w = static_cast<std::size_t>(W > 0 ? W : words);
  const int blocks = (nb + L - 1) / L;
  const int cbb = column_block(static_cast<int>(w), L) / L;
  const __m512i ids = _mm512_setr_epi32(0, 1, 2, 3, 4, 5, 6, 7, 8, 9, 10, 11, 12, 13, 14, 15);
  const __mmask16 pad = padding_avx512(nb - (blocks - 1) * L);
  const __m512i none = _mm512_set1_epi32(kNoDistance);
  int* const col_dist = r.best_a_dist.data();
  int* const col_best = r.best_a.data();
  for (int t0 = 0; t0 < blocks; t0 += cbb) {
    const int t1 = std::min(blocks, t0 + cbb);
    for (int i = 0; i < na; ++i) {
      const std::uint64_t* ai = a + static_cast<std::size_t>(i) * w;
      const __m512i iv = _mm512_set1_epi32(i);
      __m512i row_dist = none, row_best = _mm512_set1_epi32(-1);
      for (int t = t0; t < t1; ++t) {
        __m512i d = block_distances_avx512<W>(ai, b + static_cast<std::size_t>(t) * w * L, static_cast<int>(w));
        if (t == blocks - 1) d = _mm512_mask_mov_epi32(d, pad, none);
        const __m512i jv = _mm512_add_epi32(_mm512_set1_epi32(t * L), ids);
        const __mmask16 closer = _mm512_cmpgt_epi32_mask(row_dist, d);
        row_dist = min_epi32_avx512(row_dist, d);
        row_best = _mm512_mask_mov_epi32(row_best, closer, jv);
        int* cd = col_dist + t * L;
        int* cb = col_best + t * L;
        const __m512i c = _mm512_loadu_si512(cd);
        const __mmask16 col_closer = _mm512_cmpgt_epi32_mask(c, d);
        _mm512_storeu_si512(cd, min_epi32_avx512(c, d));
        _mm512_mask_storeu_epi32(cb, col_closer, iv);
      }
      alignas(64) std::array<int, L> dl, bl;
      _mm512_store_si512(dl.data(), row_dist);
      _mm512_store_si512(bl.data(), row_best);
      const std::size_t si = static_cast<std::size_t>(i);
      for (int l = 0; l < L; ++l) {
        const int d = dl[static_cast<std::size_t>(l)], j = bl[static_cast<std::size_t>(l)];
        if (d < r.best_b_dist[si] || (d == r.best_b_dist[si] && j >= 0 && j < r.best_b[si])) {
          r.best_b_dist[si] = d;
          r.best_b[si] = j;
        }
      }
    }
  }
}

template <int W>
__attribute__((target("avx512f,avx512vpopcntdq"))) void two_nearest_avx512(const std::uint64_t* a, int na,
                                                                           const std::uint64_t* b, int nb, int words,
                                                                           TwoNearestResult& r) {
  constexpr int L = 16;
  const std::size_t w = static_cast<std::size_t>(W > 0 ? W : words);
  const int blocks = (nb + L - 1) / L;
  const int cbb = column_block(static_cast<int>(w), L) / L;
  const __m512i ids = _mm512_setr_epi32(0, 1, 2, 3, 4, 5, 6, 7, 8, 9, 10, 11, 12, 13, 14, 15);
  const __mmask16 pad = padding_avx512(nb - (blocks - 1) * L);
  const __m512i none = _mm512_set1_epi32(kNoDistance);
  for (int t0 = 0; t0 < blocks; t0 += cbb) {
    const int t1 = std::min(blocks, t0 + cbb);
    for (int i = 0; i < na; ++i) {
      const std::uint64_t* ai = a + static_cast<std::size_t>(i) * w;
      __m512i d1 = none, d2 = none, i1 = _mm512_set1_epi32(-1);
      for (int t = t0; t < t1; ++t) {
        __m512i d = block_distances_avx512<W>(ai, b + static_cast<std::size_t>(t) * w * L, static_cast<int>(w));
        if (t == blocks - 1) d = _mm512_mask_mov_epi32(d, pad, none);
        const __m512i jv = _mm512_add_epi32(_mm512_set1_epi32(t * L), ids);
        const __mmask16 closer = _mm512_cmpgt_epi32_mask(d1, d);
        d2 = _mm512_mask_mov_epi32(min_epi32_avx512(d2, d), closer, d1);
        d1 = min_epi32_avx512(d1, d);
        i1 = _mm512_mask_mov_epi32(i1, closer, jv);
      }
      alignas(64) std::array<int, L> a1, b1, a2;
      _mm512_store_si512(a1.data(), d1);
      _mm512_store_si512(b1.data(), i1);
      _mm512_store_si512(a2.data(), d2);
      const std::size_t si = static_cast<std::size_t>(i);
      Nearest2 m{r.best_dist[si], r.best[si], r.second_dist[si]};
      for (std::size_t l = 0; l < L; ++l) m = merge(m, {a1[l], b1[l], a2[l]});
      r.best_dist[si] = m.d1;
      r.best[si] = m.i1;
      r.second_dist[si] = m.d2;
    }
  }
}

#endif  // VMAP_DETAIL_HAMMING_X86

/// Lanes a level's train blocks have (1: row-major).
constexpr int hamming_lanes(HammingLevel level) {
  return level == HammingLevel::avx512 ? 16 : level == HammingLevel::avx2 ? 8 : 1;
}

/// Packs a and b for `level` and calls kernel.template run<W>(a, na, b, nb, words) with W
/// the word count when it is an ORB (4) or A-KAZE (8) width, 0 (read at run time) otherwise.
template <class Run>
void with_packed(const cv::Mat& a, const cv::Mat& b, HammingLevel level, HammingScratch& s, Run&& run) {
  const int words = (a.cols + 7) / 8;
  const int lanes = hamming_lanes(level);
  pack_rows(a, words, s.a);
  if (lanes == 1)
    pack_rows(b, words, s.b);
  else
    pack_interleaved(b, words, lanes, s.b);
  if (words == 4)
    run(std::integral_constant<int, 4>{}, words);
  else if (words == 8)
    run(std::integral_constant<int, 8>{}, words);
  else
    run(std::integral_constant<int, 0>{}, words);
}

/// Nearest neighbours both ways between two binary descriptor matrices (CV_8U, same
/// width, continuous rows not required), at `level` (already resolved against the CPU).
inline void mutual_hamming(const cv::Mat& a, const cv::Mat& b, HammingLevel level, HammingScratch& s,
                           MutualResult& r) {
  const int na = a.rows, nb = b.rows;
  const int lanes = hamming_lanes(level);
  const std::size_t padded = static_cast<std::size_t>((nb + lanes - 1) / lanes * lanes);
  r.best_b.assign(static_cast<std::size_t>(na), -1);
  r.best_b_dist.assign(static_cast<std::size_t>(na), kNoDistance);
  r.best_a.assign(padded, -1);
  r.best_a_dist.assign(padded, kNoDistance);
  if (na > 0 && nb > 0) {
    with_packed(a, b, level, s, [&](auto w, int words) {
      constexpr int W = decltype(w)::value;
      const std::uint64_t* pa = s.a.data();
      const std::uint64_t* pb = s.b.data();
      switch (level) {
#if defined(VMAP_DETAIL_HAMMING_X86)
        case HammingLevel::avx512: mutual_avx512<W>(pa, na, pb, nb, words, r); return;
        case HammingLevel::avx2: mutual_avx2<W>(pa, na, pb, nb, words, r); return;
        case HammingLevel::popcnt: mutual_popcnt<W>(pa, na, pb, nb, words, r); return;
#endif
        default: mutual_portable<W>(pa, na, pb, nb, words, r); return;
      }
    });
  }
  r.best_a.resize(static_cast<std::size_t>(nb));
  r.best_a_dist.resize(static_cast<std::size_t>(nb));
}

/// Each row of a's nearest row of b and the two smallest distances, at `level`.
inline void two_nearest_hamming(const cv::Mat& a, const cv::Mat& b, HammingLevel level, HammingScratch& s,
                                TwoNearestResult& r) {
  const int na = a.rows, nb = b.rows;
  r.best.assign(static_cast<std::size_t>(na), -1);
  r.best_dist.assign(static_cast<std::size_t>(na), kNoDistance);
  r.second_dist.assign(static_cast<std::size_t>(na), kNoDistance);
  if (na == 0 || nb == 0) return;
  with_packed(a, b, level, s, [&](auto w, int words) {
    constexpr int W = decltype(w)::value;
    const std::uint64_t* pa = s.a.data();
    const std::uint64_t* pb = s.b.data();
    switch (level) {
#if defined(VMAP_DETAIL_HAMMING_X86)
      case HammingLevel::avx512: two_nearest_avx512<W>(pa, na, pb, nb, words, r); return;
      case HammingLevel::avx2: two_nearest_avx2<W>(pa, na, pb, nb, words, r); return;
      case HammingLevel::popcnt: two_nearest_popcnt<W>(pa, na, pb, nb, words, r); return;
#endif
      default: two_nearest_portable<W>(pa, na, pb, nb, words, r); return;
    }
  });
}

#undef VMAP_DETAIL_ALWAYS_INLINE
#undef VMAP_DETAIL_HAMMING_X86

}  // namespace vmap::detail
