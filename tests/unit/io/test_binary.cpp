// io/binary.hpp: the little-endian encoding of vmap's files, checked byte by byte, and
// the reader's refusals (truncation at every byte, hostile counts, oversized strings,
// trailing bytes), each a vmap::Error that names the file, the offset and the field.
#include <vmap/io/binary.hpp>

#include <doctest/doctest.h>

#include <cmath>
#include <cstdint>
#include <limits>
#include <string>
#include <vector>

using vmap::detail::BinaryReader;
using vmap::detail::BinaryWriter;

namespace {

std::string hex(const std::string& s) {
  static constexpr char digits[] = "0123456789abcdef";
  std::string out;
  for (char c : s) {
    const auto b = static_cast<unsigned char>(c);
    out += digits[b >> 4];
    out += digits[b & 0xF];
  }
  return out;
}

std::string message(auto&& f) {
  try {
    f();
  } catch (const vmap::Error& e) {
    return e.what();
  }
  return "no error";
}

/// A small record holding one of every type; read_record reads it back field by field.
std::string small_record() {
  BinaryWriter w;
  w.u8(7);
  w.u32(0xDEADBEEFU);
  w.u64(0x0123456789ABCDEFULL);
  w.i32(-5);
  w.f32(1.5f);
  w.f64(-2.25);
  w.str("key", 16, "test");
  w.bytes("\x00\x01", 2);
  return std::move(w).take();
}

/// Reads small_record() back; true when every value matches. Reads are not wrapped in
/// doctest checks, so a truncation's vmap::Error reaches the caller.
bool read_record(std::string_view bytes) {
  BinaryReader r(bytes, "record 'r.bin'");
  bool same = r.u8("the u8") == 7;
  same &= r.u32("the u32") == 0xDEADBEEFU;
  same &= r.u64("the u64") == 0x0123456789ABCDEFULL;
  same &= r.i32("the i32") == -5;
  same &= r.f32("the f32") == 1.5f;
  same &= r.f64("the f64") == -2.25;
  same &= r.str("the name", 16) == "key";
  same &= r.bytes(2, "the tail") == std::string_view("\x00\x01", 2);
  r.expect_end("the tail");
  return same;
}

}  // namespace

TEST_CASE("binary: every type round-trips, extremes and special values included") {
  const float f32s[] = {0.0f, -0.0f, 1.0f, -3.25e-7f, std::numeric_limits<float>::max(),
                        std::numeric_limits<float>::denorm_min(), std::numeric_limits<float>::infinity()};
  const double f64s[] = {0.0, -0.0, 1e300, -1.0 / 3.0, std::numeric_limits<double>::denorm_min(),
                         -std::numeric_limits<double>::infinity()};
  const std::string with_nul("a\0b", 3);
  const std::string longest(100, 'x');

  BinaryWriter w;
  w.u8(0);
  w.u8(255);
  w.u32(0);
  w.u32(std::numeric_limits<std::uint32_t>::max());
  w.u64(std::numeric_limits<std::uint64_t>::max());
  w.u64(1ULL << 63);
  w.i32(std::numeric_limits<std::int32_t>::min());
  w.i32(std::numeric_limits<std::int32_t>::max());
  w.i32(-1);
  for (float v : f32s) w.f32(v);
  w.f32(std::numeric_limits<float>::quiet_NaN());
  for (double v : f64s) w.f64(v);
  w.f64(std::numeric_limits<double>::quiet_NaN());
  w.str("", 100, "test");
  w.str(with_nul, 100, "test");
  w.str(longest, 100, "test");  // exactly at the limit
  w.bytes(with_nul);
  w.f32s(f32s, 7);
  const std::string bytes = w.data();
  CHECK(bytes.size() == w.size());
  CHECK(bytes.size() == 2 + 8 + 16 + 12 + 8 * 4 + 7 * 8 + 4 + (4 + 3) + (4 + 100) + 3 + 7 * 4);

  BinaryReader r(bytes, "round trip");
  CHECK(r.u8("a") == 0);
  CHECK(r.u8("a") == 255);
  CHECK(r.u32("a") == 0);
  CHECK(r.u32("a") == std::numeric_limits<std::uint32_t>::max());
  CHECK(r.u64("a") == std::numeric_limits<std::uint64_t>::max());
  CHECK(r.u64("a") == 1ULL << 63);
  CHECK(r.i32("a") == std::numeric_limits<std::int32_t>::min());
  CHECK(r.i32("a") == std::numeric_limits<std::int32_t>::max());
  CHECK(r.i32("a") == -1);
  for (float v : f32s) {
    const float got = r.f32("a");
    CHECK(got == v);
    CHECK(std::signbit(got) == std::signbit(v));  // -0 stays -0
  }
  CHECK(std::isnan(r.f32("a")));
  for (double v : f64s) {
    const double got = r.f64("a");
    CHECK(got == v);
    CHECK(std::signbit(got) == std::signbit(v));
  }
  CHECK(std::isnan(r.f64("a")));
  CHECK(r.str("a", 100).empty());
  CHECK(r.str("a", 100) == with_nul);
  CHECK(r.str("a", 100) == longest);
  CHECK(r.bytes(3, "a") == with_nul);
  CHECK(r.offset() == bytes.size() - 28);
  std::vector<float> back(7);
  r.f32s(back.data(), back.size(), "a");
  for (std::size_t i = 0; i < back.size(); ++i) CHECK(back[i] == f32s[i]);
  CHECK(r.at_end());
  CHECK(r.remaining() == 0);
  r.expect_end("the floats");
}

