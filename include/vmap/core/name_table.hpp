#pragma once

// The table behind every enum's names (see core/names.hpp for how it is used). It
// lives apart from names.hpp, which raises Errors, so that core/error.hpp can name its
// own ErrorKind values with it without including itself.

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

}  // namespace vmap
