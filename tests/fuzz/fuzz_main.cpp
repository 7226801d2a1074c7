// One libFuzzer entry point, compiled once per loader of loaders.hpp with
// VMAP_FUZZ_FUNCTION set to that loader's function (see CMakeLists.txt).
#include "loaders.hpp"

#include <vmap/core/error.hpp>

#include <cstddef>
#include <cstdint>
#include <string_view>

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
  try {
    VMAP_FUZZ_FUNCTION(std::string_view(reinterpret_cast<const char*>(data), size));
  } catch (const vmap::Error&) {
    // Bad input reported as it should be.
  }
  return 0;
}
