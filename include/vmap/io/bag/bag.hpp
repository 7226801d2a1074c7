#pragma once

// Robot bags as a source of camera frames (read by io/frame_source.hpp): ROS 1 bags
// (format 2.0, `.bag`), ROS 2 rosbag2 sqlite3 (`.db3` or its folder) and MCAP (`.mcap`,
// or a rosbag2 folder holding one). What a bag holds: `bag_info`. The calibration a
// `sensor_msgs/CameraInfo` topic beside an image topic states: `bag_camera`.
//
// ROS 1 bags without compressed chunks and rosbag2 sqlite3 bags are read by these
// headers alone; lz4 and bz2 chunks and MCAP files need the vmap::bags component
// (CMake target vmap::bags, io/bag/component.cpp), and without it opening one is a
// vmap::Error that says so.
//
// Topic choice (`topic`, empty: automatic): a bag with one image topic (sensor_msgs/Image
// or sensor_msgs/CompressedImage) needs none; with several and none given, the Error
// lists them with their types and message counts.
//
// Calibration: the CameraInfo topic beside image topic `/ns/image_raw` (or
// `/ns/image_raw/compressed`) is `/ns/camera_info`, as ROS camera drivers publish it; its
// first message gives a vmap::Camera (plumb_bob, rational_polynomial, equidistant).

#include <vmap/core/error.hpp>
#include <vmap/geometry/camera.hpp>
#include <vmap/io/bag/messages.hpp>
#include <vmap/io/bag/ros1_bag.hpp>
#include <vmap/io/bag/rosbag2_sqlite.hpp>
#include <vmap/io/bag/types.hpp>
#include <vmap/io/files.hpp>

#include <algorithm>
#include <cstdint>
#include <filesystem>
#include <fstream>
#include <map>
#include <memory>
#include <optional>
#include <string>
#include <string_view>
#include <utility>
#include <vector>

