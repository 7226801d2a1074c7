#pragma once

// Protocol-buffer wire encoding, enough to write tiny ONNX models by hand in tests.

#include <cstdint>
#include <string>

namespace vmap::test {

inline std::string varint(std::uint64_t v) {
  std::string s;
  do {
    auto byte = static_cast<char>(v & 0x7Fu);
    v >>= 7;
    if (v) byte = static_cast<char>(byte | 0x80);
    s += byte;
  } while (v);
  return s;
}
inline std::string field_varint(std::uint32_t f, std::uint64_t v) { return varint(f << 3) + varint(v); }
inline std::string field_bytes(std::uint32_t f, const std::string& b) {
  return varint((f << 3) | 2u) + varint(b.size()) + b;
}

}  // namespace vmap::test