TEST_CASE("binary: exact little-endian bytes") {
  auto bytes_of = [](auto write) {
    BinaryWriter w;
    write(w);
    return hex(w.data());
  };
  CHECK(bytes_of([](BinaryWriter& w) { w.u8(0xAB); }) == "ab");
  CHECK(bytes_of([](BinaryWriter& w) { w.u32(0x01020304U); }) == "04030201");
  CHECK(bytes_of([](BinaryWriter& w) { w.u64(0x0102030405060708ULL); }) == "0807060504030201");
  CHECK(bytes_of([](BinaryWriter& w) { w.i32(-2); }) == "feffffff");
  CHECK(bytes_of([](BinaryWriter& w) { w.f32(1.0f); }) == "0000803f");
  CHECK(bytes_of([](BinaryWriter& w) { w.f32(-2.5f); }) == "000020c0");
  CHECK(bytes_of([](BinaryWriter& w) { w.f64(1.0); }) == "000000000000f03f");
  CHECK(bytes_of([](BinaryWriter& w) { w.f64(-0.0); }) == "0000000000000080");
  CHECK(bytes_of([](BinaryWriter& w) { w.str("ab", 10, "test"); }) == "020000006162");
  const float two[] = {1.0f, -2.5f};
  CHECK(bytes_of([&](BinaryWriter& w) { w.f32s(two, 2); }) == "0000803f000020c0");

  // And the reader takes the same bytes, whatever the host's order.
  const std::string in("\x04\x03\x02\x01\x08\x07\x06\x05\x04\x03\x02\x01\xfe\xff\xff\xff", 16);
  BinaryReader r(in, "fixed bytes");
  CHECK(r.u32("a") == 0x01020304U);
  CHECK(r.u64("b") == 0x0102030405060708ULL);
  CHECK(r.i32("c") == -2);
}

TEST_CASE("binary: truncation at every byte of a small record is an Error naming file, offset and field") {
  const std::string record = small_record();
  REQUIRE(record.size() == 1 + 4 + 8 + 4 + 4 + 8 + 7 + 2);
  CHECK(read_record(record));
  for (std::size_t cut = 0; cut < record.size(); ++cut) {
    CAPTURE(cut);
    const std::string_view part(record.data(), cut);
    CHECK_THROWS_AS((void)read_record(part), vmap::Error);
    const std::string msg = message([&] { (void)read_record(part); });
    CHECK(msg.find("record 'r.bin'") != std::string::npos);
    CHECK(msg.find("truncated") != std::string::npos);
    CHECK(msg.find("(at byte ") != std::string::npos);
  }
  // Cut inside the u64 (bytes 5..12): the message says where and what.
  CHECK(message([&] { (void)read_record(std::string_view(record.data(), 9)); }) ==
        "record 'r.bin': truncated or corrupt: the u64 needs 8 bytes, 4 left (at byte 5)");
  // A trailing byte is an Error too.
  CHECK(message([&] { (void)read_record(record + "z"); }) ==
        "record 'r.bin': corrupt: 1 unexpected bytes after the tail (at byte 38)");
  // A reader over part of a file reports offsets in the whole file.
  BinaryReader payload(std::string_view(record.data(), 3), "map file 'm.vmap'", 24);
  (void)payload.u8("a");
  CHECK(message([&] { (void)payload.u32("the count"); }) ==
        "map file 'm.vmap': truncated or corrupt: the count needs 4 bytes, 2 left (at byte 25)");
}

