#pragma once

// A reader of ROS 1 bags, format 2.0 (wiki.ros.org/Bags/Format/2.0), over the bag file
// itself: a reader of our own rather than Debian's rosbag_storage, so that it streams
// one chunk at a time, checks every length against the file and BagLimits before it
// allocates, reads on past a corrupt chunk, and needs no ROS installation.
//
// Layout: the magic "#ROSBAG V2.0\n", then records, each `uint32 header_len, header,
// uint32 data_len, data`, the header a list of `uint32 len, name=value` fields whose
// `op` says what the record is: 0x03 bag header (index_pos, conn_count, chunk_count;
// padded to 4096 bytes), 0x05 chunk (compression none|bz2|lz4, size: the uncompressed
// size; data: connection and message records), 0x04 index data (after each chunk),
// 0x07 connection (conn, topic; data: a header of type, md5sum, message_definition, ...),
// 0x02 message data (conn, time: uint32 sec, uint32 nsec) and, from index_pos on, the
// connections and 0x06 chunk infos (chunk_pos, start_time, end_time, count; data: count
// pairs of uint32 conn, uint32 messages). lz4 chunks are LZ4 frames (roslz4).
//
// Topics and counts come from the index at index_pos; a bag without one (index_pos 0:
// recording was cut short) or whose index lies past the end of the file (truncated) is
// read through once to find them. Damage ends the bag with a warning naming the byte,
// except a chunk that does not decompress or whose records do not fit it, which is
// skipped with a warning (the records after it are still in place).

#include <vmap/core/error.hpp>
#include <vmap/io/bag/detail/file.hpp>
#include <vmap/io/bag/types.hpp>

#include <algorithm>
#include <cstdint>
#include <filesystem>
#include <map>
#include <memory>
#include <new>
#include <optional>
#include <string>
#include <string_view>
#include <vector>

