#pragma once

// Timestamps in whole sub-second units (EuRoC's nanoseconds, microsecond and millisecond
// file names) as seconds. A direct division of a 19-digit count would round it to a
// double first; splitting whole seconds from the remainder keeps it exact to the unit at
// Unix times.

#include <cstdint>

namespace vmap {

/// Seconds from `count` units of 1/`per_second` s (per_second >= 1).
[[nodiscard]] inline double seconds_from_count(std::uint64_t count, std::uint64_t per_second) noexcept {
  return static_cast<double>(count / per_second) +
         static_cast<double>(count % per_second) / static_cast<double>(per_second);
}

/// Seconds from a whole number of nanoseconds.
[[nodiscard]] inline double seconds_from_nanoseconds(std::uint64_t ns) noexcept {
  return seconds_from_count(ns, 1000000000ULL);
}

}  // namespace vmap