TEST_CASE("binary: require_items refuses a huge count before anything is allocated") {
  const std::string sixteen(16, '\0');
  BinaryReader r(sixteen, "GCS file 'g.gcs'");
  r.require_items(2, 8, "the cell count");   // exactly fits
  r.require_items(0, 1000, "the cell count");
  CHECK_THROWS_WITH_AS(r.require_items(3, 8, "the cell count"),
                       "GCS file 'g.gcs': truncated or corrupt: the cell count claims 3 items of 8 bytes, 16 bytes "
                       "left (at byte 0)",
                       vmap::Error);
  // The typical guard: the count comes from the file, the vector is sized only after
  // the check, so a hostile count never reaches the allocator.
  std::vector<double> cells;
  auto load = [&](std::uint64_t count) {
    r.require_items(count, sizeof(double), "the cell count");
    cells.resize(static_cast<std::size_t>(count));
  };
  CHECK_THROWS_AS(load(std::uint64_t{1} << 60), vmap::Error);
  CHECK_THROWS_AS(load(std::numeric_limits<std::uint64_t>::max()), vmap::Error);
  // count * item_bytes wraps around to 8 here; the check must not multiply.
  CHECK_THROWS_AS(load((std::uint64_t{1} << 61) + 1), vmap::Error);
  CHECK(cells.capacity() == 0);
  CHECK_THROWS_AS(r.require_items(1, 0, "nothing"), vmap::Error);  // item size 0 is a caller error

  // f32s checks its count before writing anything.
  std::vector<float> out(2, 42.0f);
  CHECK_THROWS_AS(r.f32s(out.data(), std::uint64_t{1} << 62, "descriptors"), vmap::Error);
  CHECK(out[0] == 42.0f);
  CHECK(r.offset() == 0);
  // So does bytes().
  CHECK_THROWS_AS((void)r.bytes(std::numeric_limits<std::uint64_t>::max(), "the image"), vmap::Error);
}

TEST_CASE("binary: string length limits on both sides") {
  BinaryWriter w;
  CHECK_THROWS_WITH_AS(w.str(std::string(5, 'x'), 4, "save_map: a key image name"),
                       "save_map: a key image name is longer than 4 bytes", vmap::Error);
  CHECK(w.size() == 0);  // nothing half-written
  w.u8(0xAA);
  w.u32(5000);  // a hostile length
  w.bytes(std::string(8, 'x'));
  BinaryReader r(w.data(), "map file 'm.vmap'");
  (void)r.u8("flag");
  CHECK_THROWS_WITH_AS((void)r.str("name", 4096), "map file 'm.vmap': name is 5000 bytes long (limit 4096) (at byte 1)",
                       vmap::Error);
}

TEST_CASE("binary: crc32 is the zlib / PNG CRC-32") {
  CHECK(vmap::detail::crc32("123456789") == 0xCBF43926U);
  CHECK(vmap::detail::crc32("") == 0U);
  CHECK(vmap::detail::crc32("The quick brown fox jumps over the lazy dog") == 0x414FA339U);
}

namespace {
struct Inner {
  int a = 0;
  double b = 0.0;
};
enum class Mode : std::uint8_t { x, y };
struct Outer {
  Inner inner{};  // a nested aggregate counts as one field
  Mode mode = Mode::x;
  std::vector<int> list{};
  std::string name;
  bool flag = false;
};
struct Empty {};
}  // namespace

// The options codecs assert their structs' field counts; the count must be exact for
// nested aggregates, enums and library types alike, or a new field could pass unnoticed.
TEST_CASE("binary: field_count counts an aggregate's fields") {
  static_assert(vmap::detail::field_count<Inner>() == 2);
  static_assert(vmap::detail::field_count<Outer>() == 5);
  static_assert(vmap::detail::field_count<Empty>() == 0);
  CHECK(vmap::detail::field_count<Outer>() == 5);
}
