// The loaders under fuzzing: one VMAP_FUZZ_LOADER(name, body) line each, where `body`
// parses `bytes` (a std::string_view of the fuzzer's input). tests/fuzz/CMakeLists.txt
// reads the names from this file and builds one libFuzzer executable `fuzz_<name>` per
// line, seeded from tests/fuzz/corpus/<name>/ when that folder exists. Adding a loader
// is one line here (and, optionally, a few seed files). This file, which includes every
// reader of the library, is compiled once; each executable adds fuzz_main.cpp.
//
// A loader may throw vmap::Error for bad input (that is the contract); any other
// exception, a crash, a sanitizer report, a leak or a timeout is a finding.

#include <vmap/hooks/class_names.hpp>
#include <vmap/hooks/precomputed_detections.hpp>
#include <vmap/io/bag/bag.hpp>
#include <vmap/io/calibration.hpp>
#include <vmap/io/frame_source.hpp>
#include <vmap/io/image.hpp>
#include <vmap/io/poses.hpp>
#include <vmap/keyframe/map_io.hpp>
#include <vmap/lcd/binary_tree.hpp>
#include <vmap/lcd/evaluation.hpp>
#include <vmap/memory/stacks.hpp>
#include <vmap/memory/store.hpp>
#include <vmap/memory/visual_memory.hpp>
#include <vmap/place/database.hpp>
#include <vmap/place/vocabulary.hpp>
#include <vmap/place/vocabulary_import.hpp>
#include <vmap/som/gcs.hpp>

#include "common/cli_support.hpp"  // the --config reader of the command line

#include <cstddef>
#include <unistd.h>
#include <fstream>
#include <filesystem>
#include <cstdint>
#include <cstdlib>
#include <sstream>
#include <string>
#include <string_view>

#define VMAP_FUZZ_LOADER(name, body) \
  void fuzz_load_##name([[maybe_unused]] std::string_view bytes); \
  void fuzz_load_##name([[maybe_unused]] std::string_view bytes) body

// Key images of at most 1 Mi pixels, 8 Mi together: a decoded image stays far below the
// fuzzer's memory limit.
inline constexpr vmap::MapLoadOptions fuzz_pixel_limits{.max_image_pixels = 1 << 20, .max_total_image_pixels = 1 << 23};

// A robot bag (ROS 1, rosbag2 sqlite3, MCAP): written to a file of its own per process,
// every message read through, then each image topic read as frames (small limits, so a
// decoded image stays far below the fuzzer's memory limit).
inline void fuzz_bag(std::string_view bytes, const char* extension) {
  const std::filesystem::path p =
      std::filesystem::temp_directory_path() / ("vmap_fuzz_bag_" + std::to_string(::getpid()) + extension);
  std::filesystem::remove(p);
  std::ofstream(p, std::ios::binary).write(bytes.data(), static_cast<std::streamsize>(bytes.size()));
  const vmap::BagLimits limits{.max_chunk_bytes = 1 << 24, .max_header_bytes = 1 << 20};
  try {
    auto stream = vmap::detail::open_message_stream(p, limits);
    vmap::detail::StreamMessage m;
    while (stream->next(m)) {
    }
    for (const auto& t : vmap::detail::bag_topics(*stream)) {
      if (!vmap::detail::is_image_type(t.type)) continue;
      try {
        auto frames = vmap::FrameSource::open(p, {.max_pixels = 1 << 20, .topic = t.name, .bag_limits = limits});
        while (frames.next()) {
        }
        (void)frames.times_ns();
      } catch (const vmap::Error&) {
      }
    }
  } catch (...) {
    std::filesystem::remove(p);
    throw;
  }
  std::filesystem::remove(p);
}

// One row of a memory store, decoded as MemoryStore's reader decodes it (the record
// codecs of memory/detail/record_codecs.hpp, then the check that nothing follows the
// record): the first byte picks the row, the rest is its blob. Faster than a whole store
// per input, and it reaches the codecs with the blob's bytes as they are, with no
// checksum in the way.
inline void fuzz_memory_record(std::string_view bytes) {
  if (bytes.empty()) return;
  namespace d = vmap::detail;
  d::BinaryReader r(bytes.substr(1), "fuzz");
  std::uint64_t pixels = 0;
  const d::KeyReading how{fuzz_pixel_limits, pixels, nullptr, true};
  switch (static_cast<unsigned char>(bytes[0]) % 9) {
    case 0:
      (void)d::read_key_record(r, vmap::memory_format_version, how);
      r.expect_end("the key image");
      break;
    case 1:
      (void)d::read_key_record(r, 4, {fuzz_pixel_limits, pixels, nullptr, false});
      r.expect_end("the key image");
      break;
    case 2:
      (void)d::read_key_pair(r, "verification status");
      r.expect_end("the link");
      break;
    case 3:
      (void)d::read_loop_record(r, vmap::memory_format_version, 64);
      r.expect_end("the loop edge");
      break;
    case 4:
      (void)d::read_selector_record(r, vmap::memory_format_version, how, 3);
      break;
    case 5:
      (void)d::read_sessions_record(r, 64, 1000);
      break;
    case 6:
      (void)d::read_vocabulary_record(r);
      break;
    case 7:
      (void)d::read_memory_options(r);
      break;
    default:
      (void)d::memory_read_detections(r);
      r.expect_end("the detections");
      break;
  }
}

