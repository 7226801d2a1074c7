// Robot bags as frame sources (io/bag/, the vmap::bags component): the CDR decoder,
// every image encoding in each container, topics, CameraInfo, stamps, bounds on what a
// file claims, damage (a bag cut at every record boundary, bit flips), the pipelined
// run, and a program without the component. The bags are written here: ROS 1 by
// Debian's rosbag (tests/support/write_ros1_bags.py), rosbag2 and MCAP by
// tests/support/bags.hpp.

#include "support/bags.hpp"
#include "support/errors.hpp"
#include "support/fifo.hpp"
#include "support/peak_memory.hpp"
#include "support/shared_data.hpp"

#include <vmap/io/bag/bag.hpp>
#include <vmap/io/bag/cdr.hpp>
#include <vmap/io/frame_source.hpp>
#include <vmap/keyframe/pipeline.hpp>

#include <doctest/doctest.h>
#include <opencv2/imgcodecs.hpp>
#include <opencv2/imgproc.hpp>

#include <chrono>
#include <cstdint>
#include <filesystem>
#include <limits>
#include <map>
#include <random>
#include <string>
#include <vector>

namespace fs = std::filesystem;
using vmap::test::error_of;

namespace {

using vmap::test::same_pixels;

/// Pixel (x, y) of channel c of message k in the test bags (write_ros1_bags.py).
int pattern(int x, int y, int c, int k) { return (x + 2 * y + 40 * c + 7 * k) % 256; }

/// The image the test pattern gives in OpenCV's order for `encoding` (channels of the
/// message reordered to BGR(A)), 8- or 16-bit.
cv::Mat expected_image(const std::string& encoding, int k, int w = 24, int h = 20) {
  const bool wide = encoding == "mono16" || encoding == "16UC1";
  const int channels = encoding == "rgb8" || encoding == "bgr8" || encoding == "8UC3" ? 3
                       : encoding == "rgba8" || encoding == "bgra8"                  ? 4
                                                                                      : 1;
  cv::Mat m(h, w, CV_MAKETYPE(wide ? CV_16U : CV_8U, channels));
  for (int y = 0; y < h; ++y)
    for (int x = 0; x < w; ++x)
      for (int c = 0; c < channels; ++c) {
        // Channel c of the message lands at OpenCV channel c, except for RGB(A), whose
        // first three are reversed.
        const bool rgb = encoding == "rgb8" || encoding == "rgba8";
        const int at = rgb && c < 3 ? 2 - c : c;
        if (wide)
          m.ptr<std::uint16_t>(y)[x * channels + at] = static_cast<std::uint16_t>(pattern(x, y, c, k) * 257);
        else
          m.ptr<std::uint8_t>(y)[x * channels + at] = static_cast<std::uint8_t>(pattern(x, y, c, k));
      }
  return m;
}

cv::Mat expected_grey(const std::string& encoding, int k) {
  cv::Mat e = expected_image(encoding, k);
  if (e.depth() == CV_16U) {
    cv::Mat g;
    e.convertTo(g, CV_8U, 1.0 / 257.0);
    return g;
  }
  if (e.channels() == 1) return e;
  cv::Mat g;
  cv::cvtColor(e, g, e.channels() == 4 ? cv::COLOR_BGRA2GRAY : cv::COLOR_BGR2GRAY);
  return g;
}

struct Read {
  std::vector<vmap::Frame> frames;
  std::vector<vmap::SkippedFrame> skipped;
  std::vector<std::string> warnings;
};

Read read_all(const fs::path& bag, vmap::FrameSourceOptions o = {}) {
  Read r;
  o.on_skip = [&](const vmap::SkippedFrame& s) { r.skipped.push_back(s); };
  o.on_warning = [&](const std::string& w) { r.warnings.push_back(w); };
  auto src = vmap::FrameSource::open(bag, o);
  while (auto f = src.next()) r.frames.push_back(std::move(*f));
  return r;
}

/// A ROS 1 bag's records: header fields by name, for patching test bags.
struct Ros1Record {
  std::size_t at = 0, header_len = 0, data_len = 0;
};

Ros1Record ros1_record(const std::string& bytes, std::size_t at) {
  Ros1Record r;
  r.at = at;
  r.header_len = vmap::detail::le_u32(bytes.data() + at);
  r.data_len = vmap::detail::le_u32(bytes.data() + at + 4 + r.header_len);
  return r;
}

int ros1_op(const std::string& bytes, const Ros1Record& r) {
  vmap::detail::Ros1Header h;
  std::string why;
  REQUIRE(vmap::detail::parse_ros1_header(std::string_view(bytes.data() + r.at + 4, r.header_len), h, why));
  return h.op;
}

/// Offset of field `name=` inside the header of record `r`: where its value starts.
std::size_t ros1_field(const std::string& bytes, const Ros1Record& r, const std::string& name) {
  const std::string key = name + "=";
  const auto at = bytes.find(key, r.at + 4);
  REQUIRE(at != std::string::npos);
  REQUIRE(at < r.at + 4 + r.header_len);
  return at + key.size();
}

void put_u32(std::string& bytes, std::size_t at, std::uint32_t v) {
  for (int i = 0; i < 4; ++i) bytes[at + static_cast<std::size_t>(i)] = static_cast<char>((v >> (8 * i)) & 0xff);
}

const std::vector<std::string> encodings_read = {"mono8", "8UC1", "mono16", "16UC1", "rgb8", "bgr8", "8UC3", "rgba8", "bgra8"};

/// The ROS 2 test messages: each encoding as in the ROS 1 bags (16-bit ones big-endian
/// too), a PNG CompressedImage, an equidistant CameraInfo beside /cam/image_raw, an
/// unread encoding and a non-image topic.
std::vector<vmap::test::TestMessage> ros2_messages() {
  std::vector<vmap::test::TestMessage> out;
  for (int k = 0; k < 3; ++k) {
    const std::int64_t t = 2000000000LL * (k + 1) + 17;
    for (const auto& enc : encodings_read) {
      for (bool big : {false, true}) {
        const bool wide = enc == "mono16" || enc == "16UC1";
        if (big && !wide) continue;
        cv::Mat e = expected_image(enc, k);
        // Back to the message's channel order and byte order.
        if (enc == "rgb8") cv::cvtColor(e, e, cv::COLOR_BGR2RGB);
        if (enc == "rgba8") cv::cvtColor(e, e, cv::COLOR_BGRA2RGBA);
        std::string data(reinterpret_cast<const char*>(e.data), e.total() * e.elemSize());
        if (big)
          for (std::size_t i = 0; i + 1 < data.size(); i += 2) std::swap(data[i], data[i + 1]);
        const auto step = static_cast<std::uint32_t>(e.cols * e.elemSize());
        out.push_back({"/" + enc + (big ? "_be" : "") + "/image_raw", "sensor_msgs/msg/Image", t + 5,
                       vmap::test::cdr_image(t, 24, 20, enc, step, data, big)});
      }
    }
    std::vector<uchar> png;
    cv::imencode(".png", expected_image("mono8", k), png);
    out.push_back({"/cam/image_raw/compressed", "sensor_msgs/msg/CompressedImage", t + 5,
                   vmap::test::cdr_compressed(t, "mono8; png compressed", std::string(png.begin(), png.end()))});
    out.push_back({"/cam/camera_info", "sensor_msgs/msg/CameraInfo", t + 5,
                   vmap::test::cdr_camera_info(t, 24, 20, "equidistant", {0.01, -0.02, 0.003, -0.004},
                                               {20, 0, 12.5, 0, 20.5, 9.5, 0, 0, 1})});
    out.push_back({"/bayer/image_raw", "sensor_msgs/msg/Image", t + 5,
                   vmap::test::cdr_image(t, 24, 20, "bayer_rggb8", 24, std::string(480, '\x10'))});
    out.push_back({"/imu", "sensor_msgs/msg/Imu", t + 5, vmap::test::CdrWriter().header(t).str()});
  }
  return out;
}

/// The ROS 2 test bags: a .db3 and MCAP files in each chunk compression.
std::vector<fs::path> ros2_test_bags(const std::string& name) {
  const auto dir = vmap::test::scratch_dir(name);
  const auto messages = ros2_messages();
  vmap::test::write_db3(dir / "bag.db3", messages);
  vmap::test::write_mcap(dir / "zstd.mcap", messages, "zstd");
  vmap::test::write_mcap(dir / "lz4.mcap", messages, "lz4");
  vmap::test::write_mcap(dir / "none.mcap", messages, "");
  return {dir / "bag.db3", dir / "zstd.mcap", dir / "lz4.mcap", dir / "none.mcap"};
}

}  // namespace

