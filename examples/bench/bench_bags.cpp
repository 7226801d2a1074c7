// Reading robot bags (io/bag/, the vmap::bags component) against reading the same frames
// from image files, in one process:
//
//   - compressed bags (the RTAB-Map loop JPEGs in MCAP, rosbag2 sqlite3 and a ROS 1 bag
//     with lz4 chunks) against the JPEG folder they were made from: the same JPEG bytes
//     decoded either way, so the ratio is the cost of reading the container;
//   - raw sensor_msgs/Image bags (TUM fr1_rpy's 60 frames, mono8) against decoding the
//     same frames from their JPEG files (rgb.txt);
//   - peak resident memory (VmHWM) of a process that reads each bag (this program run
//     again with --peak-of, so that no earlier read's heap is counted), and of synthetic
//     bags of the 60 raw frames written once and ten times over (ROS 1 with uncompressed
//     chunks, rosbag2 sqlite3, MCAP with zstd chunks): a reader that holds one chunk at
//     a time needs the same memory for both.
//
//   bench_bags [--shared DIR] [--runs N] [--scratch DIR]
//   bench_bags --peak-of INPUT [--topic T]   (prints the peak in MiB)
//
// Frames are decoded to grey, as `vmap build` reads them, one thread, best of N runs
// taken in turn (each configuration once per round).
#include <vmap/io/bag/bag.hpp>
#include <vmap/io/frame_source.hpp>
#include <vmap/io/sqlite.hpp>

#include <mcap/writer.hpp>

#include <CLI/CLI.hpp>

#include <algorithm>
#include <chrono>
#include <cstdint>
#include <cstdio>
#include <stdio.h>
#include <filesystem>
#include <fstream>
#include <limits>
#include <string>
#include <vector>