// clang-format off
VMAP_FUZZ_LOADER(map, { (void)vmap::deserialize_map(bytes, "fuzz", fuzz_pixel_limits); })
VMAP_FUZZ_LOADER(gcs, { (void)vmap::GcsXf::deserialize(bytes, "fuzz"); (void)vmap::Gcs2d::deserialize(bytes, "fuzz"); })
VMAP_FUZZ_LOADER(tree, { (void)vmap::BinaryClassifiedTree<int>::from_text(bytes, "fuzz"); })
VMAP_FUZZ_LOADER(detections, { (void)vmap::PrecomputedDetections::parse(bytes, "fuzz"); })
VMAP_FUZZ_LOADER(poses, { (void)vmap::parse_camera_poses(bytes, vmap::guess_camera_pose_format(bytes, "fuzz"), "fuzz"); })
VMAP_FUZZ_LOADER(ground_truth, { (void)vmap::LoopGroundTruth::parse(bytes, "fuzz"); })
VMAP_FUZZ_LOADER(class_names, { (void)vmap::parse_class_names(bytes, "fuzz"); })
VMAP_FUZZ_LOADER(image_header, { (void)vmap::image_header_size(bytes); })
VMAP_FUZZ_LOADER(vocabulary, { (void)vmap::BinaryVocabularyTree::deserialize(bytes, "fuzz"); (void)vmap::FloatVocabularyTree::deserialize(bytes, "fuzz"); })
VMAP_FUZZ_LOADER(vocabulary_orbslam_text, { (void)vmap::import_orbslam_text(bytes, "fuzz"); })
VMAP_FUZZ_LOADER(vocabulary_dbow2_yaml, { (void)vmap::import_dbow2_yaml(bytes, "fuzz"); })
VMAP_FUZZ_LOADER(vocabulary_fbow, { (void)vmap::import_fbow(bytes, "fuzz"); })
// Calibration files of every format (ORB-SLAM, ROS, Kalibr, EuRoC YAML and KITTI text).
VMAP_FUZZ_LOADER(calibration, { (void)vmap::parse_camera(std::string(bytes), "fuzz"); })
// The command line's --config reader: a bad file is CLI11's ConfigError (exit 2).
VMAP_FUZZ_LOADER(config, {
  std::istringstream in{std::string(bytes)};
  try {
    (void)vmap::examples::YamlConfig("build", {"build", "loops"}).from_config(in);
  } catch (const CLI::ConfigError&) {
  }
})
VMAP_FUZZ_LOADER(place_database, { (void)vmap::PlaceDatabase<std::uint32_t>::deserialize(bytes, "fuzz"); })
// A memory file that loads is written back by the loaded memory into bytes that load
// again (whatever it accepted is a state it can save); anything else is a bug: abort.
VMAP_FUZZ_LOADER(memory, {
  const std::string again = vmap::OrbVisualMemory::deserialize(bytes, "fuzz", vmap::OrbDescriptor{}, vmap::BruteForceMatcher{},
                                                                vmap::FundamentalEstimator{}, vmap::InlierRatio{}, fuzz_pixel_limits).serialize();
  try {
    (void)vmap::OrbVisualMemory::deserialize(again, "fuzz again");
  } catch (...) {
    std::abort();
  }
})
// A memory store (an SQLite file) with mutated pages and blobs: written to a file of its
// own per process, opened read-only and loaded.
VMAP_FUZZ_LOADER(memory_store, {
  const std::filesystem::path p =
      std::filesystem::temp_directory_path() / ("vmap_fuzz_store_" + std::to_string(::getpid()) + ".vmdb");
  const auto remove_all = [&] {
    std::error_code ec;
    for (const char* suffix : {"", "-wal", "-shm"}) std::filesystem::remove(p.string() + suffix, ec);
  };
  remove_all();
  std::ofstream(p, std::ios::binary).write(bytes.data(), static_cast<std::streamsize>(bytes.size()));
  try {
    auto store = vmap::MemoryStore::open(p, vmap::sqlite::Access::read);
    (void)store.load<vmap::OrbVisualMemory>(vmap::OrbDescriptor{}, vmap::BruteForceMatcher{}, vmap::FundamentalEstimator{},
                                            vmap::InlierRatio{}, fuzz_pixel_limits);
  } catch (...) {
    remove_all();
    throw;
  }
  remove_all();
})
// One row of a memory store (fuzz_memory_record above).
VMAP_FUZZ_LOADER(memory_records, { fuzz_memory_record(bytes); })
VMAP_FUZZ_LOADER(ros1_bag, { fuzz_bag(bytes, ".bag"); })
VMAP_FUZZ_LOADER(rosbag2_sqlite, { fuzz_bag(bytes, ".db3"); })
VMAP_FUZZ_LOADER(mcap, { fuzz_bag(bytes, ".mcap"); })
// clang-format on
