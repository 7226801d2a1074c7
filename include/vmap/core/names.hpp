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
#include <vmap/core/name_table.hpp>

#include <string>
#include <string_view>

namespace vmap {

/// from_string with an Error naming `what` ("--estimator: unknown name 'x' (choose
/// magsac, ransac, lmeds or 8point)") when the text is not a name of T.
template <class T>
[[nodiscard]] T parse(std::string_view text, const std::string& what) {
  if (auto v = from_string<T>(text)) return *v;
  detail::fail(what + ": unknown name '" + std::string(text) + "' (choose " + names_of(T{}).choices() + ")");
}

}  // namespace vmap