TEST_CASE("CDR: little- and big-endian, alignment counted after the encapsulation header, XCDR2, bounds") {
  // u8 1, (pad 3) u32 0x01020304, (pad 0: offset 8) f64 1.5, string "ab".
  const std::string le("\x00\x01\x00\x00\x01\x00\x00\x00\x04\x03\x02\x01\x00\x00\x00\x00\x00\x00\xf8\x3f\x03\x00\x00\x00"
                       "ab\x00",
                       27);
  vmap::detail::CdrReader r(le, "m");
  CHECK(r.u8() == 1);
  CHECK(r.u32() == 0x01020304u);
  CHECK(r.f64() == 1.5);
  CHECK(r.string() == "ab");
  const std::string be("\x00\x00\x00\x00\x01\x00\x00\x00\x01\x02\x03\x04", 12);
  vmap::detail::CdrReader b(be, "m");
  CHECK(b.u8() == 1);
  CHECK(b.u32() == 0x01020304u);
  // XCDR2 aligns 8-byte values to 4: u32 then f64 with no padding between.
  const std::string x2("\x00\x07\x00\x00\x01\x00\x00\x00\x00\x00\x00\x00\x00\x00\xf8\x3f", 16);
  vmap::detail::CdrReader c(x2, "m");
  CHECK(c.u32() == 1u);
  CHECK(c.f64() == 1.5);
  CHECK(error_of([&] { (void)c.u8(); }).find("m: the message ends at byte 16") != std::string::npos);
  CHECK(error_of([] { vmap::detail::CdrReader(std::string_view("\x00\x02\x00\x00", 4), "m"); }).find("unknown CDR encapsulation 00 02") !=
        std::string::npos);
  // A sequence that claims more bytes than the message holds.
  const std::string huge("\x00\x01\x00\x00\xff\xff\xff\xff", 8);
  vmap::detail::CdrReader h(huge, "m");
  CHECK(error_of([&] { (void)h.byte_sequence(); }).find("needs 4294967295 more") != std::string::npos);
}

TEST_CASE("ROS 1 bags (rosbag's writer; none, bz2, lz4 chunks): every encoding exact, others refused by name") {
  for (const char* compression : {"none", "bz2", "lz4"}) {
    CAPTURE(compression);
    const auto bag = vmap::test::ros1_test_bags() / ("encodings_" + std::string(compression) + ".bag");
    const auto info = vmap::bag_info(bag);
    CHECK(info.format == vmap::BagFormat::ros1);
    CHECK(info.indexed);
    CHECK(info.topics.size() == 12);
    CHECK(info.messages == 36);
    CHECK(info.start_ns == 100000015000LL);  // "/8UC1/image_raw": 15 characters
    for (const auto& enc : encodings_read)
      for (bool big : {false, true}) {
        if (big && enc != "mono16" && enc != "16UC1") continue;
        const std::string topic = "/" + enc + (big ? "_be" : "") + "/image_raw";
        CAPTURE(topic);
        for (bool grey : {false, true}) {
          const auto r = read_all(bag, {.grey = grey, .topic = topic});
          REQUIRE(r.frames.size() == 3);
          CHECK(r.skipped.empty());
          for (int k = 0; k < 3; ++k) {
            const auto& f = r.frames[static_cast<std::size_t>(k)];
            CHECK(same_pixels(f.image, grey ? expected_grey(enc, k) : expected_image(enc, k)));
            const std::int64_t stamp = (100LL + k) * 1000000000LL + 1000LL * static_cast<std::int64_t>(topic.size());
            CHECK(f.time_ns == stamp);
            CHECK(f.name == topic + "@" + std::to_string(stamp));
            CHECK(f.index == static_cast<std::size_t>(k));
          }
        }
      }
    // An encoding vmap does not read: each frame skipped, the reason naming the topic,
    // the message type and the encoding; a topic with no readable frame is an Error.
    Read r;
    const std::string e = error_of([&] { r = read_all(bag, {.topic = "/bayer_rggb8/image_raw"}); });
    CHECK(e.find("no frame of") != std::string::npos);
    vmap::FrameSourceOptions o{.topic = "/bayer_rggb8/image_raw"};
    auto src = vmap::FrameSource::open(bag, o);
    auto p = src.claim();
    REQUIRE(p);
    const auto d = src.decode(std::move(*p));
    REQUIRE(std::holds_alternative<vmap::SkippedFrame>(d));
    const std::string reason = std::get<vmap::SkippedFrame>(d).reason;
    CHECK(reason.find("topic '/bayer_rggb8/image_raw'") != std::string::npos);
    CHECK(reason.find("sensor_msgs/Image") != std::string::npos);
    CHECK(reason.find("encoding 'bayer_rggb8' is not read") != std::string::npos);
  }
}

