#pragma once

// What every bag container shares: the public description of a bag (BagInfo, BagTopic),
// its reading limits, and, in vmap::detail, the stream of serialized messages each
// container reader implements (ROS 1 bag 2.0: io/bag/ros1_bag.hpp; rosbag2 sqlite3:
// io/bag/rosbag2_sqlite.hpp; MCAP: the vmap::bags component, io/bag/component.cpp).
//
// Messages come in the order the bag holds them (ROS 1 chunks in file order, rosbag2 rows
// in insertion order, MCAP records in file order): the order they were recorded in.
// Readers read one chunk at a time; every size read from a file is checked against the
// file's size and BagLimits before anything is allocated.

#include <vmap/core/error.hpp>
#include <vmap/core/name_table.hpp>
#include <vmap/geometry/camera.hpp>

#include <cstdint>
#include <filesystem>
#include <memory>
#include <optional>
#include <string>
#include <string_view>
#include <utility>
#include <vector>

namespace vmap {

/// The container of a bag.
enum class BagFormat : std::uint8_t {
  ros1,            ///< ROS 1 bag format 2.0 (`.bag`)
  rosbag2_sqlite,  ///< ROS 2 rosbag2, sqlite3 storage (`.db3`, or its folder with metadata.yaml)
  mcap,            ///< MCAP (`.mcap`), ROS 2's default storage since Iron
};

/// The containers' names (core/names.hpp).
[[nodiscard]] constexpr auto names_of(BagFormat) noexcept {
  return detail::NameTable<BagFormat, 3>{{{{BagFormat::ros1, "ROS 1 bag 2.0"},
                                           {BagFormat::rosbag2_sqlite, "rosbag2 sqlite3"},
                                           {BagFormat::mcap, "MCAP"}}}};
}
[[nodiscard]] constexpr std::string_view to_string(BagFormat f) noexcept { return names_of(f).name(f); }

/// Bounds of what one read may allocate.
struct BagLimits {
  /// Largest chunk (after decompression), record or message held in memory at once. A
  /// ROS 1 or MCAP chunk, or a single message (a rosbag2 row's included, its length read
  /// before its bytes), that claims more is refused (the rest of the bag is read when its
  /// structure allows, see BagInfo::warnings). 512 MiB holds the largest frame
  /// FrameSourceOptions::max_pixels lets through (64 Mi pixels of 4 bytes) twice over.
  /// A compressed chunk costs what its data decompresses to, up to the size it states,
  /// never a buffer of the stated size up front.
  std::uint64_t max_chunk_bytes = std::uint64_t{512} << 20;
  /// Largest record header of a ROS 1 bag (connection headers carry the message
  /// definition, a few kB).
  std::uint64_t max_header_bytes = std::uint64_t{16} << 20;
};

/// One topic of a bag (connections or channels of the same topic and type joined).
struct BagTopic {
  std::string name;      ///< "/cam0/image_raw"
  std::string type;      ///< "sensor_msgs/Image" (ROS 1) or "sensor_msgs/msg/Image" (ROS 2)
  std::string encoding;  ///< serialization: "ros1" or "cdr"
  std::uint64_t messages = 0;
};

/// A calibration found in a bag and where it came from.
struct BagCamera {
  Camera camera;
  std::string topic;   ///< "/cam0/camera_info"
  std::string source;  ///< "bag 'x.bag', topic '/cam0/camera_info' (its first CameraInfo)"
};

/// A bag's CameraInfo topic as the source of a calibration ("x.bag:/cam0/camera_info"),
/// as PolicyStack::camera_source records it beside calibration files.
[[nodiscard]] inline std::string bag_camera_source(const std::filesystem::path& bag, std::string_view topic) {
  return bag.string() + ":" + std::string(topic);
}

/// The bag and topic of a source bag_camera_source wrote; nullopt for anything else (a
/// calibration file). A ROS topic name is '/' then letters, digits, '_', '~' and '/', never
/// ':', so the split is at the last ':' and a file name with a dot or a space after its
/// last ":/" is not taken for one.
[[nodiscard]] inline std::optional<std::pair<std::string, std::string>> parse_bag_camera_source(std::string_view source) {
  const auto colon = source.rfind(':');
  if (colon == std::string_view::npos || colon == 0 || colon + 2 > source.size() || source[colon + 1] != '/')
    return std::nullopt;
  const std::string_view topic = source.substr(colon + 1);
  for (const char c : topic)
    if (!(c == '/' || c == '_' || c == '~' || (c >= 'a' && c <= 'z') || (c >= 'A' && c <= 'Z') || (c >= '0' && c <= '9')))
      return std::nullopt;
  return std::pair{std::string(source.substr(0, colon)), std::string(topic)};
}

/// What a bag holds, from its index where it has one (else from reading it through).
struct BagInfo {
  std::filesystem::path path;
  BagFormat format = BagFormat::ros1;
  std::vector<BagTopic> topics;  ///< by name
  std::uint64_t messages = 0;    ///< every topic's
  /// Record times (ROS 1 record time, rosbag2 timestamp, MCAP log time) of the first and
  /// last message, in nanoseconds since the Unix epoch; 0 when the bag has no message.
  std::int64_t start_ns = 0;
  std::int64_t end_ns = 0;
  /// True when topics and counts come from the bag's index or summary; false when the
  /// bag had none (a recording cut short) and it was read through to count them.
  bool indexed = true;
  /// Damage found (a truncated file, a corrupt chunk), each naming where it is.
  std::vector<std::string> warnings;
};

namespace detail {

/// One connection (ROS 1), topic row (rosbag2) or channel (MCAP).
struct BagConnection {
  std::uint32_t id = 0;
  std::string topic;
  std::string type;
  std::string encoding;  ///< "ros1" or "cdr"
  std::uint64_t messages = 0;
};

/// A serialized message. `bytes` stays valid while `owner` (the chunk or row it lies in)
/// is held, so a claimed frame keeps its bytes without a copy.
struct StreamMessage {
  std::uint32_t connection = 0;
  std::int64_t record_ns = 0;  ///< record time (see BagInfo::start_ns)
  std::uint64_t offset = 0;    ///< where it lies: a byte offset of the file (rosbag2: the row id)
  std::string_view bytes;
  std::shared_ptr<const void> owner;
};

/// The messages of a bag, in order, one chunk in memory at a time. Not thread-safe.
class MessageStream {
 public:
  MessageStream() = default;
  MessageStream(const MessageStream&) = delete;
  MessageStream& operator=(const MessageStream&) = delete;
  virtual ~MessageStream() = default;

