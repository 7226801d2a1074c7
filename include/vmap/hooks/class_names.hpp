#pragma once

// Class names of a detector, one per line in output order (e.g. coco80.names).

#include <vmap/core/error.hpp>
#include <vmap/io/detail/lines.hpp>
#include <vmap/io/files.hpp>

#include <cstdint>
#include <filesystem>
#include <string>
#include <string_view>
#include <system_error>
#include <vector>

namespace vmap {

/// Class names from the text of a names file: one class name per line, line i naming
/// label i. Trailing whitespace (and '\r') is removed; empty lines are kept only between
/// names (a file may end with blank lines). A text without any name is an Error naming
/// `name`.
[[nodiscard]] inline std::vector<std::string> parse_class_names(std::string_view text,
                                                                const std::string& name = "<class names>") {
  std::vector<std::string> names;
  detail::for_each_line(text, [&](std::string_view line, std::size_t) {
    const auto last = line.find_last_not_of(" \t\r");
    names.emplace_back(last == std::string_view::npos ? std::string_view() : line.substr(0, last + 1));
  });
  while (!names.empty() && names.back().empty()) names.pop_back();
  if (names.empty()) detail::fail("class names file '" + name + "' contains no class name");
  return names;
}

/// Reads a names file (format: parse_class_names). Errors: a missing or unreadable
/// file, a folder or a non-regular file (a device such as /dev/zero), a file larger
/// than 1 MiB (no real class list is that long), a file without any name.
[[nodiscard]] inline std::vector<std::string> read_class_names(const std::filesystem::path& path) {
  constexpr std::uintmax_t max_bytes = 1u << 20;
  return parse_class_names(read_text_file(path, "class names file", max_bytes), path.string());
}

/// The name of `label`, or "class <label>" when the list does not cover it.
[[nodiscard]] inline std::string class_name(const std::vector<std::string>& names, int label) {
  if (label >= 0 && static_cast<std::size_t>(label) < names.size() && !names[static_cast<std::size_t>(label)].empty())
    return names[static_cast<std::size_t>(label)];
  return "class " + std::to_string(label);
}

}  // namespace vmap