namespace vmap::detail {

inline constexpr std::string_view ros1_bag_magic = "#ROSBAG V2.0\n";

/// The fields of a ROS 1 record header that the reader uses.
struct Ros1Header {
  int op = -1;
  std::optional<std::uint32_t> conn, size, count, conn_count, chunk_count;
  std::optional<std::uint64_t> time, index_pos, chunk_pos, start_time, end_time;
  std::string compression, topic, type;
};

/// ROS 1 `time` (uint32 sec, uint32 nsec) in nanoseconds.
inline std::int64_t ros1_time_ns(std::uint64_t packed) noexcept {
  return static_cast<std::int64_t>(packed & 0xffffffffu) * 1000000000 + static_cast<std::int64_t>(packed >> 32);
}

/// Parses `name=value` fields; false with `why` when a length runs past the header or a
/// field has no '=' or a numeric field has the wrong size.
inline bool parse_ros1_header(std::string_view h, Ros1Header& out, std::string& why) {
  std::size_t i = 0;
  while (i < h.size()) {
    if (h.size() - i < 4) {
      why = "a field length is cut at header byte " + std::to_string(i);
      return false;
    }
    const std::uint32_t n = le_u32(h.data() + i);
    i += 4;
    if (n > h.size() - i) {
      why = "a field at header byte " + std::to_string(i - 4) + " claims " + std::to_string(n) + " bytes, the header has " +
            std::to_string(h.size() - i) + " left";
      return false;
    }
    const std::string_view field = h.substr(i, n);
    i += n;
    const std::size_t eq = field.find('=');
    if (eq == std::string_view::npos) {
      why = "a header field has no '='";
      return false;
    }
    const std::string_view name = field.substr(0, eq), value = field.substr(eq + 1);
    const auto u32 = [&](std::optional<std::uint32_t>& dst) {
      if (value.size() != 4) return false;
      dst = le_u32(value.data());
      return true;
    };
    const auto u64 = [&](std::optional<std::uint64_t>& dst) {
      if (value.size() != 8) return false;
      dst = le_u64(value.data());
      return true;
    };
    bool ok = true;
    if (name == "op") {
      ok = value.size() == 1;
      if (ok) out.op = static_cast<unsigned char>(value[0]);
    } else if (name == "conn") {
      ok = u32(out.conn);
    } else if (name == "size") {
      ok = u32(out.size);
    } else if (name == "count") {
      ok = u32(out.count);
    } else if (name == "conn_count") {
      ok = u32(out.conn_count);
    } else if (name == "chunk_count") {
      ok = u32(out.chunk_count);
    } else if (name == "time") {
      ok = u64(out.time);
    } else if (name == "index_pos") {
      ok = u64(out.index_pos);
    } else if (name == "chunk_pos") {
      ok = u64(out.chunk_pos);
    } else if (name == "start_time") {
      ok = u64(out.start_time);
    } else if (name == "end_time") {
      ok = u64(out.end_time);
    } else if (name == "compression") {
      out.compression = value;
    } else if (name == "topic") {
      out.topic = value;
    } else if (name == "type") {
      out.type = value;
    }
    if (!ok) {
      why = "header field '" + std::string(name) + "' has " + std::to_string(value.size()) + " bytes";
      return false;
    }
  }
  return true;
}

class Ros1Bag final : public MessageStream {
 public:
  Ros1Bag(const std::filesystem::path& path, const BagLimits& limits)
      : file_(path, "bag '" + path.string() + "'"), limits_(limits) {
    format_ = BagFormat::ros1;
    const std::string& what = file_.what();
    char magic[13];
    if (file_.size() < ros1_bag_magic.size() || !file_.read(0, magic, sizeof magic) ||
        std::string_view(magic, sizeof magic) != ros1_bag_magic)
      fail(ErrorKind::corrupt, what + " is not a ROS 1 bag of format 2.0: it does not start with \"#ROSBAG V2.0\"");
    Record bag_header;
    std::string why;
    if (!read_record(ros1_bag_magic.size(), bag_header, why) || bag_header.head.op != 0x03)
      fail(ErrorKind::corrupt, what + ": no bag header record at byte 13" + (why.empty() ? std::string() : ": " + why));
    data_start_ = bag_header.end;
    data_end_ = file_.size();
    const std::uint64_t index_pos = bag_header.head.index_pos.value_or(0);
    bool have_index = false;
    if (index_pos == 0) {
      warnings_.push_back(what + " has no index (index_pos 0: its recording was not closed); read through to list it");
    } else if (index_pos < data_start_ || index_pos > file_.size()) {
      warnings_.push_back(what + ": its index at byte " + std::to_string(index_pos) + " lies outside the file (" +
                          std::to_string(file_.size()) + " bytes): the file is truncated; read through to list it");
    } else {
      have_index = read_index(index_pos, bag_header.head);
      if (have_index) data_end_ = index_pos;
    }
    if (!have_index) scan();
    std::sort(connections_.begin(), connections_.end(), [](const auto& a, const auto& b) { return a.id < b.id; });
    rewind();
  }

  bool next(StreamMessage& out) override {
    Item item;
    while (advance(item)) {
      if (item.head.op != 0x02 || !item.head.conn || !wanted(*item.head.conn)) continue;
      out.connection = *item.head.conn;
      out.record_ns = ros1_time_ns(item.head.time.value_or(0));
      out.offset = item.offset;
      out.bytes = item.data;
      out.owner = item.owner;
      return true;
    }
    return false;
  }

 private:
  struct Record {
    Ros1Header head;
    std::uint64_t data_offset = 0;
    std::uint32_t data_len = 0;
    std::uint64_t end = 0;
  };
  /// A message or connection record, from a chunk or the top level.
  struct Item {
    Ros1Header head;
    std::string_view data;
    std::shared_ptr<const void> owner;
    std::uint64_t offset = 0;  ///< the file offset of its chunk (or of itself)
  };

