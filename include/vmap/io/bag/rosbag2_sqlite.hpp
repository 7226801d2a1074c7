#pragma once

// A reader of ROS 2 rosbag2 bags in sqlite3 storage (rosbag2_storage_sqlite3, the Humble
// default), through the SQLite the memory store uses (io/sqlite.hpp): a `.db3` file, or
// the bag's folder (its `metadata.yaml` lists the files in `relative_file_paths`; without
// it, the folder's `.db3` files in natural order, as rosbag2 numbers its splits).
//
// Tables: `topics(id, name, type, serialization_format, ...)` and `messages(id, topic_id,
// timestamp, data)`, messages in CDR. Messages are read by row id, the order they were
// written, one row at a time; a message's length is read before its bytes, and one longer
// than BagLimits::max_chunk_bytes is skipped with a warning naming its row, unread.
// rosbag2's compressed bags (compression_mode file or message) are refused with a message
// saying so. Every file of the bag must be a regular file, named once: a metadata.yaml
// that lists a FIFO, a device or one file twice is refused before any file is opened.
//
// A file SQLite finds damaged ends with a warning naming the file and the last row read;
// the next split file, if any, is still read.

#include <vmap/core/error.hpp>
#include <vmap/io/bag/types.hpp>
#include <vmap/io/detail/natural_order.hpp>
#include <vmap/io/files.hpp>
#include <vmap/io/sqlite.hpp>

#include <sys/stat.h>

#include <algorithm>
#include <cctype>
#include <cstdint>
#include <filesystem>
#include <fstream>
#include <map>
#include <memory>
#include <optional>
#include <string>
#include <string_view>
#include <tuple>
#include <utility>
#include <vector>

