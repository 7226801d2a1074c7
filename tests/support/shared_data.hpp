#pragma once

// Access to ../shared (real image sequences and models) for the tests in the doctest
// test suite "data". CTest runs that suite only when CMake found the folder (otherwise
// it reports the suite as skipped, or fails configuration under
// VMAP_REQUIRE_SHARED_DATA), so a test here may REQUIRE the files to exist.

#include <doctest/doctest.h>

#include <filesystem>
#include <string>

namespace vmap::test {

inline std::filesystem::path shared_dir() {
  const std::string dir = VMAP_SHARED_DIR;
  REQUIRE_MESSAGE(!dir.empty(), "VMAP_SHARED_DIR is not set: run the \"data\" suite through CTest");
  return std::filesystem::path(dir);
}

/// Path under ../shared/data; REQUIREs that it exists.
inline std::filesystem::path data_path(const std::string& relative) {
  auto p = shared_dir() / "data" / relative;
  REQUIRE_MESSAGE(std::filesystem::exists(p), "missing shared data file: " << p.string());
  return p;
}

/// Path under ../shared/models; REQUIREs that it exists.
inline std::filesystem::path model_path(const std::string& relative) {
  auto p = shared_dir() / "models" / relative;
  REQUIRE_MESSAGE(std::filesystem::exists(p), "missing shared model file: " << p.string());
  return p;
}

/// The repository's own folder (sample frames under examples/data).
inline std::filesystem::path source_dir() { return std::filesystem::path(VMAP_TEST_SOURCE_DIR); }

/// A fresh scratch folder under the build tree, removed and recreated on each call.
inline std::filesystem::path scratch_dir(const std::string& name) {
  auto p = std::filesystem::path(VMAP_TEST_BINARY_DIR) / "scratch" / name;
  std::filesystem::remove_all(p);
  std::filesystem::create_directories(p);
  return p;
}

}  // namespace vmap::test