  /// The record at `pos` of the file (its header parsed, its data not read); false and
  /// `why` when it does not fit the file or its header is malformed.
  bool read_record(std::uint64_t pos, Record& r, std::string& why) const {
    const std::uint64_t size = file_.size();
    char len[4];
    if (pos > size || size - pos < 8 || !file_.read(pos, len, 4)) {
      why = "the file ends at byte " + std::to_string(size) + ", inside a record's header length";
      return false;
    }
    const std::uint32_t hl = le_u32(len);
    if (hl > limits_.max_header_bytes) {
      why = "a record header claims " + std::to_string(hl) + " bytes, more than the limit of " +
            std::to_string(limits_.max_header_bytes) + " (BagLimits::max_header_bytes)";
      return false;
    }
    if (size - pos - 8 < hl) {
      why = "a record header of " + std::to_string(hl) + " bytes runs past the end of the file (" + std::to_string(size) +
            " bytes)";
      return false;
    }
    std::string header(hl + std::size_t{4}, '\0');
    if (!file_.read(pos + 4, header.data(), header.size())) {
      why = "the file ended while reading a record header";
      return false;
    }
    r.data_len = le_u32(header.data() + hl);
    r.data_offset = pos + 8 + hl;
    if (size - r.data_offset < r.data_len) {
      why = "a record claims " + std::to_string(r.data_len) + " bytes of data, the file has " +
            std::to_string(size - r.data_offset) + " left";
      return false;
    }
    r.end = r.data_offset + r.data_len;
    r.head = Ros1Header{};
    return parse_ros1_header(std::string_view(header.data(), hl), r.head, why);
  }

  std::string record_data(const Record& r, const char* role) const {
    return file_.read_string(r.data_offset, r.data_len, limits_.max_chunk_bytes, role);
  }

  /// Connections (0x07) and chunk infos (0x06) from index_pos to the end; false (with a
  /// warning) when they are damaged.
  bool read_index(std::uint64_t pos, const Ros1Header& bag_header) {
    std::map<std::uint32_t, BagConnection> found;
    std::vector<std::uint64_t> chunks;
    std::int64_t start = 0, end = 0;
    bool any = false;
    try {
      while (pos < file_.size()) {
        Record r;
        std::string why;
        if (!read_record(pos, r, why)) {
          warnings_.push_back(file_.what() + ": the index is damaged at byte " + std::to_string(pos) + " (" + why +
                              "); read through to list it");
          return false;
        }
        if (r.head.op == 0x07) {
          add_connection(r.head, record_data(r, "connection record"), found);
        } else if (r.head.op == 0x06) {
          const std::string d = record_data(r, "chunk info record");
          const std::uint32_t n = r.head.count.value_or(0);
          if (d.size() / 8 < n) {
            warnings_.push_back(file_.what() + ": the chunk info at byte " + std::to_string(pos) +
                                " is damaged; read through to list the bag");
            return false;
          }
          for (std::uint32_t k = 0; k < n; ++k) {
            const std::uint32_t conn = le_u32(d.data() + 8 * k), count = le_u32(d.data() + 8 * k + 4);
            found[conn].id = conn;
            found[conn].messages += count;
          }
          if (r.head.chunk_pos) chunks.push_back(*r.head.chunk_pos);
          if (count_in_chunk(r.head)) {
            const std::int64_t s = ros1_time_ns(*r.head.start_time), e = ros1_time_ns(*r.head.end_time);
            start = any ? std::min(start, s) : s;
            end = any ? std::max(end, e) : e;
            any = true;
          }
        }
        pos = r.end;
      }
    } catch (const Error& e) {
      warnings_.push_back(std::string(e.what()) + "; read through to list the bag");
      return false;
    }
    // The bag header's counts check the index: a damaged one is read through instead.
    if (bag_header.chunk_count && *bag_header.chunk_count != chunks.size()) {
      warnings_.push_back(file_.what() + ": its index lists " + std::to_string(chunks.size()) + " chunks, its header " +
                          std::to_string(*bag_header.chunk_count) + "; read through to list it");
      return false;
    }
    if (bag_header.conn_count && *bag_header.conn_count != found.size()) {
      warnings_.push_back(file_.what() + ": its index lists " + std::to_string(found.size()) + " connections, its header " +
                          std::to_string(*bag_header.conn_count) + "; read through to list it");
      return false;
    }
    for (auto& [id, c] : found) {
      if (c.topic.empty()) {
        warnings_.push_back(file_.what() + ": the index counts messages of connection " + std::to_string(id) +
                            " but does not define it; read through to list the bag");
        return false;
      }
      connections_.push_back(c);
    }
    if (any) {
      start_ns_ = start;
      end_ns_ = end;
      any_time_ = true;
    }
    std::sort(chunks.begin(), chunks.end());
    chunk_positions_ = std::move(chunks);
    indexed_ = true;
    return true;
  }

