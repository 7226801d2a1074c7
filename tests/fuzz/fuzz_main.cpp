// One libFuzzer entry point, compiled once per loader of loaders.cpp with
// VMAP_FUZZ_FUNCTION set to that loader's function (see CMakeLists.txt).
#include <vmap/core/error.hpp>

#include <cstddef>
#include <cstdint>
#include <string_view>

void VMAP_FUZZ_FUNCTION(std::string_view bytes);  // defined in loaders.cpp

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
  try {
    VMAP_FUZZ_FUNCTION(std::string_view(reinterpret_cast<const char*>(data), size));
  } catch (const vmap::Error&) {
    // Bad input reported as it should be.
  }
  return 0;
}
