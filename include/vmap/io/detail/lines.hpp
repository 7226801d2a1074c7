#pragma once

// Line-by-line reading of a text file held in memory, shared by the text formats
// (pose files, ground-truth matrices) so that every parser counts lines the same way
// for its "file:line" error messages.

#include <cstddef>
#include <string_view>

namespace vmap::detail {

/// Calls f(line, line_number) for every line of `text` (1-based numbers; the '\n' is
/// not part of the line, a trailing '\r' is).
template <class F>
void for_each_line(std::string_view text, F&& f) {
  std::size_t line_no = 0;
  for (std::size_t pos = 0; pos < text.size();) {
    const std::size_t nl = text.find('\n', pos);
    const std::size_t end = nl == std::string_view::npos ? text.size() : nl;
    f(text.substr(pos, end - pos), ++line_no);
    pos = end + 1;
  }
}

}  // namespace vmap::detail
