#pragma once

// Readers of serialized ROS messages: CDR (ROS 2, both rosbag2 sqlite3 and MCAP's ROS 2
// profile) and the ROS 1 wire format. Both offer the same calls (u8, u32, i32, f64,
// string, byte sequence, float64 arrays and sequences), so that one decoder per message
// type (io/bag/messages.hpp) serves both. Every read is bounds-checked; a message that
// ends early is a vmap::Error naming the message and the byte.
//
// CDR (OMG DDS-XTypes 1.3, section 7.4.3 "XCDR"; the encapsulation header of the RTPS
// 2.3 specification, section 10): a 4-byte header (representation identifier: 00 00 CDR
// big-endian, 00 01 CDR little-endian, 00 06 / 00 07 XCDR2 plain big / little-endian;
// then 2 option bytes), then the fields, each primitive aligned to its size counted from
// the end of the header (XCDR2: at most 4). Strings: uint32 length counting the NUL,
// the bytes, the NUL. Sequences: uint32 count, the elements.
//
// ROS 1 (wiki.ros.org/msg, "Serialization"): little-endian, no alignment; strings and
// variable arrays as a uint32 count and the elements (no NUL); fixed arrays without count.

#include <vmap/core/error.hpp>

#include <cstddef>
#include <cstdint>
#include <cstring>
#include <string>
#include <string_view>
#include <vector>

namespace vmap::detail {

/// What the two wire formats share: the bytes, the position, the bounds check and the
/// calls built on u32 and f64 (sequences and arrays). `Wire` gives u32, f64 and string.
template <class Wire>
class MessageReader {
 public:
  std::uint8_t u8() {
    need(1);
    return static_cast<std::uint8_t>(b_[pos_++]);
  }
  std::int32_t i32() { return static_cast<std::int32_t>(self().u32()); }
  /// A sequence<uint8> (octets: no alignment after the count).
  std::string_view byte_sequence() {
    const std::uint32_t n = self().u32();
    need(n);
    std::string_view s = b_.substr(pos_, n);
    pos_ += n;
    return s;
  }
  void f64_array(double* out, std::size_t n) {
    for (std::size_t i = 0; i < n; ++i) out[i] = self().f64();
  }
  /// A sequence<float64> of at most `max` elements.
  std::vector<double> f64_sequence(std::size_t max) {
    const std::uint32_t n = self().u32();
    if (n > max) fail(what_ + ": a float64 sequence of " + std::to_string(n) + " elements, more than " + std::to_string(max));
    std::vector<double> v(n);
    f64_array(v.data(), n);
    return v;
  }
  [[nodiscard]] std::size_t position() const noexcept { return pos_; }

 protected:
  MessageReader(std::string_view bytes, std::string what) : b_(bytes), what_(std::move(what)) {}

  void need(std::size_t n) const {
    if (n > b_.size() - pos_) fail_short(n);
  }
  [[noreturn]] void fail_short(std::size_t n) const {
    fail(ErrorKind::corrupt, what_ + ": the message ends at byte " + std::to_string(b_.size()) + ", a field at byte " +
         std::to_string(pos_) + " needs " + std::to_string(n) + " more");
  }
  static double f64_of(std::uint64_t bits) {
    double d = 0;
    std::memcpy(&d, &bits, sizeof d);
    return d;
  }

  std::string_view b_;
  std::string what_;
  std::size_t pos_ = 0;

 private:
  Wire& self() { return static_cast<Wire&>(*this); }
};

/// Reads one CDR-encoded message.
class CdrReader : public MessageReader<CdrReader> {
 public:
  /// `what` names the message in errors ("topic '/cam' message at byte 120").
  CdrReader(std::string_view bytes, std::string what) : MessageReader(bytes, std::move(what)) {
    if (b_.size() < 4) fail_short(4);
    const auto id = static_cast<unsigned char>(b_[1]);
    if (b_[0] != 0 || (id != 0x00 && id != 0x01 && id != 0x06 && id != 0x07))
      fail(ErrorKind::corrupt, what_ + ": unknown CDR encapsulation " + hex(b_[0]) + " " + hex(b_[1]) +
           " (vmap reads plain CDR and XCDR2, little- or big-endian)");
    little_ = (id & 1) != 0;
    max_align_ = id >= 0x06 ? 4 : 8;
    origin_ = pos_ = 4;
  }

  std::uint32_t u32() { return static_cast<std::uint32_t>(integer(4)); }
  double f64() { return f64_of(integer(8)); }
  /// A string without its NUL.
  std::string_view string() {
    std::string_view s = byte_sequence();
    if (!s.empty() && s.back() == '\0') s.remove_suffix(1);
    return s;
  }

 private:
  std::uint64_t integer(std::size_t size) {
    const std::size_t a = size < max_align_ ? size : max_align_;
    const std::size_t rel = pos_ - origin_;
    const std::size_t pad = (a - rel % a) % a;
    need(pad + size);
    pos_ += pad;
    std::uint64_t v = 0;
    for (std::size_t i = 0; i < size; ++i) {
      const auto byte = static_cast<std::uint64_t>(static_cast<unsigned char>(b_[pos_ + i]));
      v |= little_ ? byte << (8 * i) : byte << (8 * (size - 1 - i));
    }
    pos_ += size;
    return v;
  }
  static std::string hex(char c) {
    static const char digits[] = "0123456789abcdef";
    const auto u = static_cast<unsigned char>(c);
    return {digits[u >> 4], digits[u & 15]};
  }

  std::size_t origin_ = 0;
  std::size_t max_align_ = 8;
  bool little_ = true;
};

/// Reads one ROS 1-serialized message (the same calls as CdrReader).
class Ros1Reader : public MessageReader<Ros1Reader> {
 public:
  Ros1Reader(std::string_view bytes, std::string what) : MessageReader(bytes, std::move(what)) {}

  std::uint32_t u32() { return static_cast<std::uint32_t>(little_endian(4)); }
  double f64() { return f64_of(little_endian(8)); }
  /// A string (no NUL on the wire).
  std::string_view string() { return byte_sequence(); }

 private:
  std::uint64_t little_endian(std::size_t size) {
    need(size);
    std::uint64_t v = 0;
    for (std::size_t i = size; i-- > 0;) v = (v << 8) | static_cast<unsigned char>(b_[pos_ + i]);
    pos_ += size;
    return v;
  }
};

}  // namespace vmap::detail