TEST_CASE("rosbag2 sqlite3 and MCAP (zstd, lz4, uncompressed): every encoding exact, CDR big-endian 16-bit swapped") {
  for (const auto& bag : ros2_test_bags("ros2_encodings")) {
    CAPTURE(bag.string());
    const auto info = vmap::bag_info(bag);
    CHECK(info.topics.size() == 15);
    CHECK(info.messages == 45);
    CHECK(info.start_ns == 2000000022LL);
    CHECK(info.end_ns == 6000000022LL);
    for (const auto& enc : encodings_read)
      for (bool big : {false, true}) {
        if (big && enc != "mono16" && enc != "16UC1") continue;
        const std::string topic = "/" + enc + (big ? "_be" : "") + "/image_raw";
        CAPTURE(topic);
        for (bool grey : {false, true}) {
          const auto r = read_all(bag, {.grey = grey, .topic = topic});
          REQUIRE(r.frames.size() == 3);
          for (int k = 0; k < 3; ++k) {
            const auto& f = r.frames[static_cast<std::size_t>(k)];
            CHECK(same_pixels(f.image, grey ? expected_grey(enc, k) : expected_image(enc, k)));
            CHECK(f.time_ns == 2000000000LL * (k + 1) + 17);
          }
        }
      }
    // PNG CompressedImage, with the equidistant CameraInfo beside it.
    const auto r = read_all(bag, {.topic = "/cam/image_raw/compressed"});
    REQUIRE(r.frames.size() == 3);
    CHECK(same_pixels(r.frames[2].image, expected_image("mono8", 2)));
    auto src = vmap::FrameSource::open(bag, {.topic = "/cam/image_raw/compressed"});
    REQUIRE(src.camera());
    CHECK(src.camera()->camera.lens == vmap::LensModel::fisheye);
    CHECK(src.camera()->camera.fx == 20.0);
    CHECK(src.camera()->camera.cy == 9.5);
    CHECK(src.camera()->camera.distortion == std::vector<double>{0.01, -0.02, 0.003, -0.004});
    CHECK(src.camera()->camera.image_size == cv::Size(24, 20));
    CHECK(src.camera()->source.find("topic '/cam/camera_info'") != std::string::npos);
    // Record times instead of header stamps.
    const auto rec = read_all(bag, {.topic = "/mono8/image_raw", .record_time = true});
    CHECK(rec.frames[0].time_ns == 2000000022LL);
    CHECK(error_of([&] { (void)vmap::FrameSource::open(bag, {.topic = "/imu"}); })
              .find("topic '/imu' holds sensor_msgs/msg/Imu, not images") != std::string::npos);
  }
}

TEST_CASE("topics: one image topic needs no choice; several list themselves; CameraInfo beside the topic") {
  const auto dir = vmap::test::ros1_test_bags();
  const auto camera_bag = dir / "camera.bag";
  const std::string several = error_of([&] { (void)vmap::FrameSource::open(camera_bag); });
  CHECK(several.find("has 2 image topics: choose one") != std::string::npos);
  CHECK(several.find("/cam/image_raw (sensor_msgs/Image, 3 messages)") != std::string::npos);
  CHECK(several.find("/fish/image_raw/compressed (sensor_msgs/CompressedImage, 2 messages)") != std::string::npos);
  CHECK(error_of([&] { (void)vmap::FrameSource::open(camera_bag, {.topic = "/nope"}); })
            .find("has no topic '/nope'; its topics: /cam/camera_info (sensor_msgs/CameraInfo, 3 messages)") !=
        std::string::npos);

  auto src = vmap::FrameSource::open(camera_bag, {.topic = "/cam/image_raw"});
  CHECK(src.kind() == vmap::SourceKind::bag);
  CHECK(src.bag_format() == vmap::BagFormat::ros1);
  CHECK(src.total() == 3u);
  REQUIRE(src.camera());
  const vmap::Camera& c = src.camera()->camera;
  CHECK(c.lens == vmap::LensModel::pinhole);
  CHECK(c.fx == 30.0);
  CHECK(c.fy == 31.0);
  CHECK(c.cx == 12.0);
  CHECK(c.cy == 10.0);
  CHECK(c.distortion == std::vector<double>{0.1, -0.2, 0.001, 0.002, 0.05});
  CHECK(src.camera()->source == "bag '" + camera_bag.string() + "', topic '/cam/camera_info' (its first CameraInfo)");
  // Header stamps, exact; record times 1 ms later; the times without decoding.
  const std::vector<std::int64_t> stamps{1000000000005LL, 1010000000005LL, 1020000000005LL};
  CHECK(src.times_ns() == stamps);
  CHECK(src.timestamps()[1] == doctest::Approx(1010.000000005));
  const auto rec = read_all(camera_bag, {.topic = "/cam/image_raw", .record_time = true});
  REQUIRE(rec.frames.size() == 3);
  CHECK(rec.frames[1].time_ns == 1010001000005LL);
  CHECK(rec.frames[1].name == "/cam/image_raw@1010001000005");
  // start / end / stride count the topic's messages.
  const auto strided = read_all(camera_bag, {.start = 1, .stride = 2, .topic = "/cam/image_raw"});
  REQUIRE(strided.frames.size() == 1);
  CHECK(strided.frames[0].index == 1);
  CHECK(strided.frames[0].time_ns == stamps[1]);
  // PNG frames beside an equidistant CameraInfo.
  auto fish = vmap::FrameSource::open(camera_bag, {.grey = true, .topic = "/fish/image_raw/compressed"});
  REQUIRE(fish.camera());
  CHECK(fish.camera()->camera.lens == vmap::LensModel::fisheye);
  CHECK(fish.camera()->camera.distortion == std::vector<double>{0.01, -0.02, 0.003, -0.004});
  auto f = fish.next();
  REQUIRE(f);
  CHECK(same_pixels(f->image, expected_image("mono8", 0)));
  // bag_camera() finds the same without a frame source.
  std::string note;
  const auto same = vmap::bag_camera(camera_bag, "/cam/image_raw", &note);
  REQUIRE(same);
  CHECK(same->camera.describe() == c.describe());
  CHECK(note.empty());
  // A CameraInfo whose K is zero gives no calibration, and says why.
  CHECK(vmap::detail::camera_info_topic_for("/cam/image_raw/compressed") == "/cam/camera_info");
  std::string why;
  const auto topics = vmap::bag_info(camera_bag).topics;
  CHECK_FALSE(vmap::detail::read_bag_camera(camera_bag, topics, "/cam/camera_info_zero", {}, why));
  CHECK(why.find("K matrix is all zero") != std::string::npos);
}

