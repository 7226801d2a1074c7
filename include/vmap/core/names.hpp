#pragma once

// Names of values, both ways. Every enum a user may give as text (an option in a
// configuration file, a command-line flag, a Python keyword) has one table of names
// (`names_of`) beside it, which its `to_string` and `from_string<T>` both read:
//
//   vmap::from_string<vmap::RobustMethod>("magsac")  // RobustMethod::magsac
//   vmap::from_string<vmap::RobustMethod>("magsak")  // nullopt
//
// `parse<T>(text, what)` is the same with an Error that names `what` and lists the
// names it knows, for inputs that must be valid.

#include <vmap/core/error.hpp>

#include <array>
#include <cstddef>
#include <optional>
#include <string>
#include <string_view>
#include <utility>

namespace vmap {

namespace detail {

/// The names of an enum's values, in one table that both directions read.
template <class T, std::size_t N>
struct NameTable {
  std::array<std::pair<T, std::string_view>, N> entries;

  [[nodiscard]] constexpr std::string_view name(T value) const noexcept {
    for (const auto& [v, n] : entries)
      if (v == value) return n;
    return "unknown";
  }
  [[nodiscard]] constexpr std::optional<T> value(std::string_view text) const noexcept {
    for (const auto& [v, n] : entries)
      if (n == text) return v;
    return std::nullopt;
  }
  /// "a, b or c": for messages.
  [[nodiscard]] std::string choices() const {
    std::string out;
    for (std::size_t i = 0; i < N; ++i) {
      if (i > 0) out += i + 1 == N ? " or " : ", ";
      out += entries[i].second;
    }
    return out;
  }
};

}  // namespace detail

/// Reads back what `to_string(T)` writes; nullopt for any other text. T's header
/// declares `constexpr auto names_of(T)`, the detail::NameTable both directions read.
template <class T>
[[nodiscard]] constexpr std::optional<T> from_string(std::string_view text) noexcept {
  return names_of(T{}).value(text);
}

/// from_string with an Error naming `what` ("--estimator: unknown name 'x' (choose
/// magsac, ransac, lmeds or 8point)") when the text is not a name of T.
template <class T>
[[nodiscard]] T parse(std::string_view text, const std::string& what) {
  if (auto v = from_string<T>(text)) return *v;
  detail::fail(what + ": unknown name '" + std::string(text) + "' (choose " + names_of(T{}).choices() + ")");
}

}  // namespace vmap