namespace {

namespace fs = std::filesystem;
using Clock = std::chrono::steady_clock;

double status_mib(const std::string& field) {
  std::ifstream in("/proc/self/status");
  for (std::string line; std::getline(in, line);)
    if (line.rfind(field + ":", 0) == 0) return std::stod(line.substr(field.size() + 1)) / 1024.0;
  return 0.0;
}


struct Config {
  std::string label;
  fs::path input;
  std::string topic;
};

struct Timing {
  double best = std::numeric_limits<double>::infinity();
  std::size_t frames = 0;
};

std::size_t read_all(const Config& c) {
  auto src = vmap::FrameSource::open(c.input, {.grey = true, .topic = c.topic});
  std::size_t n = 0;
  while (auto f = src.next()) n += f->image.empty() ? 0 : 1;
  return n;
}

/// The serialized messages of `topic` in `bag`, in order.
std::vector<std::string> payloads(const fs::path& bag, const std::string& topic) {
  auto s = vmap::detail::open_message_stream(bag);
  std::vector<std::uint32_t> ids;
  for (const auto& c : s->connections())
    if (c.topic == topic) ids.push_back(c.id);
  s->select(ids);
  std::vector<std::string> out;
  vmap::detail::StreamMessage m;
  while (s->next(m)) out.emplace_back(m.bytes);
  return out;
}

void put(std::string& b, std::uint32_t v) {
  for (int i = 0; i < 4; ++i) b += static_cast<char>((v >> (8 * i)) & 0xff);
}
void put64(std::string& b, std::uint64_t v) {
  for (int i = 0; i < 8; ++i) b += static_cast<char>((v >> (8 * i)) & 0xff);
}
std::string field(const std::string& name, const std::string& value) {
  std::string f;
  put(f, static_cast<std::uint32_t>(name.size() + 1 + value.size()));
  return f + name + "=" + value;
}
std::string u32_value(std::uint32_t v) {
  std::string s;
  put(s, v);
  return s;
}
std::string u64_value(std::uint64_t v) {
  std::string s;
  put64(s, v);
  return s;
}
std::string record(const std::string& header, const std::string& data) {
  std::string r;
  put(r, static_cast<std::uint32_t>(header.size()));
  r += header;
  put(r, static_cast<std::uint32_t>(data.size()));
  return r + data;
}
std::uint64_t ros1_time(std::int64_t ns) {
  return static_cast<std::uint64_t>(ns / 1000000000) | (static_cast<std::uint64_t>(ns % 1000000000) << 32);
}

/// A ROS 1 bag 2.0 with uncompressed chunks of 4 messages (wiki.ros.org/Bags/Format/2.0).
void write_ros1(const fs::path& file, const std::string& topic, const std::vector<std::string>& messages, int repeat) {
  const std::string conn_header = field("topic", topic) + field("type", "sensor_msgs/Image") +
                                  field("md5sum", "060021388200f6f0f447d0fcd9c64743") + field("message_definition", "");
  const std::string connection = record(field("op", "\x07") + field("conn", u32_value(0)) + field("topic", topic), conn_header);
  std::ofstream out(file, std::ios::binary);
  out << "#ROSBAG V2.0\n";
  const std::uint64_t header_at = 13;
  out << std::string(4096, ' ');
  std::uint64_t pos = header_at + 4096;
  std::string infos;
  std::uint32_t chunks = 0;
  const std::size_t total = messages.size() * static_cast<std::size_t>(repeat);
  for (std::size_t first = 0; first < total; first += 4) {
    std::string data = connection, index;
    std::int64_t t0 = 0, t1 = 0;
    std::uint32_t count = 0;
    for (std::size_t k = first; k < std::min(total, first + 4); ++k, ++count) {
      const std::int64_t t = 1000000000LL * static_cast<std::int64_t>(k + 1);
      if (k == first) t0 = t;
      t1 = t;
      put64(index, ros1_time(t));
      put(index, static_cast<std::uint32_t>(data.size()));
      data += record(field("op", "\x02") + field("conn", u32_value(0)) + field("time", u64_value(ros1_time(t))),
                     messages[k % messages.size()]);
    }
    const std::string chunk = record(field("op", "\x05") + field("compression", "none") +
                                         field("size", u32_value(static_cast<std::uint32_t>(data.size()))),
                                     data);
    const std::string idx = record(field("op", "\x04") + field("ver", u32_value(1)) + field("conn", u32_value(0)) +
                                       field("count", u32_value(count)),
                                   index);
    infos += record(field("op", "\x06") + field("ver", u32_value(1)) + field("chunk_pos", u64_value(pos)) +
                        field("start_time", u64_value(ros1_time(t0))) + field("end_time", u64_value(ros1_time(t1))) +
                        field("count", u32_value(1)),
                    u32_value(0) + u32_value(count));
    out << chunk << idx;
    pos += chunk.size() + idx.size();
    ++chunks;
  }
  out << connection << infos;
  const std::string header = field("op", "\x03") + field("index_pos", u64_value(pos)) + field("conn_count", u32_value(1)) +
                             field("chunk_count", u32_value(chunks));
  std::string bag_header;
  put(bag_header, static_cast<std::uint32_t>(header.size()));
  bag_header += header;
  put(bag_header, static_cast<std::uint32_t>(4096 - 8 - header.size()));
  bag_header += std::string(4096 - 8 - header.size(), ' ');
  out.seekp(static_cast<std::streamoff>(header_at));
  out << bag_header;
}

void write_db3(const fs::path& file, const std::string& topic, const std::vector<std::string>& messages, int repeat) {
  fs::remove(file);
  vmap::sqlite::Database db(file, vmap::sqlite::Access::create, "bench bag");
  db.exec("PRAGMA journal_mode=DELETE", "journal");
  db.exec(
      "CREATE TABLE topics(id INTEGER PRIMARY KEY, name TEXT NOT NULL, type TEXT NOT NULL, serialization_format TEXT "
      "NOT NULL, offered_qos_profiles TEXT NOT NULL);"
      "CREATE TABLE messages(id INTEGER PRIMARY KEY, topic_id INTEGER NOT NULL, timestamp INTEGER NOT NULL, data BLOB "
      "NOT NULL);",
      "create tables");
  db.prepare("INSERT INTO topics VALUES (1, ?, 'sensor_msgs/msg/Image', 'cdr', '')", "topic").bind_text(1, topic).run();
  vmap::sqlite::Transaction tx(db, "insert");
  auto add = db.prepare("INSERT INTO messages(topic_id, timestamp, data) VALUES (1, ?, ?)", "message");
  for (int r = 0; r < repeat; ++r)
    for (std::size_t k = 0; k < messages.size(); ++k)
      add.bind(1, static_cast<std::int64_t>(r * 1000 + static_cast<int>(k))).bind_blob(2, messages[k]).run();
  tx.commit();
}

void write_mcap(const fs::path& file, const std::string& topic, const std::vector<std::string>& messages, int repeat) {
  mcap::McapWriter writer;
  mcap::McapWriterOptions o("ros2");
  o.compression = mcap::Compression::Zstd;
  if (!writer.open(file.string(), o).ok()) vmap::detail::fail("cannot write " + file.string());
  mcap::Schema schema("sensor_msgs/msg/Image", "ros2msg", std::string());
  writer.addSchema(schema);
  mcap::Channel channel(topic, "cdr", schema.id);
  writer.addChannel(channel);
  std::uint64_t t = 1;
  for (int r = 0; r < repeat; ++r)
    for (const auto& m : messages) {
      mcap::Message msg;
      msg.channelId = channel.id;
      msg.logTime = msg.publishTime = t++;
      msg.data = reinterpret_cast<const std::byte*>(m.data());
      msg.dataSize = m.size();
      (void)writer.write(msg);
    }
  writer.close();
}

/// The peak resident memory (MiB) and frames of a fresh process that reads `c`.
std::pair<double, std::size_t> peak_in_child(const std::string& self, const Config& c) {
  std::string cmd = "'" + self + "' --peak-of '" + c.input.string() + "'";
  if (!c.topic.empty()) cmd += " --topic '" + c.topic + "'";
  FILE* p = ::popen(cmd.c_str(), "r");
  if (p == nullptr) vmap::detail::fail("cannot run " + cmd);
  double mib = 0;
  std::size_t frames = 0;
  const int got = std::fscanf(p, "%lf %zu", &mib, &frames);
  if (::pclose(p) != 0 || got != 2) vmap::detail::fail("'" + cmd + "' failed");
  return {mib, frames};
}

}  // namespace