TEST_CASE("a bag with no image topic, and an empty bag, are Errors that say so") {
  const auto dir = vmap::test::ros1_test_bags();
  CHECK(error_of([&] { (void)vmap::FrameSource::open(dir / "no_images.bag"); }) ==
        "bag '" + (dir / "no_images.bag").string() +
            "' has no image topic (sensor_msgs/Image or sensor_msgs/CompressedImage); its topics: /imu/data "
            "(sensor_msgs/Imu, 1 message)");
  const auto empty = vmap::bag_info(dir / "empty.bag");
  CHECK(empty.topics.empty());
  CHECK(empty.messages == 0);
  CHECK(empty.warnings.empty());
  CHECK(error_of([&] { (void)vmap::FrameSource::open(dir / "empty.bag"); }).find("has no image topic") != std::string::npos);
  const auto scratch = vmap::test::scratch_dir("empty_ros2");
  vmap::test::write_db3(scratch / "empty.db3", {});
  vmap::test::write_mcap(scratch / "empty.mcap", {});
  for (const char* name : {"empty.db3", "empty.mcap"}) {
    CHECK(vmap::bag_info(scratch / name).messages == 0);
    CHECK(error_of([&] { (void)vmap::FrameSource::open(scratch / name); }).find("has no image topic") != std::string::npos);
  }
  // Not a bag of its extension.
  vmap::test::write_bytes(scratch / "x.bag", "#ROSBAG V1.2\n");
  CHECK(error_of([&] { (void)vmap::bag_info(scratch / "x.bag"); }).find("is not a ROS 1 bag of format 2.0") !=
        std::string::npos);
  vmap::test::write_bytes(scratch / "x.mcap", "hello");
  CHECK(error_of([&] { (void)vmap::bag_info(scratch / "x.mcap"); }).find("is not an MCAP file") != std::string::npos);
  vmap::test::write_bytes(scratch / "x.db3", "hello");
  CHECK(error_of([&] { (void)vmap::bag_info(scratch / "x.db3"); }).find("is not a rosbag2 sqlite3 file") !=
        std::string::npos);
}

TEST_CASE("sizes read from a bag are checked before anything is allocated") {
  const auto scratch = vmap::test::scratch_dir("bag_bounds");
  const auto original = vmap::test::read_bytes(vmap::test::ros1_test_bags() / "encodings_none.bag");
  const auto boundaries = vmap::test::record_boundaries(original, vmap::BagFormat::ros1);
  std::size_t first_chunk = 0;
  for (std::size_t at : boundaries)
    if (at < original.size() && ros1_op(original, ros1_record(original, at)) == 0x05) {
      first_chunk = at;
      break;
    }
  REQUIRE(first_chunk > 0);
  const auto full = vmap::test::all_messages(vmap::test::ros1_test_bags() / "encodings_none.bag");
  const Ros1Record chunk = ros1_record(original, first_chunk);
  std::size_t in_first = 0;
  for (const auto& m : full) in_first += m.offset == first_chunk ? 1 : 0;
  REQUIRE(in_first > 0);

  SUBCASE("a chunk that claims 4 GB is skipped with a warning; the other chunks are read") {
    std::string bytes = original;
    put_u32(bytes, ros1_field(bytes, chunk, "size"), 0xFFFFFFF0u);
    vmap::test::write_bytes(scratch / "huge_chunk.bag", bytes);
    auto s = vmap::detail::open_message_stream(scratch / "huge_chunk.bag");
    const auto got = vmap::test::all_messages(*s);
    CHECK(got.size() == full.size() - in_first);
    REQUIRE(s->warnings().size() == 1);
    CHECK(s->warnings()[0].find("chunk at byte " + std::to_string(first_chunk) +
                                " claims 4294967280 uncompressed bytes, more than the limit") != std::string::npos);
  }
  SUBCASE("a message longer than its chunk ends the chunk with a warning") {
    std::string bytes = original;
    // The chunk's first record (a connection) claims more data than the chunk holds.
    const std::size_t inner = chunk.at + 8 + chunk.header_len;
    const std::uint32_t hl = vmap::detail::le_u32(bytes.data() + inner);
    put_u32(bytes, inner + 4 + hl, 0x7FFFFFF0u);
    vmap::test::write_bytes(scratch / "long_message.bag", bytes);
    auto s = vmap::detail::open_message_stream(scratch / "long_message.bag");
    const auto got = vmap::test::all_messages(*s);
    CHECK(got.size() == full.size() - in_first);
    REQUIRE_FALSE(s->warnings().empty());
    CHECK(s->warnings().back().find("the record at byte 0 of its") != std::string::npos);
    CHECK(s->warnings().back().find("runs past its end") != std::string::npos);
  }
  SUBCASE("a damaged record header: reading resumes at the next chunk the index lists") {
    std::string bytes = original;
    put_u32(bytes, first_chunk, 0x7FFFFFF0u);
    vmap::test::write_bytes(scratch / "long_header.bag", bytes);
    auto s = vmap::detail::open_message_stream(scratch / "long_header.bag");
    const auto got = vmap::test::all_messages(*s);
    CHECK(got.size() == full.size() - in_first);
    REQUIRE(s->warnings().size() == 1);
    CHECK(s->warnings()[0].find("damaged at byte " + std::to_string(first_chunk) +
                                " (a record header claims 2147483632 bytes, more than the limit of 16777216") !=
          std::string::npos);
    CHECK(s->warnings()[0].find("reading resumes at the next chunk") != std::string::npos);
  }
  SUBCASE("MCAP: a chunk that claims 4 GB uncompressed is skipped; a limit below a chunk skips it") {
    const auto bags = ros2_test_bags("bag_bounds_mcap");
    const auto mcap_bytes = vmap::test::read_bytes(bags[1]);
    const auto mb = vmap::test::record_boundaries(mcap_bytes, vmap::BagFormat::mcap);
    std::size_t mchunk = 0;
    for (std::size_t at : mb)
      if (at < mcap_bytes.size() && mcap_bytes[at] == 0x06) {
        mchunk = at;
        break;
      }
    REQUIRE(mchunk > 0);
    std::string bytes = mcap_bytes;
    // Chunk body: start time, end time (8 + 8), uncompressed size (8).
    for (int i = 0; i < 8; ++i) bytes[mchunk + 9 + 16 + static_cast<std::size_t>(i)] = i < 4 ? '\xff' : '\0';
    vmap::test::write_bytes(scratch / "huge.mcap", bytes);
    auto s = vmap::detail::open_message_stream(scratch / "huge.mcap");
    const auto got = vmap::test::all_messages(*s);
    CHECK(got.size() < vmap::test::all_messages(bags[1]).size());
    REQUIRE_FALSE(s->warnings().empty());
    CHECK(s->warnings()[0].find("claims 4294967295 uncompressed bytes, more than the limit") != std::string::npos);
    auto small = vmap::detail::open_message_stream(bags[1], {.max_chunk_bytes = 1000});
    CHECK(vmap::test::all_messages(*small).empty());
    CHECK(small->warnings()[0].find("(BagLimits::max_chunk_bytes); skipped") != std::string::npos);
  }
  SUBCASE("an image whose size claims more than its message, or more pixels than the limit, is a skipped frame") {
    vmap::test::write_db3(scratch / "claims.db3",
                          {{"/c/image_raw", "sensor_msgs/msg/Image", 1, vmap::test::cdr_image(1, 65536, 65536, "mono8", 65536, "abc")},
                           {"/c/image_raw", "sensor_msgs/msg/Image", 2, vmap::test::cdr_image(2, 100, 100, "mono8", 100, "abc")},
                           {"/c/image_raw", "sensor_msgs/msg/Image", 3, vmap::test::cdr_image(3, 10, 10, "mono8", 5, std::string(100, 'x'))}});
    Read r;
    CHECK(error_of([&] { r = read_all(scratch / "claims.db3"); }).find("no frame of") != std::string::npos);
    auto src = vmap::FrameSource::open(scratch / "claims.db3");
    std::vector<std::string> reasons;
    while (auto p = src.claim()) reasons.push_back(std::get<vmap::SkippedFrame>(src.decode(std::move(*p))).reason);
    REQUIRE(reasons.size() == 3);
    CHECK(reasons[0].find("the image is 65536x65536 pixels, more than the limit of 67108864") != std::string::npos);
    CHECK(reasons[1].find("carries 3 bytes of pixels, mono8 100x100 with step 100 needs 10000") != std::string::npos);
    CHECK(reasons[2].find("needs a step of at least 10 bytes, the message says 5") != std::string::npos);
  }
}

