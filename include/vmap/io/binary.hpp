#pragma once

// The binary encoding shared by vmap's file formats (keyframe/map_io.hpp,
// som/gcs.hpp): fixed-width little-endian integers whatever the host's byte order,
// so a file written on one machine reads on any other; f32/f64 are IEEE-754 bit
// patterns stored as little-endian u32/u64; a string is a u32 length and its bytes.
//
// BinaryReader checks every read against the bytes that are really there, and
// require_items() checks a count against them before anything is allocated, so a
// truncated, corrupt or hostile file is a vmap::Error naming the file, the byte offset
// and the field being read, never a crash or a huge allocation.

#include <vmap/core/error.hpp>

#include <array>
#include <bit>
#include <cstddef>
#include <cstdint>
#include <cstring>
#include <limits>
#include <string>
#include <string_view>
#include <utility>

namespace vmap::detail {

static_assert(sizeof(float) == 4 && sizeof(double) == 8 && std::numeric_limits<float>::is_iec559 &&
                  std::numeric_limits<double>::is_iec559,
              "vmap's binary files store IEEE-754 binary32 / binary64 values");

/// Converts to any type, in unevaluated contexts only: field_count's probe.
struct AnyField {
  template <class T>
  operator T() const;  // NOLINT(google-explicit-constructor): the probe must convert implicitly
};

/// The number of fields of the aggregate T: how many initialisers T{...} accepts. An
/// options codec asserts it, so that a field added to the options fails to compile
/// until the codec writes and reads it (a saved memory cannot silently drop an option).
template <class T, class... Fields>
consteval std::size_t field_count() {
  if constexpr (requires { T{Fields{}..., AnyField{}}; })
    return field_count<T, Fields..., AnyField>();
  else
    return sizeof...(Fields);
}

inline constexpr std::array<std::uint32_t, 256> crc32_table = [] {
  std::array<std::uint32_t, 256> t{};
  for (std::uint32_t i = 0; i < 256; ++i) {
    std::uint32_t c = i;
    for (int k = 0; k < 8; ++k) c = (c & 1U) ? 0xEDB88320U ^ (c >> 1) : c >> 1;
    t[i] = c;
  }
  return t;
}();

/// CRC-32 (IEEE 802.3, reflected polynomial 0xEDB88320) as in zlib and PNG; given the
/// CRC-32 of bytes before (`before`), that of those bytes followed by `bytes` (zlib's
/// crc32(crc, buf, len)), so that two blobs are checked as one without joining them.
inline std::uint32_t crc32(std::string_view bytes, std::uint32_t before = 0) noexcept {
  std::uint32_t c = before ^ 0xFFFFFFFFU;
  for (char ch : bytes) c = crc32_table[(c ^ static_cast<unsigned char>(ch)) & 0xFFU] ^ (c >> 8);
  return c ^ 0xFFFFFFFFU;
}

/// Appends values in the encoding above to a byte string.
class BinaryWriter {
 public:
  void u8(std::uint8_t v) { out_.push_back(static_cast<char>(v)); }
  void u32(std::uint32_t v) { little_endian(v, 4); }
  void u64(std::uint64_t v) { little_endian(v, 8); }
  /// Two's complement, as the u32 of the same bits.
  void i32(std::int32_t v) { u32(static_cast<std::uint32_t>(v)); }
  void i64(std::int64_t v) { u64(static_cast<std::uint64_t>(v)); }
  void f32(float v) { u32(std::bit_cast<std::uint32_t>(v)); }
  void f64(double v) { u64(std::bit_cast<std::uint64_t>(v)); }
  /// n f32 values (e.g. a float matrix's row): one copy on a little-endian host.
  void f32s(const float* v, std::size_t n) {
    if constexpr (std::endian::native == std::endian::little) {
      bytes(v, n * sizeof(float));
    } else {
      for (std::size_t i = 0; i < n; ++i) f32(v[i]);
    }
  }
  void bytes(const void* data, std::size_t n) { out_.append(static_cast<const char*>(data), n); }
  void bytes(std::string_view s) { out_.append(s); }
  /// u32 length + bytes. A string longer than `max_length` is refused here, so nothing
  /// is written that the reader (with the same limit) would reject; `what` names it in
  /// the message ("save_map: a key image name").
  void str(std::string_view s, std::uint32_t max_length, std::string_view what) {
    if (s.size() > max_length)
      fail(std::string(what) + " is longer than " + std::to_string(max_length) + " bytes");
    u32(static_cast<std::uint32_t>(s.size()));
    bytes(s);
  }

  [[nodiscard]] std::size_t size() const noexcept { return out_.size(); }
  [[nodiscard]] const std::string& data() const& noexcept { return out_; }
  [[nodiscard]] std::string take() && noexcept { return std::move(out_); }

 private:
  void little_endian(std::uint64_t v, int n) {
    for (int i = 0; i < n; ++i) out_.push_back(static_cast<char>((v >> (8 * i)) & 0xFFU));
  }

