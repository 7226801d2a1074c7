#pragma once

// The envelope shared by the place files (vocabulary.hpp, database.hpp), as
// keyframe/map_io.hpp's: a 24-byte header (u8[8] magic, u32 version, u64 payload size,
// u32 CRC-32 of the payload) then the payload, in io/binary.hpp's encoding.

#include <vmap/core/error.hpp>
#include <vmap/io/binary.hpp>
#include <vmap/io/files.hpp>
#include <vmap/place/detail/crc32c.hpp>

#include <algorithm>
#include <array>
#include <bit>
#include <cstring>
#include <cstdint>
#include <filesystem>
#include <fstream>
#include <limits>
#include <string>
#include <string_view>
#include <utility>

namespace vmap::detail {

inline constexpr std::size_t place_header_size = 24;

/// Raw update (no inversions) of the CRC-32 of io/binary.hpp (reflected polynomial
/// 0xEDB88320), eight bytes a step: several times faster than byte by byte, which
/// matters for the tens of megabytes of a large vocabulary of file format 1.
inline std::uint32_t crc32_update(std::uint32_t c, const void* data, std::size_t n) noexcept {
  return crc_update_sliced<0xEDB88320U>(c, static_cast<const unsigned char*>(data), n);
}

/// The same CRC-32 as io/binary.hpp's crc32(), with crc32_update.
inline std::uint32_t crc32_fast(std::string_view bytes) noexcept {
  return crc32_update(0xFFFFFFFFU, bytes.data(), bytes.size()) ^ 0xFFFFFFFFU;
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
    r.fail_here(v > version ? ErrorKind::unsupported_version : ErrorKind::corrupt,
                "format version " + std::to_string(v) + " is not supported (this build reads " +
                    std::to_string(version) + ")");
  const std::uint64_t size = r.u64("payload size");
  const std::uint32_t crc = r.u32("checksum");
  if (size != r.remaining())
    r.corrupt("truncated or padded (header says " + std::to_string(size) + " payload bytes, file has " +
              std::to_string(r.remaining()) + ")");
  if (crc32_fast(r.rest()) != crc) r.corrupt("checksum mismatch (the file is corrupt)");
  return BinaryReader(r.rest(), source, place_header_size);
}

/// Reads a whole file in one read (large vocabularies: no per-character stream
/// iteration), through vmap::read_file: a missing file, a folder, a FIFO or a device, or
/// one larger than `max_bytes`, is an Error naming `what` and the path.
inline std::string read_whole_file(const std::filesystem::path& path, const std::string& what = "file",
                                   std::uintmax_t max_bytes = std::numeric_limits<std::uintmax_t>::max()) {
  return read_file(path, max_bytes, what);
}

/// Float values read as raw little-endian bytes, put in host order (nothing to do on a
/// little-endian host).
inline void f32_from_little_endian(float* p, std::size_t n) noexcept {
  if constexpr (std::endian::native != std::endian::little)
    for (std::size_t i = 0; i < n; ++i) {
      std::uint32_t u = std::bit_cast<std::uint32_t>(p[i]);
      u = (u >> 24) | ((u >> 8) & 0xFF00U) | ((u << 8) & 0xFF0000U) | (u << 24);
      p[i] = std::bit_cast<float>(u);
    }
  (void)p;
  (void)n;
}

/// An input stream on a regular file: a missing file, a folder, a FIFO or a device is an
/// Error naming `what` and the path (require_regular_file: reading one could block or
/// never end), checked before the file is opened.
inline std::ifstream open_regular_file(const std::filesystem::path& path, const std::string& what = "file") {
  (void)require_regular_file(path, what);
  std::ifstream in(path, std::ios::binary);
  if (!in) fail(ErrorKind::io, "cannot open " + what + " '" + path.string() + "'");
  return in;
}

/// Which checksum a file's header holds.
enum class PayloadChecksum { crc32, crc32c };

/// Reads a payload front to back into the caller's buffers, from memory or straight from
/// a file, checksumming each piece right after it lands (while it is still in cache), so
/// a large file is read and checked in one pass with no intermediate copy. Every read is
/// checked against the bytes that remain; require_items() checks a count before the
/// caller allocates for it. finish() checks that nothing is left and the checksum.
class PayloadStream {
 public:
  /// A payload in memory; `base` is its offset in the file (for messages).
  PayloadStream(std::string_view payload, std::string source, std::size_t base, PayloadChecksum sum)
      : mem_(payload.data()), size_(payload.size()), source_(std::move(source)), base_(base), sum_(sum) {}
  /// `size` payload bytes from the current position of `in`.
  PayloadStream(std::istream& in, std::uint64_t size, std::string source, std::size_t base, PayloadChecksum sum)
      : in_(&in), size_(size), source_(std::move(source)), base_(base), sum_(sum) {}