namespace {

/// Flipping one bit at `count` seeded places: no crash, only vmap::Error, and the
/// messages of the records before the flipped byte delivered as they were.
void check_flips(const fs::path& bag, vmap::BagFormat format, const std::string& scratch_name, int count) {
  const auto dir = vmap::test::scratch_dir(scratch_name);
  const auto bytes = vmap::test::read_bytes(bag);
  const auto full = vmap::test::all_messages(bag);
  const auto bounds = vmap::test::record_boundaries(bytes, format);
  std::map<std::uint64_t, std::uint64_t> record_end;
  for (std::size_t i = 0; i + 1 < bounds.size(); ++i) record_end[bounds[i]] = bounds[i + 1];
  std::mt19937 rng(7);
  std::uniform_int_distribution<std::size_t> where(0, bytes.size() - 1);
  const auto file = dir / ("flip" + bag.extension().string());
  for (int i = 0; i < count; ++i) {
    const std::size_t at = where(rng);
    const int bit = static_cast<int>(rng() % 8);
    CAPTURE(at);
    std::string b = bytes;
    b[at] = static_cast<char>(b[at] ^ (1 << bit));
    vmap::test::write_bytes(file, b);
    std::vector<vmap::test::ReadMessage> got;
    bool threw_other = false;
    try {
      got = vmap::test::all_messages(file);
    } catch (const vmap::Error&) {
      continue;
    } catch (...) {
      threw_other = true;
    }
    CHECK_FALSE(threw_other);
    if (format == vmap::BagFormat::rosbag2_sqlite) continue;  // SQLite pages are not in message order
    // The messages of records that end before the flip, unless the flip hit the index
    // that names their topics.
    std::size_t before = 0;
    for (const auto& m : full) before += record_end.at(m.offset) <= at ? 1 : 0;
    REQUIRE(got.size() >= before);
    for (std::size_t k = 0; k < before; ++k) {
      CHECK(got[k].bytes == full[k].bytes);
      CHECK(got[k].record_ns == full[k].record_ns);
    }
    // Any frame source over the flipped bag ends with frames or a vmap::Error.
    try {
      Read r = read_all(file, {.topic = "/mono8/image_raw"});
      (void)r;
    } catch (const vmap::Error&) {
    }
  }
}

}  // namespace

TEST_CASE("each container cut at every record boundary ends with the messages before the cut") {
  for (const char* c : {"none", "bz2", "lz4"}) {
    CAPTURE(c);
    vmap::test::check_cuts(vmap::test::ros1_test_bags() / ("encodings_" + std::string(c) + ".bag"), vmap::BagFormat::ros1,
               std::string("cut_ros1_") + c);
  }
  const auto bags = ros2_test_bags("cut_ros2");
  for (std::size_t i = 1; i < bags.size(); ++i) vmap::test::check_cuts(bags[i], vmap::BagFormat::mcap, "cut_mcap");
  // A frame source over a cut bag: the frames before the cut, and a warning naming its
  // byte; the bag is cut where the chunk of the third rgb8 frame starts.
  const auto lz4_bag = vmap::test::ros1_test_bags() / "encodings_lz4.bag";
  const auto bytes = vmap::test::read_bytes(lz4_bag);
  std::uint64_t cut = 0;
  for (const auto& m : vmap::test::all_messages(lz4_bag))
    if (m.topic == "/rgb8/image_raw") cut = m.offset;
  const auto dir = vmap::test::scratch_dir("cut_frames");
  vmap::test::write_bytes(dir / "cut.bag", std::string_view(bytes).substr(0, cut));
  const auto r = read_all(dir / "cut.bag", {.topic = "/rgb8/image_raw"});
  REQUIRE(r.frames.size() == 2);
  for (std::size_t k = 0; k < r.frames.size(); ++k) CHECK(same_pixels(r.frames[k].image, expected_image("rgb8", static_cast<int>(k))));
  REQUIRE(r.warnings.size() == 1);
  const std::uint64_t index_pos = vmap::detail::le_u64(bytes.data() + bytes.find("index_pos=") + 10);
  CHECK(r.warnings[0] == "bag '" + (dir / "cut.bag").string() + "': its index at byte " + std::to_string(index_pos) +
                             " lies outside the file (" + std::to_string(cut) +
                             " bytes): the file is truncated; read through to list it");
  // rosbag2: the file cut at every page.
  const auto db3 = vmap::test::read_bytes(bags[0]);
  const auto full = vmap::test::all_messages(bags[0]);
  for (std::size_t page = 4096; page < db3.size(); page += 4096) {
    CAPTURE(page);
    vmap::test::write_bytes(dir / "cut.db3", std::string_view(db3).substr(0, page));
    std::vector<vmap::test::ReadMessage> got;
    if (error_of([&] { got = vmap::test::all_messages(dir / "cut.db3"); }) != "no error") continue;
    REQUIRE(got.size() <= full.size());
    for (std::size_t k = 0; k < got.size(); ++k) CHECK(got[k] == full[k]);
  }
}