namespace vmap::detail {

/// The value of a top-level `key: value` line of a rosbag2 metadata.yaml (machine-written
/// by rosbag2: one key a line, block lists of `- item`), quotes removed.
inline std::optional<std::string> rosbag2_metadata_value(std::string_view text, std::string_view key) {
  std::size_t pos = 0;
  while (pos < text.size()) {
    std::size_t end = text.find('\n', pos);
    if (end == std::string_view::npos) end = text.size();
    std::string_view line = text.substr(pos, end - pos);
    pos = end + 1;
    const std::size_t indent = line.find_first_not_of(' ');
    if (indent == std::string_view::npos) continue;
    line.remove_prefix(indent);
    if (line.substr(0, key.size()) != key || line.size() <= key.size() || line[key.size()] != ':') continue;
    std::string_view v = line.substr(key.size() + 1);
    while (!v.empty() && (v.front() == ' ' || v.front() == '\t')) v.remove_prefix(1);
    while (!v.empty() && (v.back() == ' ' || v.back() == '\r' || v.back() == '\t')) v.remove_suffix(1);
    if (v.size() >= 2 && (v.front() == '"' || v.front() == '\'') && v.back() == v.front()) v = v.substr(1, v.size() - 2);
    return std::string(v);
  }
  return std::nullopt;
}

/// The items of the block list under `key:` in a metadata.yaml.
inline std::vector<std::string> rosbag2_metadata_list(std::string_view text, std::string_view key) {
  std::vector<std::string> items;
  std::size_t pos = 0;
  std::optional<std::size_t> key_indent;
  while (pos < text.size()) {
    std::size_t end = text.find('\n', pos);
    if (end == std::string_view::npos) end = text.size();
    std::string_view line = text.substr(pos, end - pos);
    pos = end + 1;
    while (!line.empty() && (line.back() == '\r' || line.back() == ' ')) line.remove_suffix(1);
    const std::size_t indent = line.find_first_not_of(' ');
    if (indent == std::string_view::npos) continue;
    const std::string_view body = line.substr(indent);
    if (!key_indent) {
      if (body.size() == key.size() + 1 && body.substr(0, key.size()) == key && body.back() == ':') key_indent = indent;
      continue;
    }
    if (body.size() >= 2 && body[0] == '-' && body[1] == ' ' && indent >= *key_indent) {
      std::string_view v = body.substr(2);
      if (v.size() >= 2 && (v.front() == '"' || v.front() == '\'') && v.back() == v.front()) v = v.substr(1, v.size() - 2);
      items.emplace_back(v);
      continue;
    }
    break;
  }
  return items;
}

class Rosbag2Sqlite final : public MessageStream {
 public:
  /// `input`: a `.db3` file or a rosbag2 folder.
  explicit Rosbag2Sqlite(const std::filesystem::path& input, const BagLimits& limits = {})
      : input_(input), limits_(limits) {
    format_ = BagFormat::rosbag2_sqlite;
    const std::string what = "bag '" + input.string() + "'";
    std::error_code ec;
    if (std::filesystem::is_directory(input, ec)) {
      const auto meta = input / "metadata.yaml";
      if (std::filesystem::exists(meta, ec)) {
        const std::string text = read_text_file(meta, "rosbag2 metadata", std::uintmax_t{16} << 20);
        const auto mode = rosbag2_metadata_value(text, "compression_mode");
        const auto format = rosbag2_metadata_value(text, "compression_format");
        if ((mode && !mode->empty()) || (format && !format->empty()))
          fail(what + " is compressed (rosbag2 compression_format '" + format.value_or("") + "', mode '" +
               mode.value_or("") + "'); vmap reads uncompressed rosbag2 bags: decompress it first (ros2 bag convert)");
        if (const auto storage = rosbag2_metadata_value(text, "storage_identifier"); storage && *storage != "sqlite3")
          fail(what + " is stored as '" + *storage + "', not sqlite3");
        for (const auto& f : rosbag2_metadata_list(text, "relative_file_paths")) files_.push_back(input / f);
      }
      if (files_.empty()) {
        std::vector<std::string> names;
        for (std::filesystem::directory_iterator it(input, ec), end; !ec && it != end; it.increment(ec))
          if (it->path().extension() == ".db3") names.push_back(it->path().filename().string());
        std::sort(names.begin(), names.end(), natural_less);
        for (const auto& n : names) files_.push_back(input / n);
      }
      if (files_.empty()) fail(what + ": the folder holds no .db3 file (a rosbag2 sqlite3 bag)");
    } else {
      files_.push_back(input);
    }
    check_files(what);
    std::map<std::tuple<std::string, std::string, std::string>, std::uint32_t> ids;
    bool any = false;
    for (std::size_t f = 0; f < files_.size(); ++f) {
      check_length(files_[f]);
      sqlite::Database db = open_db(files_[f]);
      auto& map = topic_maps_.emplace_back();
      auto topics = db.prepare("SELECT id, name, type, serialization_format FROM topics", "list its topics");
      while (topics.step()) {
        const std::int64_t row = topics.integer(0);
        const auto key = std::make_tuple(topics.text(1), topics.text(2), topics.text(3));
        auto [it, fresh] = ids.try_emplace(key, static_cast<std::uint32_t>(connections_.size()));
        if (fresh) connections_.push_back({it->second, std::get<0>(key), std::get<1>(key), std::get<2>(key), 0});
        map[row] = it->second;
      }
      auto counts = db.prepare("SELECT topic_id, COUNT(*), MIN(timestamp), MAX(timestamp) FROM messages GROUP BY topic_id",
                               "count its messages");
      try {
        while (counts.step()) {
          const auto it = map.find(counts.integer(0));
          if (it == map.end()) continue;
          connections_[it->second].messages += static_cast<std::uint64_t>(counts.integer(1));
          const std::int64_t lo = counts.integer(2), hi = counts.integer(3);
          start_ns_ = any ? std::min(start_ns_, lo) : lo;
          end_ns_ = any ? std::max(end_ns_, hi) : hi;
          any = true;
        }
      } catch (const Error& e) {
        warnings_.push_back(std::string(e.what()) + " (the file is damaged; its messages are read up to the damage)");
        indexed_ = false;
      }
    }
    any_time_ = any;
    for (const auto& c : connections_)
      if (c.encoding != "cdr")
        warnings_.push_back(what + ": topic '" + c.topic + "' is serialized as '" + c.encoding + "', not cdr");
  }

  bool next(StreamMessage& out) override {
    for (;;) {
      if (!statement_) {
        if (file_ >= files_.size()) return false;
        open_file();
        if (!statement_) {
          ++file_;
          continue;
        }
      }
      try {
        if (statement_->step()) {
          const auto& map = topic_maps_[file_];
          const auto it = map.find(statement_->integer(1));
          last_row_ = statement_->integer(0);
          if (it == map.end() || !wanted(it->second)) continue;
          const std::int64_t length = statement_->integer(3);
          if (length < 0 || static_cast<std::uint64_t>(length) > limits_.max_chunk_bytes) {
            warnings_.push_back("bag '" + files_[file_].string() + "', row " + std::to_string(last_row_) + ": a message of " +
                                std::to_string(length) + " bytes, more than the limit of " +
                                std::to_string(limits_.max_chunk_bytes) + " (BagLimits::max_chunk_bytes); skipped");
            continue;
          }
          auto data = std::make_shared<const std::string>(statement_->blob(4));
          out.connection = it->second;
          out.record_ns = statement_->integer(2);
          out.offset = static_cast<std::uint64_t>(last_row_);
          out.bytes = *data;
          out.owner = std::move(data);
          return true;
        }
      } catch (const Error& e) {
        warnings_.push_back(std::string(e.what()) + " after row " + std::to_string(last_row_) +
                            " (the file is damaged); the messages before it were read");
      }
      statement_.reset();
      db_.reset();
      ++file_;
    }
  }

