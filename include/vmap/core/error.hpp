#pragma once

#include <stdexcept>
#include <string>

namespace vmap {

/// Thrown for invalid arguments and unreadable inputs. The message names the input
/// (a file, an option, an image) and what was wrong with it. Expected outcomes (no
/// features, degenerate geometry, no loop) are values, never an Error.
class Error : public std::runtime_error {
 public:
  using std::runtime_error::runtime_error;
};

namespace detail {

[[noreturn]] inline void fail(const std::string& what) { throw Error(what); }

/// Always-on precondition check (release builds too): invalid input must never be a
/// silent wrong answer.
inline void check(bool condition, const std::string& what) {
  if (!condition) fail(what);
}

}  // namespace detail
}  // namespace vmap
