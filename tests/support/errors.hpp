#pragma once

// The message (and kind) of the vmap::Error an action throws, for checks of what an error
// says.

#include <vmap/core/error.hpp>

#include <string>

namespace vmap::test {

inline std::string error_of(auto&& action) {
  try {
    action();
  } catch (const vmap::Error& e) {
    return e.what();
  }
  return "no error";
}

/// The kind and message of the vmap::Error an action throws (kind invalid_argument and
/// message "no error" when it throws none).
struct ErrorSeen {
  ErrorKind kind = ErrorKind::invalid_argument;
  std::string message = "no error";
};

inline ErrorSeen error_seen(auto&& action) {
  try {
    action();
  } catch (const vmap::Error& e) {
    return {e.kind(), e.what()};
  }
  return {};
}

}  // namespace vmap::test
