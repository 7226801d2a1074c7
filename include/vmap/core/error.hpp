#pragma once

#include <vmap/core/name_table.hpp>

#include <cstdint>
#include <stdexcept>
#include <string>
#include <string_view>
#include <type_traits>
#include <utility>

namespace vmap {

/// What kind of failure an Error is, so that a program can act on it without reading
/// its message (as std::errc does for std::system_error): a robot at boot starts a new
/// memory on `not_found`, keeps the damaged file aside on `corrupt`, and asks for a
/// fix of its configuration on `invalid_argument` or `policy_mismatch`.
enum class ErrorKind : std::uint8_t {
  invalid_argument,     ///< a bad option, value or call: the caller must change it
  not_found,            ///< a file or folder that does not exist
  corrupt,              ///< a file that exists but is damaged or is not of its format
  unsupported_version,  ///< a file of a newer format version than this build reads
  policy_mismatch,      ///< a memory or vocabulary made with other policies (descriptor, stack)
  busy,                 ///< a resource held by another program (a store's writer lock)
  io,                   ///< a write, flush or rename that the system refused (disk full, permissions)
  unavailable,          ///< a database server that cannot be reached or went away: try again later
};

/// The names of the kinds, as written above (core/names.hpp).
[[nodiscard]] constexpr auto names_of(ErrorKind) noexcept {
  return detail::NameTable<ErrorKind, 8>{{{{ErrorKind::invalid_argument, "invalid_argument"},
                                           {ErrorKind::not_found, "not_found"},
                                           {ErrorKind::corrupt, "corrupt"},
                                           {ErrorKind::unsupported_version, "unsupported_version"},
                                           {ErrorKind::policy_mismatch, "policy_mismatch"},
                                           {ErrorKind::busy, "busy"},
                                           {ErrorKind::io, "io"},
                                           {ErrorKind::unavailable, "unavailable"}}}};
}
[[nodiscard]] constexpr std::string_view to_string(ErrorKind k) noexcept { return names_of(k).name(k); }

/// Thrown for invalid arguments and unreadable inputs. The message names the input
/// (a file, an option, an image) and what was wrong with it; `kind()` says which kind
/// of failure it is. Expected outcomes (no features, degenerate geometry, no loop) are
/// values, never an Error.
class Error : public std::runtime_error {
 public:
  /// An invalid argument: the meaning every `Error(message)` had before kinds existed.
  explicit Error(const std::string& what) : std::runtime_error(what) {}
  explicit Error(const char* what) : std::runtime_error(what) {}
  Error(ErrorKind kind, const std::string& what) : std::runtime_error(what), kind_(kind) {}

  [[nodiscard]] ErrorKind kind() const noexcept { return kind_; }

 private:
  ErrorKind kind_ = ErrorKind::invalid_argument;
};

namespace detail {

[[noreturn]] inline void fail(const std::string& what) { throw Error(what); }
[[noreturn]] inline void fail(ErrorKind kind, const std::string& what) { throw Error(kind, what); }

/// Always-on precondition check (release builds too): invalid input must never be a
/// silent wrong answer. The message is built only on failure (as manif's CHECK does):
/// pass a literal, or, for a composed message, a callable that returns it
/// (`check(n > 0, [&] { return "n must be > 0, got " + std::to_string(n); })`), so a
/// check that holds costs no allocation on a per-frame path. The forms without a kind
/// raise `ErrorKind::invalid_argument`.
inline void check(bool condition, ErrorKind kind, const char* what) {
  if (!condition) [[unlikely]]
    fail(kind, what);
}

/// A message that already exists as a string (nothing is built here).
inline void check(bool condition, ErrorKind kind, const std::string& what) {
  if (!condition) [[unlikely]]
    fail(kind, what);
}

/// The lazy form: `make_message()` runs only when `condition` is false.
template <class MakeMessage>
requires std::is_invocable_r_v<std::string, MakeMessage&>
inline void check(bool condition, ErrorKind kind, MakeMessage&& make_message) {
  if (!condition) [[unlikely]]
    fail(kind, std::string(make_message()));
}

inline void check(bool condition, const char* what) { check(condition, ErrorKind::invalid_argument, what); }
inline void check(bool condition, const std::string& what) {
  check(condition, ErrorKind::invalid_argument, what);
}
template <class MakeMessage>
requires std::is_invocable_r_v<std::string, MakeMessage&>
inline void check(bool condition, MakeMessage&& make_message) {
  check(condition, ErrorKind::invalid_argument, std::forward<MakeMessage>(make_message));
}

}  // namespace detail
}  // namespace vmap
