#pragma once

// Which instruction set the Hamming matcher kernels use (detail/hamming.hpp). The
// library is compiled without -march: every level is built with GCC target attributes
// and chosen at run time from what the CPU reports, capped by the caller's request
// (BruteForceOptions::hamming_level, else the environment variable VMAP_HAMMING_LEVEL),
// so that every level can be measured and tested on one machine.

#include <vmap/core/error.hpp>
#include <vmap/core/name_table.hpp>

#include <cstdlib>
#include <optional>
#include <string>
#include <string_view>

namespace vmap {

/// Kernel levels, lowest first; each one's results are identical to `portable`'s.
enum class HammingLevel {
  portable,  ///< plain C++ (__builtin_popcountll, no CPU-specific instruction)
  popcnt,    ///< the 64-bit POPCNT instruction, one descriptor word at a time
  avx2,      ///< 256-bit XOR + nibble-table popcount, 8 train descriptors at a time
  avx512,    ///< AVX-512F + VPOPCNTDQ: 512-bit XOR + popcount, 16 train descriptors at a time
};

/// portable, popcnt, avx2, avx512 (core/names.hpp).
[[nodiscard]] constexpr auto names_of(HammingLevel) noexcept {
  return detail::NameTable<HammingLevel, 4>{{{{HammingLevel::portable, "portable"},
                                              {HammingLevel::popcnt, "popcnt"},
                                              {HammingLevel::avx2, "avx2"},
                                              {HammingLevel::avx512, "avx512"}}}};
}
[[nodiscard]] constexpr std::string_view to_string(HammingLevel level) noexcept { return names_of(level).name(level); }

/// The level named `name` (portable, popcnt, avx2, avx512); an Error naming `where` otherwise.
[[nodiscard]] inline HammingLevel parse_hamming_level(std::string_view name, std::string_view where) {
  if (const auto level = from_string<HammingLevel>(name)) return *level;
  detail::fail(std::string(where) + ": unknown Hamming kernel level '" + std::string(name) +
               "' (expected portable, popcnt, avx2 or avx512)");
}

/// The highest level this CPU (and its operating system) supports; checked once.
[[nodiscard]] inline HammingLevel cpu_hamming_level() noexcept {
#if defined(__GNUC__) && (defined(__x86_64__) || defined(__i386__))
  static const HammingLevel level = [] {
    __builtin_cpu_init();
    if (__builtin_cpu_supports("avx512f") && __builtin_cpu_supports("avx512vpopcntdq")) return HammingLevel::avx512;
    if (__builtin_cpu_supports("avx2")) return HammingLevel::avx2;
    if (__builtin_cpu_supports("popcnt")) return HammingLevel::popcnt;
    return HammingLevel::portable;
  }();
  return level;
#else
  return HammingLevel::portable;
#endif
}

/// The level the kernels run at: `requested` (else VMAP_HAMMING_LEVEL, else the
/// highest), lowered to what the CPU supports, so forcing a level the CPU lacks falls
/// back to the best one it has instead of faulting.
[[nodiscard]] inline HammingLevel resolve_hamming_level(std::optional<HammingLevel> requested) {
  HammingLevel want = HammingLevel::avx512;
  if (requested) {
    want = *requested;
  } else if (const char* env = std::getenv("VMAP_HAMMING_LEVEL"); env != nullptr && *env != '\0') {
    want = parse_hamming_level(env, "environment variable VMAP_HAMMING_LEVEL");
  }
  const HammingLevel cpu = cpu_hamming_level();
  return want < cpu ? want : cpu;
}

}  // namespace vmap
