#pragma once

// Where each section of a memory file starts (include/vmap/memory/visual_memory.hpp's
// layout: a 16-byte header, then sections { u8[4] tag, u64 length, u32 CRC, bytes }),
// for tests that damage one section at a time.

#include <cstddef>
#include <cstdint>
#include <string>
#include <vector>

namespace vmap::test {

inline std::vector<std::size_t> section_starts(const std::string& file) {
  std::vector<std::size_t> out;
  std::size_t at = 16;
  while (at + 16 <= file.size()) {
    out.push_back(at);
    std::uint64_t len = 0;
    for (int i = 0; i < 8; ++i) len |= static_cast<std::uint64_t>(static_cast<unsigned char>(file[at + 4 + i])) << (8 * i);
    at += 16 + len;
  }
  return out;
}

}  // namespace vmap::test