 private:
  void open_file() {
    try {
      db_ = std::make_unique<sqlite::Database>(open_db(files_[file_]));
      // Only the rows of selected topics: the others' data (point clouds ...) is not read.
      // length() of a blob is read from its record header, without its bytes; the bytes
      // are read only when the length is within the limit.
      std::string in;
      for (const auto& [row, id] : topic_maps_[file_])
        if (wanted(id)) in += (in.empty() ? "" : ",") + std::to_string(row);
      const std::string limit = std::to_string(limits_.max_chunk_bytes);
      statement_ = std::make_unique<sqlite::Statement>(
          db_->prepare("SELECT id, topic_id, timestamp, length(data), CASE WHEN length(data) <= " + limit +
                           " THEN data END FROM messages WHERE topic_id IN (" + in + ") ORDER BY id",
                       "read its messages"));
      last_row_ = 0;
    } catch (const Error& e) {
      warnings_.push_back(e.what());
      statement_.reset();
      db_.reset();
    }
  }

  /// A read-only connection that reads a file cut short up to where it ends: SQLite
  /// refuses a file shorter than its header states unless writable_schema is on (which
  /// lets a read-only connection read it page by page, the damage then an error at the
  /// first missing page).
  static sqlite::Database open_db(const std::filesystem::path& file) {
    sqlite::Database db(file, sqlite::Access::read, "bag '" + file.string() + "'");
    db.exec("PRAGMA writable_schema=ON", "read it");
    return db;
  }

  /// Every file is a regular file (a FIFO named by metadata.yaml would block the reads
  /// below, a device never end) and is named once: a file listed twice, under any name,
  /// would be read twice.
  void check_files(const std::string& what) const {
    std::map<std::pair<dev_t, ino_t>, std::filesystem::path> seen;
    for (const auto& file : files_) {
      const struct stat st = require_regular_file(file, "bag file");
      const auto [it, fresh] = seen.try_emplace({st.st_dev, st.st_ino}, file);
      if (!fresh)
        fail(ErrorKind::corrupt, what + " names the file '" + file.string() + "' twice" +
             (it->second == file ? std::string() : " (also as '" + it->second.string() + "')") +
             "; each file of a bag is read once: list it once in metadata.yaml's relative_file_paths");
    }
  }

  /// A warning when the file is shorter than its SQLite header states (SQLite file
  /// format, section 1.3: page size at byte 16, page count at byte 28, both big-endian).
  void check_length(const std::filesystem::path& file) {
    std::ifstream in(file, std::ios::binary);
    unsigned char h[32] = {};
    in.read(reinterpret_cast<char*>(h), sizeof h);
    if (in.gcount() != sizeof h) return;
    std::uint64_t page = (std::uint64_t{h[16]} << 8) | h[17];
    if (page == 1) page = 65536;
    const std::uint64_t pages = (std::uint64_t{h[28]} << 24) | (std::uint64_t{h[29]} << 16) | (std::uint64_t{h[30]} << 8) | h[31];
    std::error_code ec;
    const auto size = std::filesystem::file_size(file, ec);
    if (!ec && pages > 0 && page * pages > size)
      warnings_.push_back("bag '" + file.string() + "' ends at byte " + std::to_string(size) + ", its SQLite header states " +
                          std::to_string(page * pages) + " bytes: the file is truncated; its messages are read up to the end");
  }

  std::filesystem::path input_;
  BagLimits limits_;
  std::vector<std::filesystem::path> files_;
  std::vector<std::map<std::int64_t, std::uint32_t>> topic_maps_;  ///< per file: topic row -> connection
  std::size_t file_ = 0;
  std::unique_ptr<sqlite::Database> db_;
  std::unique_ptr<sqlite::Statement> statement_;
  std::int64_t last_row_ = 0;
};

}  // namespace vmap::detail
