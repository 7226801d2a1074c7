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
  /// "a, b or c": for messages. Only a value's first name: a later one is an old spelling
  /// that still reads back but is no longer offered.
  [[nodiscard]] std::string choices() const {
    std::size_t offered = 0;
    for (std::size_t i = 0; i < N; ++i) offered += first_name(i);
    std::string out;
    std::size_t written = 0;
    for (std::size_t i = 0; i < N; ++i) {
      if (!first_name(i)) continue;
      if (written > 0) out += written + 1 == offered ? " or " : ", ";
      out += entries[i].second;
      ++written;
    }
    return out;
  }

 private:
  [[nodiscard]] constexpr bool first_name(std::size_t i) const noexcept {
    for (std::size_t j = 0; j < i; ++j)
      if (entries[j].first == entries[i].first) return false;
    return true;
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