  /// The next message of a selected connection; false at the end of the bag or at damage
  /// that ends it (then recorded in warnings()).
  virtual bool next(StreamMessage& out) = 0;

  /// Only the messages of these connections are returned (all before the first call).
  void select(std::vector<std::uint32_t> ids) {
    selected_ = std::move(ids);
    select_all_ = false;
  }
  [[nodiscard]] const std::vector<BagConnection>& connections() const noexcept { return connections_; }
  [[nodiscard]] const std::vector<std::string>& warnings() const noexcept { return warnings_; }
  [[nodiscard]] BagFormat format() const noexcept { return format_; }
  [[nodiscard]] bool indexed() const noexcept { return indexed_; }
  [[nodiscard]] std::int64_t start_ns() const noexcept { return start_ns_; }
  [[nodiscard]] std::int64_t end_ns() const noexcept { return end_ns_; }

 protected:
  [[nodiscard]] bool wanted(std::uint32_t id) const noexcept {
    if (select_all_) return true;
    for (std::uint32_t s : selected_)
      if (s == id) return true;
    return false;
  }
  /// Widens [start_ns_, end_ns_] to `t` (while counting messages without an index).
  void saw_time(std::int64_t t) noexcept {
    if (!any_time_ || t < start_ns_) start_ns_ = t;
    if (!any_time_ || t > end_ns_) end_ns_ = t;
    any_time_ = true;
  }

  BagFormat format_ = BagFormat::ros1;
  std::vector<BagConnection> connections_;
  std::vector<std::string> warnings_;
  bool indexed_ = true;
  std::int64_t start_ns_ = 0, end_ns_ = 0;
  bool any_time_ = false;

 private:
  std::vector<std::uint32_t> selected_;
  bool select_all_ = true;
};

/// What the vmap::bags component (io/bag/component.cpp, linked through the CMake target
/// vmap::bags) provides: the decompressors of ROS 1 chunks and the MCAP reader, which
/// need liblz4, libzstd, libbz2 and the MCAP library's one implementation unit. The
/// headers reach them through this table, filled when the component's translation unit
/// is initialised, so that a program that reads no bag links none of those libraries.
struct BagComponent {
  /// Decompresses `in` into `out`, which must come to exactly `out_size` bytes (the size
  /// its chunk states); false and `reason` when the data is corrupt or decompresses to
  /// another size. `out` grows with what the data gives, never past `out_size`: a chunk
  /// that states more than its data holds costs what the data holds, not what it states.
  bool (*bz2)(std::string_view in, std::size_t out_size, std::string& out, std::string& reason) = nullptr;
  bool (*lz4_frame)(std::string_view in, std::size_t out_size, std::string& out, std::string& reason) = nullptr;
  /// An MCAP file's message stream.
  std::unique_ptr<MessageStream> (*open_mcap)(const std::filesystem::path& file, const BagLimits& limits) = nullptr;
};

/// The component's table, or null in a program built without it.
inline const BagComponent*& bag_component() noexcept {
  static const BagComponent* component = nullptr;
  return component;
}

/// The table, or an Error naming `what` needed it and how to get it.
inline const BagComponent& require_bag_component(const std::string& what) {
  const BagComponent* c = bag_component();
  if (c == nullptr)
    fail(what + " needs the vmap::bags component (MCAP, lz4 and bz2 readers), which this program was built "
                "without: link the CMake target vmap::bags (find_package(vmap COMPONENTS bags))");
  return *c;
}

}  // namespace detail
}  // namespace vmap
