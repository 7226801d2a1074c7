#pragma once

// rosbag2 sqlite3 bags for tests, written with the SQLite vmap links (no MCAP library):
// CDR messages (sensor_msgs Image, CompressedImage, CameraInfo) and the tables rosbag2
// writes. support/bags.hpp adds ROS 1 and MCAP bags for the bag readers' tests.

#include <vmap/io/sqlite.hpp>

#include <cstdint>
#include <cstring>
#include <filesystem>
#include <string>
#include <string_view>
#include <utility>
#include <vector>

namespace vmap::test {

/// A little-endian CDR message (encapsulation 00 01 00 00), fields aligned from its end.
class CdrWriter {
 public:
  CdrWriter() : b_("\x00\x01\x00\x00", 4) {}
  CdrWriter& u8(std::uint8_t v) {
    b_ += static_cast<char>(v);
    return *this;
  }
  CdrWriter& u32(std::uint32_t v) {
    align(4);
    for (int i = 0; i < 4; ++i) b_ += static_cast<char>((v >> (8 * i)) & 0xff);
    return *this;
  }
  CdrWriter& i32(std::int32_t v) { return u32(static_cast<std::uint32_t>(v)); }
  CdrWriter& f64(double d) {
    align(8);
    std::uint64_t v = 0;
    std::memcpy(&v, &d, sizeof v);
    for (int i = 0; i < 8; ++i) b_ += static_cast<char>((v >> (8 * i)) & 0xff);
    return *this;
  }
  CdrWriter& string(std::string_view s) {
    u32(static_cast<std::uint32_t>(s.size() + 1));
    b_ += s;
    b_ += '\0';
    return *this;
  }
  CdrWriter& bytes(std::string_view s) {
    u32(static_cast<std::uint32_t>(s.size()));
    b_ += s;
    return *this;
  }
  CdrWriter& header(std::int64_t stamp_ns, std::string_view frame = "cam") {
    return i32(static_cast<std::int32_t>(stamp_ns / 1000000000)).u32(static_cast<std::uint32_t>(stamp_ns % 1000000000)).string(frame);
  }
  [[nodiscard]] const std::string& str() const noexcept { return b_; }

 private:
  void align(std::size_t n) {
    while ((b_.size() - 4) % n != 0) b_ += '\0';
  }
  std::string b_;
};

/// A CDR sensor_msgs/msg/Image.
inline std::string cdr_image(std::int64_t stamp_ns, std::uint32_t w, std::uint32_t h, std::string_view encoding,
                             std::uint32_t step, std::string_view data, bool big_endian = false) {
  return CdrWriter().header(stamp_ns).u32(h).u32(w).string(encoding).u8(big_endian ? 1 : 0).u32(step).bytes(data).str();
}

/// A CDR sensor_msgs/msg/CompressedImage.
inline std::string cdr_compressed(std::int64_t stamp_ns, std::string_view format, std::string_view data) {
  return CdrWriter().header(stamp_ns).string(format).bytes(data).str();
}

/// A CDR sensor_msgs/msg/CameraInfo (K, D and the model; R, P, binning, ROI zero).
inline std::string cdr_camera_info(std::int64_t stamp_ns, std::uint32_t w, std::uint32_t h, std::string_view model,
                                   const std::vector<double>& d, const std::vector<double>& k) {
  CdrWriter c;
  c.header(stamp_ns).u32(h).u32(w).string(model).u32(static_cast<std::uint32_t>(d.size()));
  for (double v : d) c.f64(v);
  for (double v : k) c.f64(v);
  for (int i = 0; i < 9 + 12; ++i) c.f64(i % 4 == 0 ? 1.0 : 0.0);
  c.u32(0).u32(0).u32(0).u32(0).u32(0).u32(0).u8(0);
  return c.str();
}

struct TestMessage {
  std::string topic, type;
  std::int64_t record_ns = 0;
  std::string data;
};

/// A rosbag2 sqlite3 file with the schema rosbag2 writes (schema version 3).
inline void write_db3(const std::filesystem::path& file, const std::vector<TestMessage>& messages) {
  std::filesystem::remove(file);
  sqlite::Database db(file, sqlite::Access::create, "test bag");
  db.exec("PRAGMA journal_mode=DELETE", "journal");
  db.exec(
      "CREATE TABLE schema(schema_version INTEGER PRIMARY KEY, ros_distro TEXT NOT NULL);"
      "INSERT INTO schema VALUES (3, 'humble');"
      "CREATE TABLE topics(id INTEGER PRIMARY KEY, name TEXT NOT NULL, type TEXT NOT NULL, serialization_format TEXT "
      "NOT NULL, offered_qos_profiles TEXT NOT NULL);"
      "CREATE TABLE messages(id INTEGER PRIMARY KEY, topic_id INTEGER NOT NULL, timestamp INTEGER NOT NULL, data BLOB "
      "NOT NULL);"
      "CREATE INDEX timestamp_idx ON messages (timestamp ASC);",
      "create tables");
  std::vector<std::pair<std::string, std::string>> topics;  // a topic row per name and type
  auto add_topic = db.prepare("INSERT INTO topics VALUES (?, ?, ?, 'cdr', '')", "topic");
  auto add = db.prepare("INSERT INTO messages(topic_id, timestamp, data) VALUES (?, ?, ?)", "message");
  for (const auto& m : messages) {
    std::size_t id = 0;
    while (id < topics.size() && topics[id] != std::pair{m.topic, m.type}) ++id;
    if (id == topics.size()) {
      topics.emplace_back(m.topic, m.type);
      add_topic.bind(1, static_cast<std::int64_t>(id + 1)).bind_text(2, m.topic).bind_text(3, m.type).run();
    }
    add.bind(1, static_cast<std::int64_t>(id + 1)).bind(2, m.record_ns).bind_blob(3, m.data).run();
  }
}

}  // namespace vmap::test