int main(int argc, char** argv) {
  CLI::App app{"bench_bags: reading robot bags against reading image files"};
  fs::path shared = VMAP_SHARED_DIR;
  int runs = 5;
  fs::path scratch = fs::temp_directory_path() / "vmap_bench_bags";
  app.add_option("--shared", shared, "The shared data folder (data/bags, data/rtabmap_loop)");
  app.add_option("--runs", runs, "Rounds; each configuration's best time is kept")->check(CLI::Range(1, 100));
  app.add_option("--scratch", scratch, "Folder for the synthetic bags (about 1.3 GB)");
  std::string peak_of, peak_topic;
  app.add_option("--peak-of", peak_of, "Read INPUT, print the process's peak resident memory (MiB) and its frames");
  app.add_option("--topic", peak_topic, "With --peak-of: the bag's topic");
  CLI11_PARSE(app, argc, argv);
  try {
    if (!peak_of.empty()) {
      const std::size_t n = read_all({"", peak_of, peak_topic});
      std::printf("%.1f %zu\n", status_mib("VmHWM"), n);
      return 0;
    }
    const std::string self = fs::read_symlink("/proc/self/exe").string();
    const fs::path bags = shared / "data/bags";
    const fs::path sample = fs::path(VMAP_SOURCE_DIR) / "examples/data/tum_fr1_rpy_60/rgb.txt";
    const std::vector<std::pair<Config, std::vector<Config>>> groups = {
        {{"JPEG folder (rtabmap_loop/images)", shared / "data/rtabmap_loop/images", ""},
         {{"MCAP, lz4 chunks", bags / "rtabmap_loop.mcap", ""},
          {"rosbag2 sqlite3", bags / "rtabmap_loop_db3", ""},
          {"ROS 1, lz4 chunks", bags / "rtabmap_loop_compressed.bag", ""}}},
        {{"JPEG files (tum_fr1_rpy_60/rgb.txt)", sample, ""},
         {{"MCAP, zstd chunks, mono8", bags / "tum_fr1_rpy_60.mcap", "/cam0/image_raw"},
          {"rosbag2 sqlite3, mono8", bags / "tum_fr1_rpy_60_db3", "/cam0/image_raw"},
          {"ROS 1, bz2 chunks, mono8", bags / "tum_fr1_rpy_60.bag", "/cam0/image_raw"}}}};
    std::vector<Config> all;
    for (const auto& [base, others] : groups) {
      all.push_back(base);
      all.insert(all.end(), others.begin(), others.end());
    }
    std::vector<Timing> t(all.size());
    for (int r = 0; r < runs; ++r)
      for (std::size_t i = 0; i < all.size(); ++i) {
        const auto t0 = Clock::now();
        t[i].frames = read_all(all[i]);
        t[i].best = std::min(t[i].best, std::chrono::duration<double>(Clock::now() - t0).count());
      }
    std::printf("bench_bags: frames read and decoded to grey, one thread, best of %d rounds\n", runs);
    std::size_t i = 0;
    for (const auto& [base, others] : groups) {
      const Timing b = t[i++];
      std::printf("\n%-40s %4zu frames %8.1f ms %8.1f frames/s (baseline)\n", base.label.c_str(), b.frames, 1e3 * b.best,
                  static_cast<double>(b.frames) / b.best);
      for (const auto& o : others) {
        const Timing x = t[i++];
        std::printf("%-40s %4zu frames %8.1f ms %8.1f frames/s  time %.3fx the baseline's\n", o.label.c_str(), x.frames,
                    1e3 * x.best, static_cast<double>(x.frames) / x.best, x.best / b.best);
      }
    }

    // Peak memory: each shared bag, then synthetic bags 1x and 10x as long.
    std::printf("\npeak resident memory of a process that reads the input (VmHWM)\n");
    for (const auto& c : all) {
      const auto [mib, n] = peak_in_child(self, c);
      std::printf("%-40s %5zu frames  %7.1f MiB\n", c.label.c_str(), n, mib);
    }
    fs::create_directories(scratch);
    const std::string topic = "/cam0/image_raw";
    const auto ros1 = payloads(bags / "tum_fr1_rpy_60.bag", topic);
    const auto cdr = payloads(bags / "tum_fr1_rpy_60.mcap", topic);
    std::printf("\nsynthetic bags of the 60 raw 640x480 frames, once and ten times over:\n");
    for (int repeat : {1, 10}) {
      const std::string tag = "x" + std::to_string(repeat);
      write_ros1(scratch / (tag + ".bag"), topic, ros1, repeat);
      write_db3(scratch / (tag + ".db3"), topic, cdr, repeat);
      write_mcap(scratch / (tag + ".mcap"), topic, cdr, repeat);
      for (const char* ext : {".bag", ".db3", ".mcap"}) {
        const fs::path file = scratch / (tag + ext);
        const auto [mib, n] = peak_in_child(self, {tag, file, ""});
        std::printf("%-8s %-5s %9.1f MB %5zu frames  %7.1f MiB\n", tag.c_str(), ext,
                    static_cast<double>(fs::file_size(file)) / 1e6, n, mib);
      }
    }
    for (int repeat : {1, 10})
      for (const char* ext : {".bag", ".db3", ".mcap"}) fs::remove(scratch / ("x" + std::to_string(repeat) + ext));
  } catch (const std::exception& e) {
    std::fprintf(stderr, "bench_bags: %s\n", e.what());
    return 1;
  }
  return 0;
}
