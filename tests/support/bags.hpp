#pragma once

// Bags for the bag readers' tests: ROS 1 bags written by Debian's rosbag writer
// (tests/support/write_ros1_bags.py), rosbag2 sqlite3 bags (support/ros2_bags.hpp) and
// MCAP bags written here (the MCAP library's writer, which the vmap::bags component links),
// the top-level record offsets of each container (to cut a bag at every record
// boundary), and the messages of a bag as a list to compare.

#include "support/errors.hpp"
#include "support/ros2_bags.hpp"
#include "support/shared_data.hpp"

#include <vmap/io/bag/bag.hpp>
#include <vmap/io/sqlite.hpp>

#include <opencv2/core.hpp>

#include <mcap/writer.hpp>

#include <unistd.h>

#include <doctest/doctest.h>

#include <cstdint>
#include <cstdlib>
#include <cstring>
#include <filesystem>
#include <map>
#include <string>
#include <string_view>
#include <vector>

namespace vmap::test {

/// Two images with the same size, type and pixels.
inline bool same_pixels(const cv::Mat& a, const cv::Mat& b) {
  return a.size() == b.size() && a.type() == b.type() && cv::norm(a, b, cv::NORM_INF) == 0;
}

/// The folder of the ROS 1 test bags, written once per test run by Debian's rosbag.
inline const std::filesystem::path& ros1_test_bags() {
  static const std::filesystem::path dir = [] {
    // One folder per process: the "data" suite runs beside the others under CTest.
    const auto d = scratch_dir("ros1_bags_" + std::to_string(::getpid()));
    const std::string cmd = "/usr/bin/python3 '" + (source_dir() / "tests/support/write_ros1_bags.py").string() + "' '" +
                            d.string() + "'";
    REQUIRE_MESSAGE(std::system(cmd.c_str()) == 0,
                    "writing the ROS 1 test bags needs Debian's python3-rosbag and python3-sensor-msgs (bash .ci/install-deps)");
    return d;
  }();
  return dir;
}

/// An MCAP file (ROS 2 profile, CDR) written by the MCAP library; `compression` "",
/// "lz4" or "zstd"; `chunk_size` the writer's chunk threshold.
inline void write_mcap(const std::filesystem::path& file, const std::vector<TestMessage>& messages,
                       const std::string& compression = "zstd", std::uint64_t chunk_size = 4096) {
  mcap::McapWriter writer;
  mcap::McapWriterOptions o("ros2");
  o.compression = compression == "lz4"    ? mcap::Compression::Lz4
                  : compression == "zstd" ? mcap::Compression::Zstd
                                          : mcap::Compression::None;
  o.chunkSize = chunk_size;
  REQUIRE(writer.open(file.string(), o).ok());
  std::vector<std::pair<std::string, mcap::ChannelId>> channels;  // a channel per topic and type
  for (const auto& m : messages) {
    mcap::ChannelId id = 0;
    bool found = false;
    for (const auto& [t, c] : channels)
      if (t == m.topic + '\n' + m.type) id = c, found = true;
    if (!found) {
      mcap::Schema schema(m.type, "ros2msg", std::string("# test"));
      writer.addSchema(schema);
      mcap::Channel channel(m.topic, "cdr", schema.id);
      writer.addChannel(channel);
      id = channel.id;
      channels.emplace_back(m.topic + '\n' + m.type, id);
    }
    mcap::Message msg;
    msg.channelId = id;
    msg.logTime = static_cast<mcap::Timestamp>(m.record_ns);
    msg.publishTime = msg.logTime;
    msg.data = reinterpret_cast<const std::byte*>(m.data.data());
    msg.dataSize = m.data.size();
    REQUIRE(writer.write(msg).ok());
  }
  writer.close();
}

/// Start offsets of a bag's top-level records (ROS 1: after the magic; MCAP: after
/// the magic, up to the closing magic), and the file's size at the end.
inline std::vector<std::uint64_t> record_boundaries(const std::string& bytes, BagFormat format) {
  std::vector<std::uint64_t> out;
  const auto le32 = [&](std::size_t at) { return static_cast<std::uint64_t>(detail::le_u32(bytes.data() + at)); };
  if (format == BagFormat::ros1) {
    std::size_t pos = 13;
    while (pos + 8 <= bytes.size()) {
      out.push_back(pos);
      const std::uint64_t hl = le32(pos);
      const std::uint64_t dl = le32(pos + 4 + hl);
      pos += 8 + hl + dl;
    }
  } else {
    std::size_t pos = 8;
    while (pos + 9 <= bytes.size()) {
      out.push_back(pos);
      pos += 9 + detail::le_u64(bytes.data() + pos + 1);
    }
  }
  out.push_back(bytes.size());
  return out;
}

/// Every message of a bag (all topics), as (connection topic, record time, bytes).
struct ReadMessage {
  std::string topic;
  std::int64_t record_ns = 0;
  std::uint64_t offset = 0;
  std::string bytes;
  bool operator==(const ReadMessage&) const = default;
};

inline std::vector<ReadMessage> all_messages(detail::MessageStream& s) {
  std::vector<ReadMessage> out;
  detail::StreamMessage m;
  while (s.next(m)) {
    std::string topic;
    for (const auto& c : s.connections())
      if (c.id == m.connection) topic = c.topic;
    out.push_back({topic, m.record_ns, m.offset, std::string(m.bytes)});
  }
  return out;
}

inline std::vector<ReadMessage> all_messages(const std::filesystem::path& bag, const BagLimits& limits = {}) {
  auto s = detail::open_message_stream(bag, limits);
  return all_messages(*s);
}

/// Cutting `bag` at every record boundary: no crash, only vmap::Error, and exactly the
/// messages of the records that end before the cut (the same bytes, in order).
inline void check_cuts(const std::filesystem::path& bag, BagFormat format, const std::string& scratch_name) {
  const auto dir = scratch_dir(scratch_name);
  const auto bytes = read_bytes(bag);
  const auto full = all_messages(bag);
  const auto bounds = record_boundaries(bytes, format);
  std::map<std::uint64_t, std::uint64_t> record_end;  // record start -> end
  for (std::size_t i = 0; i + 1 < bounds.size(); ++i) record_end[bounds[i]] = bounds[i + 1];
  const auto cut_file = dir / ("cut" + bag.extension().string());
  std::size_t errors = 0;
  for (std::uint64_t cut : bounds) {
    if (cut == bytes.size()) continue;
    CAPTURE(cut);
    write_bytes(cut_file, std::string_view(bytes).substr(0, cut));
    std::vector<ReadMessage> got;
    const std::string e = error_of([&] { got = all_messages(cut_file); });
    if (e != "no error") {
      ++errors;
      continue;
    }
    std::size_t expected = 0;
    for (const auto& m : full) expected += record_end.at(m.offset) <= cut ? 1 : 0;
    REQUIRE(got.size() == expected);
    for (std::size_t i = 0; i < got.size(); ++i) CHECK(got[i] == full[i]);
    // The reader says where the file ends.
    if (expected > 0 && cut > 8) {
      auto s = detail::open_message_stream(cut_file);
      (void)all_messages(*s);
      REQUIRE_FALSE(s->warnings().empty());
    }
  }
  // Only a cut inside the first records (magic, bag header) may refuse the file.
  CHECK(errors <= 2);
}

}  // namespace vmap::test
