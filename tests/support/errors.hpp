#pragma once

// The message of the vmap::Error an action throws, for checks of what an error says.

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

}  // namespace vmap::test