TEST_CASE("bit flips: no crash, only vmap::Error, the messages before the damage as they were") {
  for (const char* c : {"none", "bz2", "lz4"})
    check_flips(vmap::test::ros1_test_bags() / ("encodings_" + std::string(c) + ".bag"), vmap::BagFormat::ros1,
                std::string("flip_ros1_") + c, 150);
  const auto bags = ros2_test_bags("flip_ros2");
  check_flips(bags[0], vmap::BagFormat::rosbag2_sqlite, "flip_db3", 150);
  for (std::size_t i = 1; i < bags.size(); ++i) check_flips(bags[i], vmap::BagFormat::mcap, "flip_mcap", 150);
}

TEST_CASE("pipelined runs decode bag messages on the preparing threads, in order, as next() does") {
  for (const auto& bag : {vmap::test::ros1_test_bags() / "encodings_lz4.bag", ros2_test_bags("pipeline")[1]}) {
    const vmap::FrameSourceOptions o{.grey = true, .topic = "/rgb8/image_raw"};
    const auto plain = read_all(bag, o);
    auto src = vmap::FrameSource::open(bag, o);
    std::vector<std::function<vmap::Frame(const vmap::Frame&)>> prepares(
        2, [](const vmap::Frame& f) { return vmap::Frame{f.image.clone(), f.index, f.name, f.timestamp, f.time_ns}; });
    std::vector<vmap::Frame> got;
    vmap::detail::run_pipelined_on<vmap::Frame>(src, 4, prepares, [&](vmap::Frame&& f) { got.push_back(std::move(f)); });
    REQUIRE(got.size() == plain.frames.size());
    for (std::size_t k = 0; k < got.size(); ++k) {
      CHECK(got[k].name == plain.frames[k].name);
      CHECK(same_pixels(got[k].image, plain.frames[k].image));
    }
  }
}

TEST_CASE("without the vmap::bags component: MCAP and compressed ROS 1 chunks are an Error that says what to link") {
  const auto bags = ros2_test_bags("no_component");
  const vmap::detail::BagComponent* component = vmap::detail::bag_component();
  REQUIRE(component != nullptr);
  vmap::detail::bag_component() = nullptr;
  const std::string mcap = error_of([&] { (void)vmap::FrameSource::open(bags[1], {.topic = "/mono8/image_raw"}); });
  const std::string lz4 = error_of([&] { (void)read_all(vmap::test::ros1_test_bags() / "encodings_lz4.bag", {.topic = "/mono8/image_raw"}); });
  std::size_t plain = 0, db3 = 0;
  const std::string ok = error_of([&] {
    plain = read_all(vmap::test::ros1_test_bags() / "encodings_none.bag", {.topic = "/mono8/image_raw"}).frames.size();
    db3 = read_all(bags[0], {.topic = "/mono8/image_raw"}).frames.size();
  });
  vmap::detail::bag_component() = component;
  CHECK(mcap.find("(MCAP) needs the vmap::bags component") != std::string::npos);
  CHECK(mcap.find("link the CMake target vmap::bags") != std::string::npos);
  CHECK(lz4.find("(lz4) needs the vmap::bags component") != std::string::npos);
  CHECK(ok == "no error");
  CHECK(plain == 3);
  CHECK(db3 == 3);
}

TEST_CASE("a bag that is not a regular file or a folder is refused by name before it is opened (a FIFO never blocks)") {
  const auto dir = vmap::test::scratch_dir("bag_fifos");
  std::vector<fs::path> fifos;
  for (const char* name : {"f.bag", "f.mcap", "f.db3", "f"}) fifos.push_back(vmap::test::make_fifo(dir / name));
  // A rosbag2 folder whose metadata.yaml lists a FIFO beside a real file, and one whose
  // .db3 files (no metadata) include a FIFO.
  const auto listed = dir / "listed";
  const auto globbed = dir / "globbed";
  for (const auto& d : {listed, globbed}) {
    fs::create_directories(d);
    vmap::test::write_db3(d / "a.db3", ros2_messages());
    fifos.push_back(vmap::test::make_fifo(d / "b.db3"));
  }
  vmap::test::write_bytes(listed / "metadata.yaml",
                          "rosbag2_bagfile_information:\n  version: 5\n  storage_identifier: sqlite3\n"
                          "  relative_file_paths:\n    - a.db3\n    - b.db3\n");
  const vmap::test::FifoWatchdog watchdog(fifos, std::chrono::seconds(20));
  for (std::size_t k = 0; k < 4; ++k) {
    const fs::path& f = fifos[k];
    CAPTURE(f.string());
    const auto seen = vmap::test::error_seen([&] { (void)vmap::FrameSource::open(f); });
    CHECK(seen.message == "frame source: input '" + f.string() +
                              "' is not a regular file or a folder (a device, FIFO or socket cannot be read as one)");
    CHECK(seen.kind == vmap::ErrorKind::invalid_argument);
    CHECK(error_of([&] { (void)vmap::bag_info(f); }) ==
          "bag '" + f.string() + "' is not a regular file or a folder (a device, FIFO or socket cannot be read as one)");
  }
  for (const auto& d : {listed, globbed}) {
    CAPTURE(d.string());
    const std::string refused =
        "bag file '" + (d / "b.db3").string() + "' is not a regular file (a device, FIFO or socket cannot be read as one)";
    CHECK(error_of([&] { (void)vmap::bag_info(d); }) == refused);
    CHECK(error_of([&] { (void)vmap::FrameSource::open(d, {.topic = "/mono8/image_raw"}); }) == refused);
  }
}