  static bool count_in_chunk(const Ros1Header& h) { return h.start_time && h.end_time; }

  void add_connection(const Ros1Header& head, std::string_view data, std::map<std::uint32_t, BagConnection>& into) {
    if (!head.conn) return;
    Ros1Header inner;
    std::string why;
    if (!parse_ros1_header(data, inner, why)) inner = Ros1Header{};
    BagConnection& c = into[*head.conn];
    c.id = *head.conn;
    c.topic = !head.topic.empty() ? head.topic : inner.topic;
    c.type = inner.type;
    c.encoding = "ros1";
  }

  /// Reads the bag through to find its connections and counts (no usable index).
  void scan() {
    indexed_ = false;
    std::map<std::uint32_t, BagConnection> found;
    rewind();
    Item item;
    while (advance(item)) {
      if (item.head.op == 0x07) {
        if (item.head.conn && found.count(*item.head.conn) == 0) add_connection(item.head, item.data, found);
      } else if (item.head.op == 0x02 && item.head.conn) {
        BagConnection& c = found[*item.head.conn];
        c.id = *item.head.conn;
        ++c.messages;
        saw_time(ros1_time_ns(item.head.time.value_or(0)));
      }
    }
    for (auto& [id, c] : found)
      if (!c.topic.empty()) connections_.push_back(c);
  }

  void rewind() {
    pos_ = data_start_;
    chunk_.reset();
    chunk_pos_ = 0;
  }

  /// Records damage once: reading after a scan meets the scan's damage again.
  void warn(std::string w) {
    if (std::find(warnings_.begin(), warnings_.end(), w) == warnings_.end()) warnings_.push_back(std::move(w));
  }

