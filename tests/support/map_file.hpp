#pragma once

// Key-image map files (keyframe/map_io.hpp) as a hostile writer makes them.

#include <vmap/keyframe/map_io.hpp>

#include <cstddef>
#include <cstdint>
#include <string>
#include <string_view>

namespace vmap::test {

/// Rewrites the header's size and CRC so that a mutated payload passes the checksum:
/// what a hostile (not merely damaged) file looks like.
inline std::string with_valid_checksum(std::string bytes) {
  if (bytes.size() < detail::map_header_size) return bytes;
  const std::string_view payload(bytes.data() + detail::map_header_size, bytes.size() - detail::map_header_size);
  const std::uint64_t size = payload.size();
  const std::uint32_t crc = detail::crc32(payload);
  for (int i = 0; i < 8; ++i) bytes[12 + static_cast<std::size_t>(i)] = static_cast<char>((size >> (8 * i)) & 0xFF);
  for (int i = 0; i < 4; ++i) bytes[20 + static_cast<std::size_t>(i)] = static_cast<char>((crc >> (8 * i)) & 0xFF);
  return bytes;
}

}  // namespace vmap::test