TEST_CASE("rosbag2: a metadata.yaml that names one file twice is refused; a message over the limit is skipped unread") {
  const auto dir = vmap::test::scratch_dir("rosbag2_checks");
  const auto twice = dir / "twice";
  fs::create_directories(twice);
  vmap::test::write_db3(twice / "a.db3", ros2_messages());
  for (const std::string second : {"a.db3", "./a.db3"}) {
    vmap::test::write_bytes(twice / "metadata.yaml", "rosbag2_bagfile_information:\n  relative_file_paths:\n    - a.db3\n    - " +
                                                          second + "\n");
    const auto seen = vmap::test::error_seen([&] { (void)vmap::bag_info(twice); });
    CHECK(seen.kind == vmap::ErrorKind::corrupt);
    CHECK(seen.message == "bag '" + twice.string() + "' names the file '" + (twice / second).string() + "' twice" +
                              (second == "a.db3" ? std::string() : " (also as '" + (twice / "a.db3").string() + "')") +
                              "; each file of a bag is read once: list it once in metadata.yaml's relative_file_paths");
  }
  // The second message holds 2 MiB, over a limit of 1 MiB: skipped with a warning naming its
  // row; the first and the third are read.
  const std::string big(2 << 20, '\x07');
  vmap::test::write_db3(dir / "big.db3",
                        {{"/c/image_raw", "sensor_msgs/msg/Image", 1, vmap::test::cdr_image(1, 24, 20, "mono8", 24, std::string(480, 'a'))},
                         {"/c/image_raw", "sensor_msgs/msg/Image", 2, vmap::test::cdr_image(2, 2048, 1024, "mono8", 2048, big)},
                         {"/c/image_raw", "sensor_msgs/msg/Image", 3, vmap::test::cdr_image(3, 24, 20, "mono8", 24, std::string(480, 'c'))}});
  const vmap::BagLimits limits{.max_chunk_bytes = 1 << 20};
  auto s = vmap::detail::open_message_stream(dir / "big.db3", limits);
  const auto got = vmap::test::all_messages(*s);
  REQUIRE(got.size() == 2);
  CHECK(got[0].record_ns == 1);
  CHECK(got[1].record_ns == 3);
  const std::size_t bytes = vmap::test::cdr_image(2, 2048, 1024, "mono8", 2048, big).size();
  REQUIRE(s->warnings().size() == 1);
  CHECK(s->warnings()[0] == "bag '" + (dir / "big.db3").string() + "', row 2: a message of " + std::to_string(bytes) +
                                " bytes, more than the limit of 1048576 (BagLimits::max_chunk_bytes); skipped");
  const auto r = read_all(dir / "big.db3", {.bag_limits = limits});
  REQUIRE(r.frames.size() == 2);
  CHECK(r.frames[1].time_ns == 3);
  CHECK(r.warnings == s->warnings());
}

namespace {

/// The byte of the first top-level chunk of a bag (ROS 1 op 0x05, MCAP opcode 0x06).
std::size_t first_chunk_of(const std::string& bytes, vmap::BagFormat f) {
  for (std::size_t at : vmap::test::record_boundaries(bytes, f)) {
    if (at >= bytes.size()) break;
    if (f == vmap::BagFormat::ros1 ? ros1_op(bytes, ros1_record(bytes, at)) == 0x05 : bytes[at] == 0x06) return at;
  }
  FAIL("no chunk");
  return 0;
}

/// `bag` with its first chunk's stated uncompressed size set to `size`, written to `out`.
fs::path with_chunk_size(const fs::path& bag, vmap::BagFormat f, std::uint64_t size, const fs::path& out) {
  std::string bytes = vmap::test::read_bytes(bag);
  const std::size_t at = first_chunk_of(bytes, f);
  if (f == vmap::BagFormat::ros1) {
    put_u32(bytes, ros1_field(bytes, ros1_record(bytes, at), "size"), static_cast<std::uint32_t>(size));
  } else {  // MCAP chunk body: start time, end time (8 + 8), uncompressed size (8)
    for (int i = 0; i < 8; ++i) bytes[at + 9 + 16 + static_cast<std::size_t>(i)] = static_cast<char>((size >> (8 * i)) & 0xff);
  }
  vmap::test::write_bytes(out, bytes);
  return out;
}

/// The uncompressed size the first chunk of a bag states.
std::uint64_t chunk_size_of(const fs::path& bag, vmap::BagFormat f) {
  const std::string bytes = vmap::test::read_bytes(bag);
  const std::size_t at = first_chunk_of(bytes, f);
  if (f == vmap::BagFormat::ros1) return vmap::detail::le_u32(bytes.data() + ros1_field(bytes, ros1_record(bytes, at), "size"));
  return vmap::detail::le_u64(bytes.data() + at + 9 + 16);
}

}  // namespace

TEST_CASE("a chunk that states more bytes than its data holds costs what the data holds, and is skipped") {
  // Each codec's first chunk states 512 MiB (the limit) for the few kB its data gives:
  // the reader decompresses into a buffer that grows with the output, so the process's
  // peak memory does not rise by the 512 MiB stated (a buffer of that size filled with
  // zeros first did); the chunk is skipped with the size it gave, the others are read.
  const auto dir = vmap::test::scratch_dir("lying_chunks");
  const auto ros2 = ros2_test_bags("lying_chunks_ros2");
  struct Case {
    fs::path bag;
    vmap::BagFormat format;
    std::string codec;
  };
  const std::vector<Case> cases{{vmap::test::ros1_test_bags() / "encodings_lz4.bag", vmap::BagFormat::ros1, "lz4"},
                                {vmap::test::ros1_test_bags() / "encodings_bz2.bag", vmap::BagFormat::ros1, "bz2"},
                                {ros2[2], vmap::BagFormat::mcap, "lz4"},
                                {ros2[1], vmap::BagFormat::mcap, "zstd"}};
  const std::uint64_t claim = vmap::BagLimits{}.max_chunk_bytes;
  for (const auto& c : cases) {
    CAPTURE(c.bag.string());
    const auto full = vmap::test::all_messages(c.bag);
    const std::uint64_t real = chunk_size_of(c.bag, c.format);
    const std::string bytes = vmap::test::read_bytes(c.bag);
    const std::size_t at = first_chunk_of(bytes, c.format);
    std::size_t in_first = 0;
    for (const auto& m : full) in_first += m.offset == at ? 1 : 0;  // a chunk's messages carry its byte
    REQUIRE(in_first > 0);
    const auto lying = with_chunk_size(c.bag, c.format, claim, dir / ("lying" + c.bag.extension().string()));
    std::vector<vmap::test::ReadMessage> got;
    std::vector<std::string> warnings;
    const auto growth = vmap::test::peak_growth([&] {
      auto s = vmap::detail::open_message_stream(lying);
      got = vmap::test::all_messages(*s);
      warnings = s->warnings();
    });
    if (growth) CHECK(*growth < (std::uint64_t{64} << 20));
    CHECK(got.size() == full.size() - in_first);
    REQUIRE_FALSE(warnings.empty());
    CHECK(warnings[0] == "bag '" + lying.string() + "': chunk at byte " + std::to_string(at) + " does not decompress (" +
                             c.codec + ": it decompresses to " + std::to_string(real) + " bytes, its chunk states " +
                             std::to_string(claim) + "); skipped");
    // A chunk that states one byte less than it holds: the probe past the stated size
    // finds the byte more.
    const auto short_by_one = with_chunk_size(c.bag, c.format, real - 1, dir / ("short" + c.bag.extension().string()));
    auto s = vmap::detail::open_message_stream(short_by_one);
    CHECK(vmap::test::all_messages(*s).size() == full.size() - in_first);
    REQUIRE_FALSE(s->warnings().empty());
    CHECK(s->warnings()[0].find("(" + c.codec + ": it decompresses to more than the " + std::to_string(real - 1) +
                                " bytes its chunk states); skipped") != std::string::npos);
  }
}