  /// The next message or connection record; false at the end.
  bool advance(Item& out) {
    for (;;) {
      if (chunk_) {
        const std::string& c = *chunk_;
        if (chunk_pos_ >= c.size()) {
          chunk_.reset();
          continue;
        }
        const std::size_t at = chunk_pos_;
        const std::size_t left = c.size() - at;
        std::string why;
        std::uint32_t hl = 0, dl = 0;
        if (left < 8 || (hl = le_u32(c.data() + at)) > left - 8 || (dl = le_u32(c.data() + at + 4 + hl)) > left - 8 - hl) {
          warn(file_.what() + ": chunk at byte " + std::to_string(chunk_offset_) + ": the record at byte " +
               std::to_string(at) + " of its " + std::to_string(c.size()) +
               " uncompressed bytes runs past its end; the rest of the chunk is skipped");
          chunk_.reset();
          continue;
        }
        Ros1Header head;
        if (!parse_ros1_header(std::string_view(c.data() + at + 4, hl), head, why)) {
          warn(file_.what() + ": chunk at byte " + std::to_string(chunk_offset_) + ": the record at byte " +
               std::to_string(at) + " of the chunk has a malformed header (" + why + "); the rest of the chunk is skipped");
          chunk_.reset();
          continue;
        }
        chunk_pos_ = at + 8 + hl + dl;
        if (head.op != 0x02 && head.op != 0x07) continue;
        out.head = std::move(head);
        out.data = std::string_view(c.data() + at + 8 + hl, dl);
        out.owner = chunk_;
        out.offset = chunk_offset_;
        return true;
      }
      if (pos_ >= data_end_) return false;
      Record r;
      std::string why;
      if (!read_record(pos_, r, why)) {
        // With an index, reading resumes at the next chunk it lists.
        const auto next_chunk = std::upper_bound(chunk_positions_.begin(), chunk_positions_.end(), pos_);
        if (next_chunk != chunk_positions_.end() && *next_chunk < data_end_) {
          warn(file_.what() + ": damaged at byte " + std::to_string(pos_) + " (" + why +
               "); reading resumes at the next chunk, byte " + std::to_string(*next_chunk));
          pos_ = *next_chunk;
          continue;
        }
        warn(file_.what() + ": truncated or damaged at byte " + std::to_string(pos_) + " (" + why +
             "); the messages before it were read");
        pos_ = data_end_;
        return false;
      }
      const std::uint64_t at = pos_;
      pos_ = r.end;
      if (r.head.op == 0x05) {
        load_chunk(r, at);
      } else if (r.head.op == 0x02 || r.head.op == 0x07) {
        auto data = std::make_shared<std::string>(record_data(r, r.head.op == 0x02 ? "message record" : "connection record"));
        out.head = std::move(r.head);
        out.data = *data;
        out.owner = std::move(data);
        out.offset = at;
        return true;
      }
    }
  }

  /// The chunk record `r` at `at`, decompressed into chunk_; a chunk that cannot be read
  /// is skipped with a warning.
  void load_chunk(const Record& r, std::uint64_t at) {
    const std::string where = file_.what() + ": chunk at byte " + std::to_string(at);
    if (!r.head.size) {
      warn(where + " has no size field; skipped");
      return;
    }
    const std::uint64_t size = *r.head.size;
    if (size > limits_.max_chunk_bytes) {
      warn(where + " claims " + std::to_string(size) + " uncompressed bytes, more than the limit of " +
           std::to_string(limits_.max_chunk_bytes) + " (BagLimits::max_chunk_bytes); skipped");
      return;
    }
    const std::string& how = r.head.compression;
    if (how != "none" && how != "bz2" && how != "lz4") {
      warn(where + " is compressed with '" + how + "' (a ROS 1 bag has none, bz2 or lz4); skipped");
      return;
    }
    if (how == "none" && r.data_len != size) {
      warn(where + " holds " + std::to_string(r.data_len) + " bytes but says " + std::to_string(size) + "; skipped");
      return;
    }
    const BagComponent* codecs = nullptr;
    if (how != "none") codecs = &require_bag_component(where + " (" + how + ")");
    std::string data = record_data(r, "chunk");
    if (how == "none") {
      chunk_ = std::make_shared<const std::string>(std::move(data));
    } else {
      std::string out, reason;
      bool ok = false;
      try {
        ok = how == "bz2" ? codecs->bz2(data, static_cast<std::size_t>(size), out, reason)
                          : codecs->lz4_frame(data, static_cast<std::size_t>(size), out, reason);
      } catch (const std::bad_alloc&) {
        fail(where + ": not enough memory for its " + std::to_string(size) + " uncompressed bytes");
      }
      if (!ok) {
        warn(where + " does not decompress (" + how + ": " + reason + "); skipped");
        return;
      }
      chunk_ = std::make_shared<const std::string>(std::move(out));
    }
    chunk_pos_ = 0;
    chunk_offset_ = at;
  }

  BagFile file_;
  BagLimits limits_;
  std::uint64_t data_start_ = 0, data_end_ = 0;
  std::uint64_t pos_ = 0;
  std::vector<std::uint64_t> chunk_positions_;  ///< from the index, sorted
  std::shared_ptr<const std::string> chunk_;
  std::size_t chunk_pos_ = 0;
  std::uint64_t chunk_offset_ = 0;
};

}  // namespace vmap::detail
