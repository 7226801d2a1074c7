#pragma once

// CRC-32C (Castagnoli, reflected polynomial 0x82F63B78; RFC 3720 appendix B.4), the
// checksum of the vocabulary files of format version 2. x86-64 has it in hardware (the
// SSE 4.2 `crc32` instruction); the library is compiled without -march, so the hardware
// path is a function compiled for SSE 4.2 and chosen at run time when the CPU has it,
// with a portable slicing-by-8 path otherwise. The two give the same value (tested).
//
// The hardware path runs three independent streams over three thirds of each block (the
// instruction has a latency of 3 cycles and a throughput of 1), then joins them: the CRC
// of A||B is the CRC of A advanced over |B| zero bytes, xor the raw CRC of B. Advancing
// over a fixed number of zero bytes is linear in the 32-bit state, so it is 4 table
// lookups (tables built once from the instruction itself).

#include <array>
#include <cstddef>
#include <cstdint>
#include <cstring>
#include <string_view>

#if defined(__x86_64__) && (defined(__GNUC__) || defined(__clang__))
#include <nmmintrin.h>
#define VMAP_CRC32C_HARDWARE 1
#endif

namespace vmap::detail {

inline constexpr std::uint32_t crc32c_polynomial = 0x82F63B78U;

/// Slicing-by-8 tables of the reflected CRC of polynomial `Poly` (table k advances a
/// byte that is followed by k more; Intel's slicing-by-8).
template <std::uint32_t Poly>
inline constexpr std::array<std::array<std::uint32_t, 256>, 8> crc_slices = [] {
  std::array<std::array<std::uint32_t, 256>, 8> t{};
  for (std::uint32_t i = 0; i < 256; ++i) {
    std::uint32_t c = i;
    for (int k = 0; k < 8; ++k) c = (c & 1U) ? Poly ^ (c >> 1) : c >> 1;
    t[0][i] = c;
  }
  for (std::size_t i = 0; i < 256; ++i)
    for (std::size_t k = 1; k < 8; ++k) t[k][i] = (t[k - 1][i] >> 8) ^ t[0][t[k - 1][i] & 0xFFU];
  return t;
}();

/// Raw update (no initial or final inversion) of the reflected CRC of polynomial `Poly`,
/// eight bytes a step.
template <std::uint32_t Poly>
inline std::uint32_t crc_update_sliced(std::uint32_t c, const unsigned char* p, std::size_t n) noexcept {
  const auto& t = crc_slices<Poly>;
  while (n >= 8) {
    const std::uint32_t lo = c ^ (static_cast<std::uint32_t>(p[0]) | static_cast<std::uint32_t>(p[1]) << 8 |
                                  static_cast<std::uint32_t>(p[2]) << 16 | static_cast<std::uint32_t>(p[3]) << 24);
    const std::uint32_t hi = static_cast<std::uint32_t>(p[4]) | static_cast<std::uint32_t>(p[5]) << 8 |
                             static_cast<std::uint32_t>(p[6]) << 16 | static_cast<std::uint32_t>(p[7]) << 24;
    c = t[7][lo & 0xFFU] ^ t[6][(lo >> 8) & 0xFFU] ^ t[5][(lo >> 16) & 0xFFU] ^ t[4][lo >> 24] ^ t[3][hi & 0xFFU] ^
        t[2][(hi >> 8) & 0xFFU] ^ t[1][(hi >> 16) & 0xFFU] ^ t[0][hi >> 24];
    p += 8;
    n -= 8;
  }
  while (n-- > 0) c = t[0][(c ^ *p++) & 0xFFU] ^ (c >> 8);
  return c;
}

/// Raw CRC-32C update, portable.
inline std::uint32_t crc32c_update_portable(std::uint32_t c, const unsigned char* p, std::size_t n) noexcept {
  return crc_update_sliced<crc32c_polynomial>(c, p, n);
}

#ifdef VMAP_CRC32C_HARDWARE

/// Bytes per stream of the three-stream loop.
inline constexpr std::size_t crc32c_stripe = 4096;

__attribute__((target("sse4.2"))) inline std::uint32_t crc32c_hw_serial(std::uint32_t c, const unsigned char* p,
                                                                          std::size_t n) noexcept {
  std::uint64_t c64 = c;
  while (n >= 8) {
    std::uint64_t v;
    std::memcpy(&v, p, 8);
    c64 = _mm_crc32_u64(c64, v);
    p += 8;
    n -= 8;
  }
  auto c32 = static_cast<std::uint32_t>(c64);
  while (n-- > 0) c32 = _mm_crc32_u8(c32, *p++);
  return c32;
}

/// The linear map "advance the raw state over crc32c_stripe zero bytes", as four byte
/// tables: shift(c) = t[0][c & 0xFF] ^ t[1][(c >> 8) & 0xFF] ^ ...
struct Crc32cShift {
  std::array<std::array<std::uint32_t, 256>, 4> t{};
  Crc32cShift() {
    static const std::array<unsigned char, crc32c_stripe> zeros{};
    std::array<std::uint32_t, 32> basis{};
    for (int b = 0; b < 32; ++b) basis[static_cast<std::size_t>(b)] = crc32c_hw_serial(1U << b, zeros.data(), zeros.size());
    for (std::size_t k = 0; k < 4; ++k)
      for (std::uint32_t v = 0; v < 256; ++v) {
        std::uint32_t s = 0;
        for (int b = 0; b < 8; ++b)
          if ((v >> b) & 1U) s ^= basis[k * 8 + static_cast<std::size_t>(b)];
        t[k][v] = s;
      }
  }
  [[nodiscard]] std::uint32_t operator()(std::uint32_t c) const noexcept {
    return t[0][c & 0xFFU] ^ t[1][(c >> 8) & 0xFFU] ^ t[2][(c >> 16) & 0xFFU] ^ t[3][c >> 24];
  }
};

__attribute__((target("sse4.2"))) inline std::uint32_t crc32c_update_hardware(std::uint32_t c, const unsigned char* p,
                                                                                std::size_t n) noexcept {
  static const Crc32cShift shift;
  while (n >= 3 * crc32c_stripe) {
    std::uint64_t a = c, b = 0, d = 0;
    const unsigned char* pb = p + crc32c_stripe;
    const unsigned char* pd = p + 2 * crc32c_stripe;
    for (std::size_t i = 0; i < crc32c_stripe; i += 8) {
      std::uint64_t va, vb, vd;
      std::memcpy(&va, p + i, 8);
      std::memcpy(&vb, pb + i, 8);
      std::memcpy(&vd, pd + i, 8);
      a = _mm_crc32_u64(a, va);
      b = _mm_crc32_u64(b, vb);
      d = _mm_crc32_u64(d, vd);
    }
    c = shift(shift(static_cast<std::uint32_t>(a)) ^ static_cast<std::uint32_t>(b)) ^ static_cast<std::uint32_t>(d);
    p += 3 * crc32c_stripe;
    n -= 3 * crc32c_stripe;
  }
  return crc32c_hw_serial(c, p, n);
}

inline bool crc32c_hardware_available() noexcept {
  static const bool yes = __builtin_cpu_supports("sse4.2");
  return yes;
}

#else

inline bool crc32c_hardware_available() noexcept { return false; }

#endif

/// Raw CRC-32C update, the fastest path this CPU has. `portable_only` forces the
/// portable one (tests compare both).
inline std::uint32_t crc32c_update(std::uint32_t c, const void* data, std::size_t n, bool portable_only = false) noexcept {
  const auto* p = static_cast<const unsigned char*>(data);
#ifdef VMAP_CRC32C_HARDWARE
  if (!portable_only && crc32c_hardware_available()) return crc32c_update_hardware(c, p, n);
#endif
  (void)portable_only;
  return crc32c_update_portable(c, p, n);
}

/// CRC-32C of `bytes` (check value of "123456789": 0xE3069283).
inline std::uint32_t crc32c(std::string_view bytes, bool portable_only = false) noexcept {
  return crc32c_update(0xFFFFFFFFU, bytes.data(), bytes.size(), portable_only) ^ 0xFFFFFFFFU;
}

}  // namespace vmap::detail