  std::string out_;
};

/// Reads values in the encoding above from bytes it does not own. `source` names the
/// input in every message ("map file 'x.vmap'"); `base_offset` is the file offset of
/// bytes[0], so a reader over part of a file reports offsets in the whole file.
class BinaryReader {
 public:
  BinaryReader(std::string_view bytes, std::string source, std::size_t base_offset = 0)
      : bytes_(bytes), source_(std::move(source)), base_(base_offset) {}

  std::uint8_t u8(std::string_view field) {
    need(1, field);
    return static_cast<std::uint8_t>(bytes_[pos_++]);
  }
  std::uint32_t u32(std::string_view field) { return static_cast<std::uint32_t>(little_endian(4, field)); }
  std::uint64_t u64(std::string_view field) { return little_endian(8, field); }
  std::int32_t i32(std::string_view field) { return static_cast<std::int32_t>(u32(field)); }
  std::int64_t i64(std::string_view field) { return static_cast<std::int64_t>(u64(field)); }
  float f32(std::string_view field) { return std::bit_cast<float>(u32(field)); }
  double f64(std::string_view field) { return std::bit_cast<double>(u64(field)); }

  /// n f32 values into out[0, n); checked before anything is written to out.
  void f32s(float* out, std::uint64_t n, std::string_view field) {
    require_items(n, sizeof(float), field);
    if constexpr (std::endian::native == std::endian::little) {
      std::memcpy(out, bytes_.data() + pos_, static_cast<std::size_t>(n) * sizeof(float));
      pos_ += static_cast<std::size_t>(n) * sizeof(float);
    } else {
      for (std::uint64_t i = 0; i < n; ++i) out[i] = f32(field);
    }
  }

  /// The next n bytes (a view into the input).
  std::string_view bytes(std::uint64_t n, std::string_view field) {
    need(n, field);
    const auto v = bytes_.substr(pos_, static_cast<std::size_t>(n));
    pos_ += static_cast<std::size_t>(n);
    return v;
  }

  /// u32 length + bytes; a length above `max_length` is an Error before anything is read.
  std::string str(std::string_view field, std::uint32_t max_length) {
    const std::size_t at = pos_;
    const std::uint32_t n = u32(field);
    if (n > max_length)
      fail_at(at, std::string(field) + " is " + std::to_string(n) + " bytes long (limit " +
                      std::to_string(max_length) + ")");
    return std::string(bytes(n, field));
  }

  /// Fails unless `count` items of at least `item_bytes` (>= 1) each still fit in what
  /// remains: call it with a count read from the file before allocating `count` items.
  void require_items(std::uint64_t count, std::uint64_t item_bytes, std::string_view field) const {
    check(item_bytes > 0, "BinaryReader::require_items: item_bytes must be >= 1");
    if (count > remaining() / item_bytes)
      corrupt("truncated or corrupt: " + std::string(field) + " claims " + std::to_string(count) + " items of " +
              std::to_string(item_bytes) + " bytes, " + std::to_string(remaining()) + " bytes left");
  }

  /// Fails if any byte is left; `after` names what should have been last.
  void expect_end(std::string_view after) const {
    if (remaining() != 0)
      corrupt("corrupt: " + std::to_string(remaining()) + " unexpected bytes after " + std::string(after));
  }

  /// Throws vmap::Error "<source>: <what> (at byte <offset>)" at the current position.
  [[noreturn]] void corrupt(const std::string& what) const { fail_at(pos_, what); }
  /// The same message with another kind: a format version newer than the reader's is
  /// `ErrorKind::unsupported_version`, not damage.
  [[noreturn]] void fail_here(ErrorKind kind, const std::string& what) const { fail_at(pos_, what, kind); }

  [[nodiscard]] std::size_t remaining() const noexcept { return bytes_.size() - pos_; }
  [[nodiscard]] bool at_end() const noexcept { return pos_ == bytes_.size(); }
  /// Offset of the next byte in the file.
  [[nodiscard]] std::size_t offset() const noexcept { return base_ + pos_; }
  /// The bytes not read yet.
  [[nodiscard]] std::string_view rest() const noexcept { return bytes_.substr(pos_); }
  [[nodiscard]] const std::string& source() const noexcept { return source_; }

 private:
  [[noreturn]] void fail_at(std::size_t pos, const std::string& what, ErrorKind kind = ErrorKind::corrupt) const {
    fail(kind, source_ + ": " + what + " (at byte " + std::to_string(base_ + pos) + ")");
  }

  void need(std::uint64_t n, std::string_view field) const {
    if (n > remaining())
      corrupt("truncated or corrupt: " + std::string(field) + " needs " + std::to_string(n) + " bytes, " +
              std::to_string(remaining()) + " left");
  }

  std::uint64_t little_endian(int n, std::string_view field) {
    need(static_cast<std::uint64_t>(n), field);
    std::uint64_t v = 0;
    for (int i = 0; i < n; ++i)
      v |= static_cast<std::uint64_t>(static_cast<unsigned char>(bytes_[pos_ + static_cast<std::size_t>(i)])) << (8 * i);
    pos_ += static_cast<std::size_t>(n);
    return v;
  }

  std::string_view bytes_;
  std::string source_;
  std::size_t base_ = 0;
  std::size_t pos_ = 0;
};

}  // namespace vmap::detail
