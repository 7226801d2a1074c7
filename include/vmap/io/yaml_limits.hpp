#pragma once

// Bounds checked on YAML text BEFORE OpenCV's FileStorage parses it. OpenCV's YAML
// parser recurses once per nesting level, so a small file nested tens of thousands of
// levels deep ("[[[[...", "- - - - ...") overflows the stack; calibration and settings
// files are a few levels deep and a few kilobytes long, so both bounds are generous.
// OpenCV 4.6's parser also never returns on some short inputs (see yaml_top_level_error),
// so the lines at the top level are checked too.

#include <vmap/core/error.hpp>

#include <algorithm>
#include <cctype>
#include <cstddef>
#include <optional>
#include <string>
#include <string_view>
#include <vector>

namespace vmap {

/// Largest YAML calibration or settings file read (bytes).
inline constexpr std::size_t max_yaml_bytes = std::size_t{1} << 20;  // 1 MiB

/// Deepest nesting accepted in such a file (flow brackets, indentation levels and "- "
/// sequence markers counted together).
inline constexpr std::size_t max_yaml_depth = 32;

/// Nesting depth of YAML text: the indentation levels open at a line, plus its leading
/// "- " markers, plus the "[" / "{" brackets open inside it; text inside quotes and
/// comments is skipped; brackets that span lines stay on top of the block levels open
/// where they began. An over-estimate for odd but valid YAML is harmless here: it only
/// has to stay below `max_yaml_depth` for real calibration and settings files.
[[nodiscard]] inline std::size_t yaml_depth(std::string_view text) {
  std::size_t deepest = 0;
  std::size_t flow = 0;              // open brackets, may span lines
  std::size_t block = 0;             // block levels open where the open brackets began
  std::vector<std::size_t> indents;  // indentation of the open block levels
  std::size_t i = 0;
  while (i < text.size()) {
    const std::size_t end = std::min(text.find('\n', i), text.size());
    const std::string_view line = text.substr(i, end - i);
    i = end + 1;
    std::size_t p = line.find_first_not_of(' ');
    if (p == std::string_view::npos || line[p] == '#' || line[p] == '\r' || line[p] == '%') continue;
    if (flow == 0) {
      while (!indents.empty() && indents.back() >= p) indents.pop_back();
      indents.push_back(p);
      block = indents.size();
      // "- - - x": every marker opens one more sequence level on the same line.
      while (p + 1 < line.size() && (line[p] == '-' || line[p] == '?') && (line[p + 1] == ' ' || line[p + 1] == '\t')) {
        ++block;
        p = line.find_first_not_of(" \t", p + 1);
        if (p == std::string_view::npos) break;
      }
      if (p == std::string_view::npos) p = line.size();
    }
    char quote = 0;
    for (std::size_t k = p; k < line.size(); ++k) {
      const char c = line[k];
      if (quote != 0) {
        if (c == quote) quote = 0;
        continue;
      }
      if (c == '"' || c == '\'') {
        quote = c;
      } else if (c == '#' && (k == 0 || line[k - 1] == ' ' || line[k - 1] == '\t')) {
        break;
      } else if (c == '[' || c == '{') {
        ++flow;
        deepest = std::max(deepest, block + flow);
      } else if ((c == ']' || c == '}') && flow > 0) {
        --flow;
      }
    }
    deepest = std::max(deepest, block + flow);
  }
  return deepest;
}

/// Why YAML text is refused at its top level (column 0), or nothing. After it has read a
/// document, OpenCV 4.6's YAMLParser::parse loops forever, without advancing, when the
/// text goes on with a '-' that does not start "---" (for example "----x", or "- item"
/// at column 0 after a map), and a second document can end the same way. Calibration,
/// settings and vocabulary files are one map of keys, so at column 0 only keys,
/// comments, directives (before the document), one "---" before the first key and
/// "..." are accepted.
[[nodiscard]] inline std::optional<std::string> yaml_top_level_error(std::string_view text) {
  bool content = false;  // the document has begun
  bool key = false;      // a line at column 0 has begun a key
  std::size_t number = 0;
  std::size_t i = 0;
  while (i < text.size()) {
    const std::size_t end = std::min(text.find('\n', i), text.size());
    std::string_view line = text.substr(i, end - i);
    i = end + 1;
    ++number;
    while (!line.empty() && (line.back() == '\r' || line.back() == ' ')) line.remove_suffix(1);
    if (line.empty() || line[0] == '#') continue;
    const char c = line[0];
    const std::string at = "line " + std::to_string(number) + " ";
    if (c == ' ' || c == '\t') {
      if (!key) return at + "is indented before the first key at column 0";
    } else if (c == '%') {
      if (content) return at + "is a directive ('%') after the document began";
    } else if (line == "---") {
      if (content) return at + "starts a second YAML document ('---'); one document is read";
      content = true;
    } else if (line == "...") {
      content = true;
    } else if (std::isalnum(static_cast<unsigned char>(c)) != 0 || c == '_' || c == '"' || c == '\'') {
      content = true;
      key = true;
    } else {
      return at + "starts with '" + std::string(1, c) + "' at the top level, where a key is expected (the file must be a map of keys)";
    }
  }
  return std::nullopt;
}

/// Fails (vmap::Error naming `name`) when YAML text is larger than `max_bytes` or nested
/// deeper than `max_depth`; called before the text reaches cv::FileStorage.
inline void check_yaml_limits(std::string_view text, const std::string& name, std::size_t max_bytes = max_yaml_bytes,
                              std::size_t max_depth = max_yaml_depth) {
  if (text.size() > max_bytes)
    detail::fail(name + ": " + std::to_string(text.size()) + " bytes, more than the " + std::to_string(max_bytes) +
                 " a YAML settings or calibration file may have");
  const std::size_t depth = yaml_depth(text);
  if (depth > max_depth)
    detail::fail(name + ": YAML nested " + std::to_string(depth) + " levels deep, more than the " +
                 std::to_string(max_depth) + " accepted");
}

/// Fails (vmap::Error naming `name`) when YAML text is not a map of keys at its top level
/// (yaml_top_level_error); called on the text exactly as cv::FileStorage will get it.
inline void check_yaml_top_level(std::string_view text, const std::string& name) {
  if (const auto why = yaml_top_level_error(text)) detail::fail(name + ": " + *why);
}

}  // namespace vmap