  /// n bytes into dst (checked first).
  void read(void* dst, std::uint64_t n, std::string_view field) {
    if (n > remaining())
      corrupt("truncated or corrupt: " + std::string(field) + " needs " + std::to_string(n) + " bytes, " +
              std::to_string(remaining()) + " left");
    auto* out = static_cast<char*>(dst);
    constexpr std::uint64_t chunk = 256 * 1024;  // fits in L2: checksummed while there
    while (n > 0) {
      const auto m = static_cast<std::size_t>(std::min(n, chunk));
      if (in_ != nullptr) {
        if (!in_->read(out, static_cast<std::streamsize>(m))) corrupt("reading failed (the file changed or is unreadable)");
      } else {
        std::memcpy(out, mem_ + pos_, m);
      }
      crc_ = sum_ == PayloadChecksum::crc32c ? crc32c_update(crc_, out, m) : crc32_update(crc_, out, m);
      pos_ += m;
      out += m;
      n -= m;
    }
  }
  std::uint8_t u8(std::string_view field) { return static_cast<std::uint8_t>(le(1, field)); }
  std::uint32_t u32(std::string_view field) { return static_cast<std::uint32_t>(le(4, field)); }
  std::uint64_t u64(std::string_view field) { return le(8, field); }
  std::int32_t i32(std::string_view field) { return static_cast<std::int32_t>(u32(field)); }

  /// Fails unless `count` items of `item_bytes` (>= 1) each fit in what remains.
  void require_items(std::uint64_t count, std::uint64_t item_bytes, std::string_view field) const {
    if (count > remaining() / item_bytes)
      corrupt("truncated or corrupt: " + std::string(field) + " claims " + std::to_string(count) + " items of " +
              std::to_string(item_bytes) + " bytes, " + std::to_string(remaining()) + " bytes left");
  }
  /// Fails if bytes are left (`after` names the last field) or the checksum differs.
  void finish(std::uint32_t expected_checksum, std::string_view after) const {
    if (remaining() != 0)
      corrupt("corrupt: " + std::to_string(remaining()) + " unexpected bytes after " + std::string(after));
    if ((crc_ ^ 0xFFFFFFFFU) != expected_checksum) corrupt("checksum mismatch (the file is corrupt)");
  }
  [[nodiscard]] std::uint64_t remaining() const noexcept { return size_ - pos_; }
  /// Throws vmap::Error "<source>: <what> (at byte <offset>)".
  [[noreturn]] void corrupt(const std::string& what) const {
    fail(source_ + ": " + what + " (at byte " + std::to_string(base_ + pos_) + ")");
  }

 private:
  std::uint64_t le(int n, std::string_view field) {
    unsigned char b[8] = {};
    read(b, static_cast<std::uint64_t>(n), field);
    std::uint64_t v = 0;
    for (int i = 0; i < n; ++i) v |= static_cast<std::uint64_t>(b[i]) << (8 * i);
    return v;
  }

  const char* mem_ = nullptr;
  std::istream* in_ = nullptr;
  std::uint64_t size_ = 0;
  std::uint64_t pos_ = 0;
  std::string source_;
  std::size_t base_ = 0;
  PayloadChecksum sum_;
  std::uint32_t crc_ = 0xFFFFFFFFU;
};

/// The 24-byte header of a place file: magic, version (one of `versions`), payload
/// size, checksum. `available` is the number of bytes after the header.
struct PayloadHeader {
  std::uint32_t version = 0;
  std::uint64_t size = 0;
  std::uint32_t checksum = 0;
};
inline PayloadHeader parse_header(std::string_view head, std::uint64_t available, std::string_view magic,
                                  std::uint32_t oldest, std::uint32_t newest, const std::string& what,
                                  const std::string& source) {
  BinaryReader r(head, source);
  if (head.size() < place_header_size)
    r.corrupt("too short (" + std::to_string(head.size()) + " bytes) to be a vmap " + what);
  if (r.bytes(8, "magic") != magic) r.corrupt("not a vmap " + what + " (wrong magic bytes)");
  PayloadHeader h;
  h.version = r.u32("version");
  if (h.version < oldest || h.version > newest)
    r.fail_here(h.version > newest ? ErrorKind::unsupported_version : ErrorKind::corrupt,
                "format version " + std::to_string(h.version) + " is not supported (this build reads " +
                    std::to_string(oldest) + ".." + std::to_string(newest) + ")");
  h.size = r.u64("payload size");
  h.checksum = r.u32("checksum");
  if (h.size != available)
    r.corrupt("truncated or padded (header says " + std::to_string(h.size) + " payload bytes, file has " +
              std::to_string(available) + ")");
  return h;
}

}  // namespace vmap::detail
