#pragma once

// The nearest of `count` consecutive rows (a vocabulary node's children, stored one
// after another) to a binary descriptor, by Hamming distance; ties go to the first row,
// as DBoW2's and FBoW's descent does. The library is compiled without -march, where
// std::popcount is a bit-twiddling sequence; the POPCNT instruction is used through a
// function compiled for it and chosen at run time, with the portable loop otherwise
// (tests compare both on every row count).

#include <bit>
#include <cstddef>
#include <cstdint>
#include <cstring>

namespace vmap::detail {

/// Index (0..count-1) of the row of `cols` bytes (rows `stride` bytes apart) nearest to
/// `q`; count >= 1.
using NearestRowFn = std::uint32_t (*)(const std::uint8_t* q, const std::uint8_t* rows, std::uint32_t count,
                                       std::size_t cols, std::size_t stride) noexcept;

// The body, instantiated once per instruction set (the popcount inside follows the
// enclosing function's target).
#define VMAP_NEAREST_ROW_BODY                                                                      \
  std::uint32_t best = 0;                                                                          \
  std::uint32_t best_d = ~0U;                                                                      \
  if (cols == 32) {                                                                                \
    std::uint64_t a[4];                                                                            \
    std::memcpy(a, q, 32);                                                                         \
    for (std::uint32_t r = 0; r < count; ++r) {                                                    \
      std::uint64_t b[4];                                                                          \
      std::memcpy(b, rows + r * stride, 32);                                                       \
      const auto d = static_cast<std::uint32_t>(std::popcount(a[0] ^ b[0]) + std::popcount(a[1] ^ b[1]) + \
                                                std::popcount(a[2] ^ b[2]) + std::popcount(a[3] ^ b[3])); \
      if (d < best_d) {                                                                            \
        best_d = d;                                                                                \
        best = r;                                                                                  \
      }                                                                                            \
    }                                                                                              \
    return best;                                                                                   \
  }                                                                                                \
  for (std::uint32_t r = 0; r < count; ++r) {                                                      \
    const std::uint8_t* row = rows + r * stride;                                                   \
    std::uint32_t d = 0;                                                                           \
    std::size_t i = 0;                                                                             \
    for (; i + 8 <= cols; i += 8) {                                                                \
      std::uint64_t x, y;                                                                          \
      std::memcpy(&x, q + i, 8);                                                                   \
      std::memcpy(&y, row + i, 8);                                                                 \
      d += static_cast<std::uint32_t>(std::popcount(x ^ y));                                       \
    }                                                                                              \
    for (; i < cols; ++i) d += static_cast<std::uint32_t>(std::popcount(static_cast<unsigned>(q[i] ^ row[i]))); \
    if (d < best_d) {                                                                              \
      best_d = d;                                                                                  \
      best = r;                                                                                    \
    }                                                                                              \
  }                                                                                                \
  return best;

/// The kernel, inlined into its caller so that it follows the caller's instruction set
/// (a caller compiled for POPCNT gets the instruction).
[[gnu::always_inline]] inline std::uint32_t nearest_row_inline(const std::uint8_t* q, const std::uint8_t* rows,
                                                                std::uint32_t count, std::size_t cols,
                                                                std::size_t stride) noexcept {
  VMAP_NEAREST_ROW_BODY
}

#undef VMAP_NEAREST_ROW_BODY

inline std::uint32_t nearest_row_portable(const std::uint8_t* q, const std::uint8_t* rows, std::uint32_t count,
                                          std::size_t cols, std::size_t stride) noexcept {
  return nearest_row_inline(q, rows, count, cols, stride);
}

#if defined(__x86_64__) && (defined(__GNUC__) || defined(__clang__))
#define VMAP_HAMMING_POPCNT 1
__attribute__((target("popcnt"))) inline std::uint32_t nearest_row_popcnt(const std::uint8_t* q, const std::uint8_t* rows,
                                                                            std::uint32_t count, std::size_t cols,
                                                                            std::size_t stride) noexcept {
  return nearest_row_inline(q, rows, count, cols, stride);
}

inline bool popcnt_available() noexcept {
  static const bool yes = __builtin_cpu_supports("popcnt");
  return yes;
}
#else
inline bool popcnt_available() noexcept { return false; }
#endif

/// The fastest kernel this CPU runs; `portable_only` forces the portable one.
inline NearestRowFn nearest_row_kernel(bool portable_only = false) noexcept {
#if defined(__x86_64__) && (defined(__GNUC__) || defined(__clang__))
  if (popcnt_available() && !portable_only) return nearest_row_popcnt;
#endif
  (void)portable_only;
  return nearest_row_portable;
}

}  // namespace vmap::detail
