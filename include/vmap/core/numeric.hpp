#pragma once

// Checks of numbers at the boundary (command-line options, option structs), so a bad
// value is an Error naming the option ("--start", "--pan") instead of wrapping around
// (-1 read into an unsigned as 18446744073709551615), or failing later in a function
// that cannot know which option fed it ("wrap_angle: the angle is not a finite number").
// And the printing of computed figures that may have overflowed (an error statistic
// of inf): `figure` says so in words instead of printing "inf" as if it were a value.

#include <vmap/core/error.hpp>

#include <charconv>
#include <cmath>
#include <cstdint>
#include <cstdio>
#include <limits>
#include <optional>
#include <string>
#include <string_view>
#include <system_error>

namespace vmap {

/// A whole non-negative number from text, for an unsigned option. A sign ('-' or '+'),
/// junk, an empty string or a value above `max` is an Error naming `option`.
[[nodiscard]] inline std::uint64_t parse_count(std::string_view text, const std::string& option,
                                               std::uint64_t max = std::numeric_limits<std::uint64_t>::max()) {
  const auto bad = [&](const std::string& why) {
    detail::fail(option + ": '" + std::string(text) + "' " + why);
  };
  if (!text.empty() && text.front() == '-') bad("is negative; a whole number >= 0 is expected");
  std::uint64_t v = 0;
  const auto [ptr, ec] = std::from_chars(text.data(), text.data() + text.size(), v);
  if (ec == std::errc::result_out_of_range) bad("is too large");
  if (ec != std::errc() || ptr != text.data() + text.size() || text.empty()) bad("is not a whole number >= 0");
  if (v > max) bad("is above the limit of " + std::to_string(max));
  return v;
}

/// A finite real number from text, for a real-valued option. Junk, nan and inf are
/// an Error naming `option`.
[[nodiscard]] inline double parse_finite(std::string_view text, const std::string& option) {
  const std::string_view digits = text.size() > 1 && text[0] == '+' && text[1] != '-' ? text.substr(1) : text;
  double v = 0.0;
  const auto [ptr, ec] = std::from_chars(digits.data(), digits.data() + digits.size(), v);
  if (ec != std::errc() || ptr != digits.data() + digits.size() || digits.empty())
    detail::fail(option + ": '" + std::string(text) + "' is not a number");
  if (!std::isfinite(v)) detail::fail(option + ": '" + std::string(text) + "' is not a finite number");
  return v;
}

/// Fails unless `value` is finite; `option` names it ("--pan").
inline void check_finite(double value, const std::string& option) {
  detail::check(std::isfinite(value),
                [&] { return option + " must be a finite number, got " + std::to_string(value); });
}

/// Fails unless lo <= value <= hi (and finite); `option` names it.
inline void check_in_range(double value, double lo, double hi, const std::string& option) {
  detail::check(std::isfinite(value) && value >= lo && value <= hi, [&] {
    return option + " must be in [" + std::to_string(lo) + ", " + std::to_string(hi) + "], got " +
           std::to_string(value);
  });
}

/// `value` printed with `decimals` decimals ("%.*f"), or a phrase saying it is not a
/// figure ("not finite (overflow)", "undefined (NaN)") so a report never shows "inf m"
/// as if it were a measurement. Callers that must fail on it test std::isfinite.
[[nodiscard]] inline std::string figure(double value, int decimals = 3) {
  if (std::isnan(value)) return "undefined (NaN)";
  if (std::isinf(value)) return "not finite (overflow)";
  char buf[64];
  std::snprintf(buf, sizeof buf, "%.*f", decimals < 0 ? 0 : decimals > 17 ? 17 : decimals, value);
  return buf;
}

/// The shortest text that reads back as exactly `value` ("0.800000011920929" for 0.8f):
/// for descriptions that are compared as text, such as a policy's `describe()`.
[[nodiscard]] inline std::string exact_text(double value) {
  char buf[40];
  const auto r = std::to_chars(buf, buf + sizeof buf, value);
  return std::string(buf, r.ptr);
}

/// `text` in double quotes, with '"' and '\' escaped by a backslash: a path in a
/// description (a policy's `describe()`) reads back exactly whatever characters it holds.
[[nodiscard]] inline std::string quote_text(std::string_view text) {
  std::string out = "\"";
  for (char c : text) {
    if (c == '"' || c == '\\') out += '\\';
    out += c;
  }
  return out + '"';
}

}  // namespace vmap