TEST_CASE("chunks that decompress hundreds of times their size are read exact (the buffer grows as they decompress)") {
  // 320x240 frames of one value: each codec's chunk is a few hundred times smaller than
  // its 150 kB of records, past the reader's first guess of its size.
  const auto check = [](const fs::path& bag, const std::string& topic) {
    CAPTURE(bag.string());
    const auto r = read_all(bag, {.topic = topic});
    REQUIRE(r.frames.size() == 2);
    CHECK(r.warnings.empty());
    for (int k = 0; k < 2; ++k)
      CHECK(same_pixels(r.frames[static_cast<std::size_t>(k)].image, cv::Mat(240, 320, CV_8UC1, cv::Scalar(k + 1))));
  };
  for (const char* codec : {"bz2", "lz4"}) check(vmap::test::ros1_test_bags() / ("flat_" + std::string(codec) + ".bag"), "/cam/image_raw");
  const auto dir = vmap::test::scratch_dir("flat_mcap");
  std::vector<vmap::test::TestMessage> flat;
  for (int k = 0; k < 2; ++k)
    flat.push_back({"/cam/image_raw", "sensor_msgs/msg/Image", 5 + k,
                    vmap::test::cdr_image(5 + k, 320, 240, "mono8", 320, std::string(320 * 240, static_cast<char>(k + 1)))});
  for (const char* codec : {"lz4", "zstd"}) {
    vmap::test::write_mcap(dir / (std::string(codec) + ".mcap"), flat, codec, std::uint64_t{1} << 20);
    CHECK(fs::file_size(dir / (std::string(codec) + ".mcap")) < 40000);
    check(dir / (std::string(codec) + ".mcap"), "/cam/image_raw");
  }
}

TEST_CASE("a topic with messages of two types is refused, naming both; an empty or foreign .mcap is corrupt as a .bag is") {
  const auto dir = vmap::test::scratch_dir("two_types");
  const auto image = [](std::int64_t t) { return vmap::test::cdr_image(t, 24, 20, "mono8", 24, std::string(480, 'x')); };
  const std::vector<vmap::test::TestMessage> mixed{
      {"/cam/image_raw", "sensor_msgs/msg/Image", 1, image(1)},
      {"/cam/image_raw", "std_msgs/msg/String", 2, vmap::test::CdrWriter().string("hello").str()},
      {"/cam/image_raw", "sensor_msgs/msg/Image", 3, image(3)}};
  vmap::test::write_db3(dir / "mixed.db3", mixed);
  vmap::test::write_mcap(dir / "mixed.mcap", mixed, "zstd");
  for (const char* name : {"mixed.db3", "mixed.mcap"}) {
    const fs::path bag = dir / name;
    CAPTURE(bag.string());
    const std::string refused = "bag '" + bag.string() +
                                "': topic '/cam/image_raw' holds messages of more than one type: sensor_msgs/msg/Image "
                                "(2 messages), std_msgs/msg/String (1 message); vmap reads a topic of one type (the "
                                "others' messages would be dropped)";
    CHECK(error_of([&] { (void)vmap::FrameSource::open(bag); }) == refused);
    CHECK(error_of([&] { (void)vmap::FrameSource::open(bag, {.topic = "/cam/image_raw"}); }) == refused);
    CHECK(vmap::bag_info(bag).topics.size() == 2);  // listed, each type with its count
  }
  // Image and CompressedImage on one topic: the same refusal, not "2 image topics".
  vmap::test::write_db3(dir / "both.db3", {{"/cam/image_raw", "sensor_msgs/msg/Image", 1, image(1)},
                                           {"/cam/image_raw", "sensor_msgs/msg/CompressedImage", 2,
                                            vmap::test::cdr_compressed(2, "png", "x")}});
  CHECK(error_of([&] { (void)vmap::FrameSource::open(dir / "both.db3"); }).find("holds messages of more than one type") !=
        std::string::npos);
  // A file of 0 bytes with each bag's extension: the same kind (corrupt) for all three.
  for (const char* name : {"zero.bag", "zero.mcap", "zero.db3"}) {
    vmap::test::write_bytes(dir / name, "");
    CAPTURE(name);
    CHECK(vmap::test::error_seen([&] { (void)vmap::bag_info(dir / name); }).kind == vmap::ErrorKind::corrupt);
  }
}

TEST_CASE("an MCAP log time beyond the range of nanosecond times is skipped with a warning, never clamped") {
  const auto dir = vmap::test::scratch_dir("mcap_times");
  const auto image = [](std::int64_t t) { return vmap::test::cdr_image(t, 24, 20, "mono8", 24, std::string(480, 'x')); };
  // record_ns -1 is written as log time 2^64 - 1 (an unsigned field).
  vmap::test::write_mcap(dir / "late.mcap", {{"/cam/image_raw", "sensor_msgs/msg/Image", 1, image(1)},
                                             {"/cam/image_raw", "sensor_msgs/msg/Image", -1, image(2)},
                                             {"/cam/image_raw", "sensor_msgs/msg/Image", 3, image(3)}},
                         "");
  const auto info = vmap::bag_info(dir / "late.mcap");
  CHECK(info.end_ns == 3);
  CHECK(info.messages == 2);
  REQUIRE_FALSE(info.warnings.empty());
  CHECK(info.warnings[0].find("its statistics give a message time 18446744073.709551615 s, beyond the range of nanosecond "
                              "times (the year 2262); read through to list it") != std::string::npos);
  const auto r = read_all(dir / "late.mcap", {.record_time = true});
  REQUIRE(r.frames.size() == 2);
  CHECK(r.frames[1].time_ns == 3);
  REQUIRE_FALSE(r.warnings.empty());
  CHECK(r.warnings.back().find("has log time 18446744073.709551615 s, beyond the range of nanosecond times (the year 2262); skipped") !=
        std::string::npos);
}
