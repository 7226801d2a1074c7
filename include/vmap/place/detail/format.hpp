#pragma once

// The envelope shared by the place files (vocabulary.hpp, database.hpp), as
// keyframe/map_io.hpp's: a 24-byte header (u8[8] magic, u32 version, u64 payload size,
// u32 CRC-32 of the payload) then the payload, in io/binary.hpp's encoding.

#include <vmap/core/error.hpp>
#include <vmap/io/binary.hpp>

#include <cstdint>
#include <filesystem>
#include <fstream>
#include <string>
#include <string_view>
#include <utility>

namespace vmap::detail {

inline constexpr std::size_t place_header_size = 24;

/// Header + payload.
inline std::string wrap_payload(std::string_view magic, std::uint32_t version, const std::string& payload) {
  BinaryWriter h;
  h.bytes(magic);
  h.u32(version);
  h.u64(payload.size());
  h.u32(crc32(payload));
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
  if (crc32(r.rest()) != crc) r.corrupt("checksum mismatch (the file is corrupt)");
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
