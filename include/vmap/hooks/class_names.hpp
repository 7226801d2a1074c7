#pragma once

// Class names of a detector, one per line in output order (e.g. coco80.names).

#include <vmap/core/error.hpp>
#include <vmap/io/files.hpp>

#include <cstdint>
#include <filesystem>
#include <sstream>
#include <string>
#include <system_error>
#include <vector>

namespace vmap {

/// Reads a names file: one class name per line, line i naming label i. Trailing
/// whitespace (and '\r') is removed; empty lines are kept only between names (a file
/// may end with blank lines). Errors: a missing or unreadable file, a folder or a
/// non-regular file (a device such as /dev/zero), a file larger than 1 MiB (no real
/// class list is that long), a file without any name.
[[nodiscard]] inline std::vector<std::string> read_class_names(const std::filesystem::path& path) {
  constexpr std::uintmax_t max_bytes = 1u << 20;
  const std::string text = read_text_file(path, "class names file", max_bytes);
  std::vector<std::string> names;
  std::istringstream in(text);
  std::string line;
  while (std::getline(in, line)) {
    const auto last = line.find_last_not_of(" \t\r");
    names.push_back(last == std::string::npos ? std::string() : line.substr(0, last + 1));
  }
  while (!names.empty() && names.back().empty()) names.pop_back();
  if (names.empty()) detail::fail("class names file '" + path.string() + "' contains no class name");
  return names;
}

/// The name of `label`, or "class <label>" when the list does not cover it.
[[nodiscard]] inline std::string class_name(const std::vector<std::string>& names, int label) {
  if (label >= 0 && static_cast<std::size_t>(label) < names.size() && !names[static_cast<std::size_t>(label)].empty())
    return names[static_cast<std::size_t>(label)];
  return "class " + std::to_string(label);
}

}  // namespace vmap