namespace vmap {

namespace detail {

inline constexpr std::string_view mcap_magic{"\x89MCAP0\r\n", 8};

/// The .mcap file of a rosbag2 folder (Iron and later record MCAP by default).
inline std::filesystem::path mcap_of_folder(const std::filesystem::path& folder) {
  std::vector<std::string> names;
  std::error_code ec;
  for (std::filesystem::directory_iterator it(folder, ec), end; !ec && it != end; it.increment(ec))
    if (it->path().extension() == ".mcap") names.push_back(it->path().filename().string());
  std::sort(names.begin(), names.end(), natural_less);
  if (names.empty()) fail("bag '" + folder.string() + "': the folder holds no .mcap file");
  if (names.size() > 1) {
    std::string list;
    for (const auto& n : names) list += (list.empty() ? "" : ", ") + n;
    fail("bag '" + folder.string() + "' is split into " + std::to_string(names.size()) + " MCAP files (" + list +
         "); give one of them");
  }
  return folder / names.front();
}

}  // namespace detail

/// The container of `input` when it is a bag (by its first bytes, else its extension;
/// a folder by its metadata.yaml or its .db3 / .mcap files), or nullopt.
[[nodiscard]] inline std::optional<BagFormat> bag_format(const std::filesystem::path& input) {
  std::error_code ec;
  if (std::filesystem::is_directory(input, ec)) {
    bool db3 = false, mcap = false;
    for (std::filesystem::directory_iterator it(input, ec), end; !ec && it != end; it.increment(ec)) {
      db3 = db3 || it->path().extension() == ".db3";
      mcap = mcap || it->path().extension() == ".mcap";
    }
    if (std::filesystem::is_regular_file(input / "metadata.yaml", ec) || db3 || mcap)
      return mcap && !db3 ? BagFormat::mcap : BagFormat::rosbag2_sqlite;
    return std::nullopt;
  }
  if (!std::filesystem::is_regular_file(input, ec)) return std::nullopt;
  char head[16] = {};
  std::ifstream in(input, std::ios::binary);
  in.read(head, sizeof head);
  const std::string_view h(head, static_cast<std::size_t>(in.gcount()));
  if (h.substr(0, 9) == "#ROSBAG V") return BagFormat::ros1;
  if (h.substr(0, 8) == detail::mcap_magic) return BagFormat::mcap;
  const std::string ext = input.extension().string();
  if (ext == ".db3") return BagFormat::rosbag2_sqlite;  // an SQLite file, checked when opened
  if (ext == ".bag") return BagFormat::ros1;
  if (ext == ".mcap") return BagFormat::mcap;
  return std::nullopt;
}

/// True when `input` is a bag (bag_format).
[[nodiscard]] inline bool is_bag(const std::filesystem::path& input) { return bag_format(input).has_value(); }

namespace detail {

/// The message stream of the bag `input`. Errors: not a bag of its format, unreadable,
/// an MCAP file without the vmap::bags component.
inline std::unique_ptr<MessageStream> open_message_stream(const std::filesystem::path& input, const BagLimits& limits = {}) {
  (void)require_file_or_folder(input, "bag");
  const auto format = bag_format(input);
  if (!format) fail("'" + input.string() + "' is not a bag (.bag, .db3, .mcap or a rosbag2 folder)");
  switch (*format) {
    case BagFormat::ros1:
      return std::make_unique<Ros1Bag>(input, limits);
    case BagFormat::rosbag2_sqlite: {
      std::error_code ec;
      if (!std::filesystem::is_directory(input, ec)) {
        char head[16] = {};
        std::ifstream in(input, std::ios::binary);
        in.read(head, sizeof head);
        if (in.gcount() != 16 || std::string_view(head, 16) != std::string_view("SQLite format 3\0", 16))
          fail(ErrorKind::corrupt, "bag '" + input.string() + "' is not a rosbag2 sqlite3 file: it does not start with \"SQLite format 3\"");
      }
      return std::make_unique<Rosbag2Sqlite>(input, limits);
    }
    case BagFormat::mcap: {
      std::error_code ec;
      const auto file = std::filesystem::is_directory(input, ec) ? mcap_of_folder(input) : input;
      return require_bag_component("bag '" + file.string() + "' (MCAP)").open_mcap(file, limits);
    }
  }
  fail("'" + input.string() + "': unknown bag format");
}

/// Topics joined by name and type, sorted by name.
inline std::vector<BagTopic> bag_topics(const MessageStream& s) {
  std::map<std::pair<std::string, std::string>, BagTopic> joined;
  for (const auto& c : s.connections()) {
    BagTopic& t = joined[{c.topic, c.type}];
    t.name = c.topic;
    t.type = c.type;
    t.encoding = c.encoding;
    t.messages += c.messages;
  }
  std::vector<BagTopic> out;
  for (auto& [key, t] : joined) out.push_back(std::move(t));
  return out;
}

/// "/a (sensor_msgs/Image, 60 messages), /b (...)".
inline std::string describe_topics(const std::vector<BagTopic>& topics) {
  std::string out;
  for (const auto& t : topics)
    out += (out.empty() ? "" : ", ") + t.name + " (" + t.type + ", " + std::to_string(t.messages) +
           (t.messages == 1 ? " message)" : " messages)");
  return out.empty() ? "none" : out;
}

inline bool is_image_type(std::string_view type) {
  const auto k = ros_message_kind(type);
  return k == RosMessageKind::image || k == RosMessageKind::compressed_image;
}

/// Fails when the topic `chosen` also carries messages of another type (ROS 1 allows a
/// topic's connections to differ): reading one type would drop the others' messages
/// without a word.
inline const BagTopic& single_type(const std::vector<BagTopic>& topics, const BagTopic& chosen, const std::string& what) {
  std::string others;
  for (const auto& t : topics)
    if (t.name == chosen.name && t.type != chosen.type)
      others += ", " + t.type + " (" + std::to_string(t.messages) + (t.messages == 1 ? " message)" : " messages)");
  if (!others.empty())
    fail(what + ": topic '" + chosen.name + "' holds messages of more than one type: " + chosen.type + " (" +
         std::to_string(chosen.messages) + (chosen.messages == 1 ? " message)" : " messages)") + others +
         "; vmap reads a topic of one type (the others' messages would be dropped)");
  return chosen;
}

/// The image topic to read: `wanted`, or the only image topic; an Error otherwise that
/// lists the topics, or when the topic holds messages of several types.
inline BagTopic choose_image_topic(const std::vector<BagTopic>& topics, const std::string& wanted,
                                   const std::string& what) {
  std::vector<BagTopic> images;
  for (const auto& t : topics)
    if (is_image_type(t.type)) images.push_back(t);
  if (!wanted.empty()) {
    for (const auto& t : topics)
      if (t.name == wanted && is_image_type(t.type)) return single_type(topics, t, what);
    for (const auto& t : topics)
      if (t.name == wanted)
        fail(what + ": topic '" + wanted + "' holds " + t.type +
             ", not images (sensor_msgs/Image or sensor_msgs/CompressedImage); its image topics: " + describe_topics(images));
    fail(what + " has no topic '" + wanted + "'; its topics: " + describe_topics(topics));
  }
  // One image topic (or one topic with two image types, refused by single_type).
  if (!images.empty() && std::all_of(images.begin(), images.end(), [&](const BagTopic& t) { return t.name == images.front().name; }))
    return single_type(topics, images.front(), what);
  if (images.empty())
    fail(what + " has no image topic (sensor_msgs/Image or sensor_msgs/CompressedImage); its topics: " +
         describe_topics(topics));
  fail(what + " has " + std::to_string(images.size()) +
       " image topics: choose one (--topic on the command line, FrameSourceOptions::topic, topic= in Python): " +
       describe_topics(images));
}

/// `/ns/camera_info` for `/ns/image_raw` or `/ns/image_raw/compressed`.
inline std::string camera_info_topic_for(std::string image_topic) {
  const std::string compressed = "/compressed";
  if (image_topic.size() > compressed.size() &&
      image_topic.compare(image_topic.size() - compressed.size(), compressed.size(), compressed) == 0)
    image_topic.resize(image_topic.size() - compressed.size());
  const auto slash = image_topic.rfind('/');
  return (slash == std::string::npos ? std::string() : image_topic.substr(0, slash)) + "/camera_info";
}

/// The connections of `topic` with image messages.
inline std::vector<std::uint32_t> image_connections(const MessageStream& s, const BagTopic& topic) {
  std::vector<std::uint32_t> ids;
  for (const auto& c : s.connections())
    if (c.topic == topic.name && c.type == topic.type) ids.push_back(c.id);
  return ids;
}

/// "bag 'x', topic '/t', message in the chunk at byte N" (MCAP: the chunk or message
/// record; rosbag2: "row N").
inline std::string message_where(const std::string& bag_what, BagFormat f, const std::string& topic, std::uint64_t offset) {
  return bag_what + ", topic '" + topic + "', message " +
         (f == BagFormat::rosbag2_sqlite ? "row " : f == BagFormat::ros1 ? "in the chunk at byte " : "in the record at byte ") +
         std::to_string(offset);
}

/// The first CameraInfo on `info_topic`, as a Camera; nullopt with `note` saying why not.
inline std::optional<BagCamera> read_bag_camera(const std::filesystem::path& input, const std::vector<BagTopic>& topics,
                                                const std::string& info_topic, const BagLimits& limits, std::string& note) {
  const auto it = std::find_if(topics.begin(), topics.end(), [&](const BagTopic& t) {
    return t.name == info_topic && ros_message_kind(t.type) == RosMessageKind::camera_info;
  });
  if (it == topics.end()) return std::nullopt;
  const std::string what = "bag '" + input.string() + "', topic '" + info_topic + "'";
  auto stream = open_message_stream(input, limits);
  std::vector<std::uint32_t> ids;
  for (const auto& c : stream->connections())
    if (c.topic == info_topic && c.type == it->type) ids.push_back(c.id);
  stream->select(ids);
  StreamMessage m;
  if (!stream->next(m)) {
    note = what + " holds no readable CameraInfo message";
    return std::nullopt;
  }
  std::string reason;
  std::optional<Camera> camera;
  try {
    const auto info = with_message_reader(it->encoding, m.bytes, what,
                                          [](auto& r, bool ros1) { return read_camera_info_message(r, ros1); });
    camera = camera_from_info(info, what, reason);
  } catch (const Error& e) {
    reason = e.what();
  }
  if (!camera) {
    note = what + " gives no calibration: " + reason;
    return std::nullopt;
  }
  return BagCamera{*camera, info_topic, what + " (its first CameraInfo)"};
}

}  // namespace detail

/// What the bag `input` holds: its topics with types and message counts, and the time
/// range of its messages. Errors: not a bag, unreadable, damaged beyond its first records.
[[nodiscard]] inline BagInfo bag_info(const std::filesystem::path& input, const BagLimits& limits = {}) {
  const auto stream = detail::open_message_stream(input, limits);
  BagInfo info;
  info.path = input;
  info.format = stream->format();
  info.topics = detail::bag_topics(*stream);
  for (const auto& t : info.topics) info.messages += t.messages;
  info.start_ns = stream->start_ns();
  info.end_ns = stream->end_ns();
  info.indexed = stream->indexed();
  info.warnings = stream->warnings();
  return info;
}

/// The calibration of the CameraInfo topic beside `image_topic` (empty: the bag's only
/// image topic), or nullopt when there is none; `note` says why a CameraInfo topic that
/// exists gives none.
[[nodiscard]] inline std::optional<BagCamera> bag_camera(const std::filesystem::path& input,
                                                         const std::string& image_topic = {},
                                                         std::string* note = nullptr, const BagLimits& limits = {}) {
  const auto stream = detail::open_message_stream(input, limits);
  const auto topics = detail::bag_topics(*stream);
  const BagTopic chosen = detail::choose_image_topic(topics, image_topic, "bag '" + input.string() + "'");
  std::string why;
  auto camera = detail::read_bag_camera(input, topics, detail::camera_info_topic_for(chosen.name), limits, why);
  if (note) *note = why;
  return camera;
}

}  // namespace vmap
