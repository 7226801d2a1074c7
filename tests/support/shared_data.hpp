#pragma once

// Access to ../shared (real image sequences and models) for the tests in the doctest
// test suite "data". CTest runs that suite only when CMake found the folder (otherwise
// it reports the suite as skipped, or fails configuration under
// VMAP_REQUIRE_SHARED_DATA), so a test here may REQUIRE the files to exist. And the
// files every test may touch: the repository's sample frames, scratch folders under the
// build tree, whole files read and written as bytes.

#include <doctest/doctest.h>

#include <filesystem>
#include <fstream>
#include <iterator>
#include <string>
#include <string_view>

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

/// The repository's 60 sample frames, as a TUM list (examples/data/tum_fr1_rpy_60/rgb.txt).
inline std::filesystem::path sample_list() { return source_dir() / "examples/data/tum_fr1_rpy_60/rgb.txt"; }

/// `name` in the scratch folder `area` under the build tree, with nothing there: no file
/// or folder, and no SQLite journal of it (`-wal`, `-shm`), so a store opened there
/// starts empty.
inline std::filesystem::path fresh_path(const std::string& area, const std::string& name) {
  const auto dir = std::filesystem::path(VMAP_TEST_BINARY_DIR) / "scratch" / area;
  std::filesystem::create_directories(dir);
  const auto p = dir / name;
  for (const char* suffix : {"", "-wal", "-shm"}) std::filesystem::remove_all(p.string() + suffix);
  return p;
}

inline std::string read_bytes(const std::filesystem::path& p) {
  std::ifstream in(p, std::ios::binary);
  return {std::istreambuf_iterator<char>(in), std::istreambuf_iterator<char>()};
}

inline void write_bytes(const std::filesystem::path& p, std::string_view bytes) {
  std::ofstream(p, std::ios::binary | std::ios::trunc).write(bytes.data(), static_cast<std::streamsize>(bytes.size()));
}

}  // namespace vmap::test
