#pragma once

#include <stdexcept>
#include <string>
#include <type_traits>

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
/// silent wrong answer. The message is built only on failure (as manif's CHECK does):
/// pass a literal, or, for a composed message, a callable that returns it
/// (`check(n > 0, [&] { return "n must be > 0, got " + std::to_string(n); })`), so a
/// check that holds costs no allocation on a per-frame path.
inline void check(bool condition, const char* what) {
  if (!condition) [[unlikely]]
    fail(what);
}

/// A message that already exists as a string (nothing is built here).
inline void check(bool condition, const std::string& what) {
  if (!condition) [[unlikely]]
    fail(what);
}

/// The lazy form: `make_message()` runs only when `condition` is false.
template <class MakeMessage>
requires std::is_invocable_r_v<std::string, MakeMessage&>
inline void check(bool condition, MakeMessage&& make_message) {
  if (!condition) [[unlikely]]
    fail(std::string(make_message()));
}

}  // namespace detail
}  // namespace vmap
