#pragma once

// The envelope shared by the place files (vocabulary.hpp, database.hpp), as
// keyframe/map_io.hpp's: a 24-byte header (u8[8] magic, u32 version, u64 payload size,
// u32 CRC-32 of the payload) then the payload, in io/binary.hpp's encoding.

#include <vmap/core/error.hpp>
#include <vmap/io/binary.hpp>

#include <array>
#include <cstdint>
#include <filesystem>
#include <fstream>
#include <string>
#include <string_view>
#include <utility>

namespace vmap::detail {

inline constexpr std::size_t place_header_size = 24;

/// Slicing-by-8 tables of the CRC-32 of io/binary.hpp (table k advances a byte that is
/// followed by k more).
inline constexpr std::array<std::array<std::uint32_t, 256>, 8> crc32_slices = [] {
  std::array<std::array<std::uint32_t, 256>, 8> t{};
  t[0] = crc32_table;
  for (std::size_t i = 0; i < 256; ++i)
    for (std::size_t k = 1; k < 8; ++k) t[k][i] = (t[k - 1][i] >> 8) ^ t[0][t[k - 1][i] & 0xFFU];
  return t;
}();

/// The same CRC-32 as io/binary.hpp's crc32(), eight bytes a step (Intel's
/// slicing-by-8): several times faster, which matters for the tens of megabytes of a
/// large vocabulary.
inline std::uint32_t crc32_fast(std::string_view bytes) noexcept {
  const auto* p = reinterpret_cast<const unsigned char*>(bytes.data());
  std::size_t n = bytes.size();
  std::uint32_t c = 0xFFFFFFFFU;
  const auto& t = crc32_slices;
  while (n >= 8) {
    const std::uint32_t lo = c ^ (static_cast<std::uint32_t>(p[0]) | static_cast<std::uint32_t>(p[1]) << 8 |
                                  static_cast<std::uint32_t>(p[2]) << 16 | static_cast<std::uint32_t>(p[3]) << 24);
    const std::uint32_t hi = static_cast<std::uint32_t>(p[4]) | static_cast<std::uint32_t>(p[5]) << 8 |
                             static_cast<std::uint32_t>(p[6]) << 16 | static_cast<std::uint32_t>(p[7]) << 24;
    c = t[7][lo & 0xFFU] ^ t[6][(lo >> 8) & 0xFFU] ^ t[5][(lo >> 16) & 0xFFU] ^ t[4][lo >> 24] ^ t[3][hi & 0xFFU] ^
        t[2][(hi >> 8) & 0xFFU] ^ t[1][(hi >> 16) & 0xFFU] ^ t[0][hi >> 24];
    p += 8;
    n -= 8;
  }
  while (n-- > 0) c = t[0][(c ^ *p++) & 0xFFU] ^ (c >> 8);
  return c ^ 0xFFFFFFFFU;
}

/// Header + payload.
inline std::string wrap_payload(std::string_view magic, std::uint32_t version, const std::string& payload) {
  BinaryWriter h;
  h.bytes(magic);
  h.u32(version);
  h.u64(payload.size());
  h.u32(crc32_fast(payload));
  h.bytes(payload);
  return std::move(h).take();
}

/// Checks the header of `file` (magic, version, size, CRC) and returns a reader over the
/// payload; `what` names the kind of file ("vocabulary"), `r` names the file.
inline BinaryReader open_payload(std::string_view file, std::string_view magic, std::uint32_t version,
                                 const std::string& what, const std::string& source) {
  BinaryReader r(file, source);
  if (file.size() < place_header_size)
    r.corrupt("too short (" + std::to_string(file.size()) + " bytes) to be a vmap " + what);
  if (r.bytes(8, "magic") != magic) r.corrupt("not a vmap " + what + " (wrong magic bytes)");
  const std::uint32_t v = r.u32("version");
  if (v != version)
    r.corrupt("format version " + std::to_string(v) + " is not supported (this build reads " + std::to_string(version) +
              ")");
  const std::uint64_t size = r.u64("payload size");
  const std::uint32_t crc = r.u32("checksum");
  if (size != r.remaining())
    r.corrupt("truncated or padded (header says " + std::to_string(size) + " payload bytes, file has " +
              std::to_string(r.remaining()) + ")");
  if (crc32_fast(r.rest()) != crc) r.corrupt("checksum mismatch (the file is corrupt)");
  return BinaryReader(r.rest(), source, place_header_size);
}

/// Reads a whole file in one read (large vocabularies: no per-character stream
/// iteration); a missing or unreadable file is an Error naming it.
inline std::string read_whole_file(const std::filesystem::path& path) {
  std::ifstream in(path, std::ios::binary | std::ios::ate);
  if (!in) fail("cannot open '" + path.string() + "'");
  const std::streamoff size = in.tellg();
  if (size < 0) fail("cannot read the size of '" + path.string() + "'");
  std::string data(static_cast<std::size_t>(size), '\0');
  in.seekg(0);
  if (!in.read(data.data(), static_cast<std::streamsize>(size))) fail("reading '" + path.string() + "' failed");
  return data;
}

}  // namespace vmap::detail
