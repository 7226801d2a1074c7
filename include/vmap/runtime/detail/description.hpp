#pragma once

// Reading back the text a policy's describe() writes (core/concepts.hpp, DescribesItself):
// "Name key=value key=(nested text) key=[a b c] key=\"quoted text\"". Values never hold
// an unbalanced bracket: describe() writes numbers, names, nested descriptions in
// parentheses, lists in square brackets and paths quoted (core/numeric.hpp, quote_text).

#include <vmap/core/error.hpp>
#include <vmap/core/numeric.hpp>

#include <charconv>
#include <cmath>
#include <cstddef>
#include <optional>
#include <string>
#include <string_view>
#include <system_error>
#include <utility>
#include <vector>

namespace vmap::detail {

/// One description: its name (the first word) and its key=value fields in order.
struct Description {
  std::string name;
  std::vector<std::pair<std::string, std::string>> fields;  ///< values unquoted; nested ones without their brackets

  [[nodiscard]] std::optional<std::string> get(std::string_view key) const {
    for (const auto& [k, v] : fields)
      if (k == key) return v;
    return std::nullopt;
  }
};

/// Splits `text` into a Description; nullopt when it is not one (an unbalanced bracket,
/// an unterminated quote, a field without '=').
[[nodiscard]] inline std::optional<Description> read_description(std::string_view text) {
  Description d;
  std::size_t i = 0;
  const auto skip_spaces = [&] {
    while (i < text.size() && text[i] == ' ') ++i;
  };
  skip_spaces();
  const std::size_t name_end = text.find(' ', i);
  d.name = std::string(text.substr(i, name_end == std::string_view::npos ? std::string_view::npos : name_end - i));
  if (d.name.empty() || d.name.find('=') != std::string::npos) return std::nullopt;
  i = name_end == std::string_view::npos ? text.size() : name_end;
  for (;;) {
    skip_spaces();
    if (i >= text.size()) return d;
    const std::size_t eq = text.find('=', i);
    if (eq == std::string_view::npos) return std::nullopt;
    std::string key(text.substr(i, eq - i));
    if (key.empty() || key.find(' ') != std::string::npos) return std::nullopt;
    i = eq + 1;
    std::string value;
    if (i < text.size() && text[i] == '"') {
      ++i;
      bool closed = false;
      while (i < text.size()) {
        const char c = text[i++];
        if (c == '\\' && i < text.size()) {
          value += text[i++];
        } else if (c == '"') {
          closed = true;
          break;
        } else {
          value += c;
        }
      }
      if (!closed) return std::nullopt;
    } else if (i < text.size() && (text[i] == '(' || text[i] == '[')) {
      const char open = text[i], close = open == '(' ? ')' : ']';
      int depth = 0;
      const std::size_t start = i;
      bool quoted = false;
      for (; i < text.size(); ++i) {
        const char c = text[i];
        if (quoted) {
          if (c == '\\') ++i;
          else if (c == '"') quoted = false;
          continue;
        }
        if (c == '"') quoted = true;
        else if (c == open) ++depth;
        else if (c == close && --depth == 0) break;
      }
      if (i >= text.size()) return std::nullopt;
      value = std::string(text.substr(start + 1, i - start - 1));
      ++i;
    } else {
      const std::size_t end = text.find(' ', i);
      value = std::string(text.substr(i, end == std::string_view::npos ? std::string_view::npos : end - i));
      i = end == std::string_view::npos ? text.size() : end;
    }
    d.fields.emplace_back(std::move(key), std::move(value));
  }
}

/// A whole decimal number of `text`, or nullopt.
[[nodiscard]] inline std::optional<long long> integer_of(std::string_view text) {
  long long v = 0;
  const auto [ptr, ec] = std::from_chars(text.data(), text.data() + text.size(), v);
  if (ec != std::errc() || ptr != text.data() + text.size()) return std::nullopt;
  return v;
}

/// A finite number of `text` (exact_text writes the shortest form that reads back), or nullopt.
[[nodiscard]] inline std::optional<double> real_of(std::string_view text) {
  double v = 0;
  const auto [ptr, ec] = std::from_chars(text.data(), text.data() + text.size(), v);
  if (ec != std::errc() || ptr != text.data() + text.size() || !std::isfinite(v)) return std::nullopt;
  return v;
}

}  // namespace vmap::detail
