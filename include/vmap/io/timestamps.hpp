#pragma once

// Frame times. Frames carry their time twice: in seconds as a double, for arithmetic
// (association with poses, rates), and in whole nanoseconds as an integer, exact where
// the source states its times in nanoseconds or in decimal seconds (EuRoC's data.csv,
// robot bags' header stamps, TUM's "1305031229.528748"). A double holds a Unix time only
// to about 0.24 us, so exports and key-image records use the integer.
//
// Counts in whole sub-second units (EuRoC's nanoseconds, microsecond and millisecond
// file names) as seconds: a direct division of a 19-digit count would round it to a
// double first; splitting whole seconds from the remainder keeps the double as close as
// it can be.

#include <vmap/core/error.hpp>

#include <cmath>
#include <cstdint>
#include <cstdio>
#include <limits>
#include <optional>
#include <string>
#include <string_view>

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

/// The nearest whole nanosecond of `seconds`, saturated to the int64 range (about +-292
/// years); 0 for NaN.
[[nodiscard]] inline std::int64_t nanoseconds_from_seconds(double seconds) noexcept {
  if (std::isnan(seconds)) return 0;
  const double ns = std::round(seconds * 1e9);
  if (ns >= 9.2e18) return std::numeric_limits<std::int64_t>::max();
  if (ns <= -9.2e18) return std::numeric_limits<std::int64_t>::min();
  return static_cast<std::int64_t>(ns);
}

/// The widest time, in seconds either side of the Unix epoch, that a frame can have: its
/// whole nanoseconds must fit a signed 64-bit integer (INT64_MAX ns is 9223372036.85 s,
/// in the year 2262), with room for a rounding. Inputs with times beyond it (a list, a
/// folder's file names, a bag, an offset) are refused by name, never clamped.
inline constexpr double max_time_seconds = 9.2e9;

/// `seconds` in whole nanoseconds, or nullopt when it is NaN or beyond +-max_time_seconds.
[[nodiscard]] inline std::optional<std::int64_t> nanoseconds_in_range(double seconds) noexcept {
  if (!(std::abs(seconds) <= max_time_seconds)) return std::nullopt;
  return nanoseconds_from_seconds(seconds);
}

/// `t` + `offset` nanoseconds, or nullopt when the sum leaves the int64 range.
[[nodiscard]] inline std::optional<std::int64_t> add_nanoseconds(std::int64_t t, std::int64_t offset) noexcept {
  std::int64_t sum = 0;
  if (__builtin_add_overflow(t, offset, &sum)) return std::nullopt;
  return sum;
}

/// "time 1e+12 s is beyond +-9.2e9 s, the range of nanosecond times (the year 2262)": the
/// words of every refusal of a time out of range ("time nan s is not finite" for a NaN or
/// an infinity, which no range holds).
[[nodiscard]] inline std::string time_out_of_range(double seconds) {
  char text[40];
  std::snprintf(text, sizeof text, "%.17g", seconds);
  if (!std::isfinite(seconds)) return std::string("time ") + text + " s is not finite";
  return std::string("time ") + text + " s is beyond +-9.2e9 s, the range of nanosecond times (the year 2262)";
}

/// `seconds` in whole nanoseconds; an Error "WHAT: time ... s is beyond +-9.2e9 s ..."
/// when it is NaN or out of range (a time a caller gives, e.g. a pushed frame's).
[[nodiscard]] inline std::int64_t frame_time_ns(double seconds, const std::string& what) {
  const auto ns = nanoseconds_in_range(seconds);
  if (!ns) detail::fail(what + ": " + time_out_of_range(seconds));
  return *ns;
}

/// Exact nanoseconds of a decimal number of seconds ("1305031229.528748", "-0.5", "12"):
/// digits beyond the ninth decimal are rounded half up. nullopt when the text is not a
/// plain decimal number (no exponent, no sign other than a leading '-') or is outside
/// +-9.2e9 s.
[[nodiscard]] inline std::optional<std::int64_t> nanoseconds_from_decimal(std::string_view text) noexcept {
  bool negative = false;
  if (!text.empty() && (text.front() == '-' || text.front() == '+')) {
    negative = text.front() == '-';
    text.remove_prefix(1);
  }
  const std::size_t dot = text.find('.');
  const std::string_view whole = text.substr(0, dot);
  const std::string_view frac = dot == std::string_view::npos ? std::string_view() : text.substr(dot + 1);
  if (whole.empty() && frac.empty()) return std::nullopt;
  if (whole.size() > 10) return std::nullopt;
  std::int64_t ns = 0;
  for (char c : whole) {
    if (c < '0' || c > '9') return std::nullopt;
    ns = ns * 10 + (c - '0');
  }
  if (ns > 9200000000LL) return std::nullopt;
  ns *= 1000000000;
  std::int64_t scale = 100000000;
  bool round_up = false;
  for (std::size_t i = 0; i < frac.size(); ++i) {
    const char c = frac[i];
    if (c < '0' || c > '9') return std::nullopt;
    if (i < 9) {
      ns += (c - '0') * scale;
      scale /= 10;
    } else if (i == 9) {
      round_up = c >= '5';
    }
  }
  if (round_up) ++ns;
  if (ns > 9200000000000000000LL) return std::nullopt;
  return negative ? -ns : ns;
}

/// A time of `ns` nanoseconds as exact decimal seconds, trailing zeros dropped
/// ("1305031229.528748", "12", "-0.5").
[[nodiscard]] inline std::string seconds_text(std::int64_t ns) {
  const bool negative = ns < 0;
  const std::uint64_t magnitude = negative ? std::uint64_t{0} - static_cast<std::uint64_t>(ns) : static_cast<std::uint64_t>(ns);
  std::string out = (negative ? "-" : "") + std::to_string(magnitude / 1000000000U);
  std::string fraction = std::to_string(magnitude % 1000000000U);
  fraction.insert(0, 9 - fraction.size(), '0');
  while (!fraction.empty() && fraction.back() == '0') fraction.pop_back();
  if (!fraction.empty()) out += "." + fraction;
  return out;
}

}  // namespace vmap
