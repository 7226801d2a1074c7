#pragma once

// The single-file format of a visual memory (.vmem): one back-end of the memory's
// records (memory/records.hpp), the whole memory in one file, written atomically by
// VisualMemory::save. The other back-end is the memory store (memory/store.hpp).
//
// Encoding (io/binary.hpp): integers little-endian, fixed width; f32/f64 IEEE-754; str =
// u32 length + bytes.
//
//   header: u8[8] "VMAPMEMO", u32 version (5), u32 section count (12)
//   sections, in this order, each { u8[4] tag, u64 length, u32 CRC-32 of the bytes, bytes }:
//     "opts"  the options whole (record_codecs.hpp, write_memory_options): the selector's
//             (f64 tau, u8 rule, u8 fast path), u8 image storage, i32 JPEG quality, u64
//             vocabulary_after, the vocabulary tree's (i32 branching, i32 depth, i32
//             iterations, u64 max_descriptors, u64 seed), u8 scoring, the loop options
//             (lcd/loop_engine.hpp, write_loop_options), u64 localize_top_k, the
//             label options (u64 sample, f64 min/max influence, u32 n + n x i32 order)
//     "keys"  u64 frames pushed, u32 key images m, m x key record (u64 frame index, f64
//             time s, i64 time ns, str name, features as in map files, u8 image kind
//             none/PNG/JPEG [+ i32 rows, cols, type, u32 length, bytes], pose: u8 kind
//             none/SE(2)/SE(3) [+ 3 or 12 f64])
//     "link"  u32 m - 1, the link into each key image after the first (map_io.hpp's pair
//             record: u8 status, f64[9] F, i32 matches, i32 inliers, f64 similarity)
//     "loop"  u32 e, e x { u32 from, u32 to, f64 BoW score, u8 status, f64[9] model, i32
//             matches, i32 inliers, f64 similarity, f64 confidence }
//     "selc"  the selector's record: u8 has I_{j-1} [its key record], its score (u8 0 none
//             | 1 complete | 2 degeneracy deferred, then the score [and the inlier mask]),
//             u8 has last frame [u64 last frame index]
//     "voca"  u8 has vocabulary [u64 length, the vocabulary's file bytes]
//     "plcd"  u64 length, the place database's file bytes (place/database.hpp): the bag of
//             words of each key image checked for loops, key images 0 .. n-1
//     "plcy"  4 x str: what each policy records of itself (describe(); "" for none)
//     "labl"  u8 labelled, u8 has schema [u32 n + n x i32], u32 m, each key image's
//             detections (u32 n + n x {i32 label, f32 score, f32 x y w h}), I_{j-1}'s
//     "gcsl"  u8 has GCS [the GCS's record, memory/gcs.hpp]
//     "dcsn"  the loop engine's state (lcd/loop_engine.hpp, LoopEngineState)
//     "sess"  u32 n, n x {u64 first key image, u64 first frame}: the sessions after the first
//
// Earlier versions still load: version 4 kept the loop options in three places ("opts"
// the window, top k and inlier floor; "labl" eq. 3's threshold, m and the candidate
// source with the label options; "dcsn" the rest, before the engine's state), the loop
// edges' confidences after the state in "dcsn", and key records without the time in
// nanoseconds; version 3 had no "sess" (one session); version 2 no "dcsn" (decision
// options at their defaults, confidences 0); version 1 none of "plcy", "labl", "gcsl".
//
// Every section is parsed by its own reader, so every error names the file and the
// section, and counts are checked against the bytes that remain before anything is
// allocated. The records' consistency (with each other, with the policies given to
// load) is VisualMemory::from_records's to check, as it is for a store's records.

#include <vmap/core/error.hpp>
#include <vmap/io/atomic_file.hpp>
#include <vmap/io/binary.hpp>
#include <vmap/io/database_files.hpp>
#include <vmap/keyframe/map_io.hpp>
#include <vmap/memory/detail/format.hpp>
#include <vmap/memory/detail/record_codecs.hpp>
#include <vmap/memory/records.hpp>
#include <vmap/place/database.hpp>

#include <array>
#include <cstddef>
#include <cstdint>
#include <filesystem>
#include <string>
#include <string_view>
#include <system_error>
#include <vector>

namespace vmap::detail {

/// The bytes of a .vmem file of these (whole) records, key images' pixels kept as
/// `storage` says.
[[nodiscard]] inline std::string vmem_file_bytes(const MemoryRecords& m, ImageStorage storage) {
  check(m.first_key == 0 && m.first_loop == 0 && m.first_bow == 0 && m.first_session == 0 && m.vocabulary &&
            m.gcs_written,
        "vmem_file_bytes: the records are not a whole memory");
  const int quality = m.options.jpeg_quality;
  MemorySectionWriter s;
  {
    BinaryWriter w;
    write_memory_options(w, m.options, storage);
    s.add("opts", w.data());
  }
  {
    BinaryWriter w;
    w.u64(m.frames);
    w.u32(static_cast<std::uint32_t>(m.keys.size()));
    for (const KeyImageRecord& k : m.keys) write_key_record(w, k.key, k.key.features, k.pose, storage, quality);
    s.add("keys", w.data());
  }
  {
    BinaryWriter w;
    w.u32(static_cast<std::uint32_t>(m.links.size()));
    for (const KeyPair& p : m.links) write_key_pair(w, p);
    s.add("link", w.data());
  }
  {
    BinaryWriter w;
    w.u32(static_cast<std::uint32_t>(m.loops.size()));
    for (const LoopEdge& e : m.loops) write_loop_record(w, e);
    s.add("loop", w.data());
  }
  {
    BinaryWriter w;
    write_selector_record(w, m.selector, storage, quality);
    s.add("selc", w.data());
  }
  {
    BinaryWriter w;
    write_vocabulary_record(w, *m.vocabulary);
    s.add("voca", w.data());
  }
  {
    BinaryWriter records;
    for (std::size_t i = 0; i < m.bows.size(); ++i)
      records.bytes(PlaceDatabase<std::uint32_t>::record_of(static_cast<std::uint32_t>(i), m.bows[i]));
    const std::string db =
        PlaceDatabase<std::uint32_t>::serialize_records(m.options.scoring, m.words, m.bows.size(), records.data());
    BinaryWriter w;
    w.u64(db.size());
    w.bytes(db);
    s.add("plcd", w.data());
  }
  {
    BinaryWriter w;
    for (const std::string& p : m.policies) w.str(p, memory_max_policy, "VisualMemory::save: a policy record");
    s.add("plcy", w.data());
  }
  {
    BinaryWriter w;
    write_labels_record(w, m.labelled, m.schema);
    w.u32(static_cast<std::uint32_t>(m.keys.size()));
    for (const KeyImageRecord& k : m.keys) memory_write_detections(w, k.detections);
    memory_write_detections(w, m.selector.previous ? m.selector.previous->detections : std::vector<Detection>{});
    s.add("labl", w.data());
  }
  {
    BinaryWriter w;
    write_gcs_record(w, m.gcs);
    s.add("gcsl", w.data());
  }
  {
    BinaryWriter w;
    m.engine.write(w);
    s.add("dcsn", w.data());
  }
  {
    BinaryWriter w;
    write_sessions_record(w, m.sessions);
    s.add("sess", w.data());
  }
  BinaryWriter h;
  h.bytes(memory_magic, 8);
  h.u32(memory_format_version);
  h.u32(memory_sections);
  h.bytes(s.out_.data());
  return std::move(h).take();
}

/// Writes the bytes of a .vmem file (vmem_file_bytes) at `path`, atomically
/// (io/atomic_file.hpp). An existing file there is replaced only when it is a .vmem
/// memory file, known by its first bytes: a memory store (this program's own memory
/// included: a save over it would turn it into a file that its next syncs no longer
/// reach), any other file, a folder or a device are refused, naming the path.
inline void save_vmem(const std::filesystem::path& path, std::string_view bytes) {
  std::error_code ec;
  if (std::filesystem::exists(path, ec)) {
    // Read through io/database_files.hpp: the file may be a store this process has open.
    if (const auto head = read_head(path, 100)) {
      const std::string_view h = *head;
      const bool store = h.size() == 100 && h.starts_with(std::string_view("SQLite format 3\0", 16)) &&
                         h.substr(68, 4) == std::string_view("VMAP", 4);
      if (store)
        fail("'" + path.string() + "' is a memory store; a save writes a single-file memory (.vmem) and never replaces "
             "a store: give another path (a store is written by its syncs, and copied by vmap memory convert)");
      if (!h.starts_with(std::string_view(memory_magic, 8)))
        fail("'" + path.string() + "' exists and is not a .vmem memory file; refusing to replace it with a saved memory");
    } else {
      fail("'" + path.string() + "' exists and is not a regular file (a folder, a device, or unreadable); refusing to "
           "replace it with a saved memory");
    }
  }
  write_file_atomically(path, bytes);
}

/// The records of a .vmem file of any version (1 to memory_format_version), parsed
/// section by section; `name` names the file in errors. `limits` bound the key images'
/// pixels; `pixels_skipped` is set when they were checked but not decoded.
[[nodiscard]] inline MemoryRecords read_vmem(std::string_view bytes, const std::string& name, const MapLoadOptions& limits,
                                             bool* pixels_skipped = nullptr) {
  BinaryReader file(bytes, "memory file '" + name + "'");
  if (bytes.size() < 16) file.corrupt("header: too short (" + std::to_string(bytes.size()) + " bytes)");
  if (file.bytes(8, "magic") != std::string_view(memory_magic, 8)) file.corrupt("header: not a vmap memory (wrong magic bytes)");
  MemoryRecords m;
  const std::uint32_t version = file.u32("version");
  if (version < 1 || version > memory_format_version)
    file.fail_here(version < 1 ? ErrorKind::corrupt : ErrorKind::unsupported_version,
                   "header: format version " + std::to_string(version) + " is not supported (this build reads 1 to " +
                       std::to_string(memory_format_version) + ")");
  m.version = version;
  const std::uint32_t sections = version == 1   ? memory_sections_v1
                                 : version == 2 ? memory_sections_v2
                                 : version == 3 ? memory_sections_v3
                                                : memory_sections;
  if (const std::uint32_t n = file.u32("section count"); n != sections)
    file.corrupt("header: " + std::to_string(n) + " sections, expected " + std::to_string(sections) + " in version " +
                 std::to_string(version));

  auto opts = memory_open_section(file, "opts");
  m.options = version >= 5 ? read_memory_options(opts) : read_options_v4(opts, version);

  std::uint64_t total_pixels = 0;
  const KeyReading how{limits, total_pixels, pixels_skipped, true};
  auto keys = memory_open_section(file, "keys");
  const std::uint64_t frames = keys.u64("frame count");
  if (frames > memory_max_frames) keys.corrupt("frame count " + std::to_string(frames) + " is more than a memory can hold (2^40)");
  m.frames = static_cast<std::size_t>(frames);
  const std::uint32_t count = keys.u32("key image count");
  keys.require_items(count, 50, "key image count");
  if (count > m.frames) keys.corrupt(std::to_string(count) + " key images for " + std::to_string(m.frames) + " frames");
  m.keys.reserve(count);
  for (std::uint32_t i = 0; i < count; ++i) m.keys.push_back(read_key_record(keys, version, how));
  keys.expect_end("the last key image");

  auto links = memory_open_section(file, "link");
  const std::uint32_t p = links.u32("pair count");
  if (p != (count == 0 ? 0U : count - 1U))
    links.corrupt("pair count " + std::to_string(p) + " for " + std::to_string(count) + " key images");
  for (std::uint32_t i = 0; i < p; ++i) m.links.push_back(read_key_pair(links, "verification status"));
  links.expect_end("the last pair");

  auto loops = memory_open_section(file, "loop");
  const std::uint32_t e = loops.u32("loop edge count");
  loops.require_items(e, 8 + 97, "loop edge count");
  for (std::uint32_t i = 0; i < e; ++i) m.loops.push_back(read_loop_record(loops, version, count));
  loops.expect_end("the last loop edge");

  auto selc = memory_open_section(file, "selc");
  m.selector = read_selector_record(selc, version, how,
                                    count > 0 ? std::optional<std::size_t>(m.keys.back().key.frame_index) : std::nullopt);

  auto voca = memory_open_section(file, "voca");
  m.vocabulary = read_vocabulary_record(voca);

  auto plcd = memory_open_section(file, "plcd");
  {
    const std::uint64_t len = plcd.u64("database length");
    const std::string source = plcd.source() + " database";
    auto db = open_payload(plcd.bytes(len, "database"), PlaceDatabase<std::uint32_t>::file_magic(),
                           PlaceDatabase<std::uint32_t>::file_version, "place database", source);
    const std::uint8_t scoring = db.u8("scoring");
    if (scoring != static_cast<std::uint8_t>(m.options.scoring)) db.corrupt("its scoring is not the memory's");
    const std::uint64_t words = db.u64("words");
    if (words > std::numeric_limits<std::uint32_t>::max()) db.corrupt("vocabulary size " + std::to_string(words) + " is too large");
    m.words = static_cast<std::size_t>(words);
    const std::uint64_t n = db.u64("image count");
    db.require_items(n, 12, "image count");
    for (std::uint64_t i = 0; i < n; ++i) {
      auto [id, bow] = PlaceDatabase<std::uint32_t>::read_record(db, m.words, m.options.scoring);
      if (id != i) db.corrupt("image id " + std::to_string(id) + " is not key image " + std::to_string(i));
      m.bows.push_back(std::move(bow));
    }
    db.expect_end("the last image");
    plcd.expect_end("the database");
  }

  if (version >= 2) {
    auto plcy = memory_open_section(file, "plcy");
    for (std::string& policy : m.policies) policy = plcy.str("policy record", memory_max_policy);
    plcy.expect_end("the policies");

    auto labl = memory_open_section(file, "labl");
    if (version <= 4) read_options_v4_labels(labl, m.options);
    read_labels_record(labl, m.options, m.labelled, m.schema);
    const std::uint32_t n = labl.u32("key detection count");
    if (n != count) labl.corrupt("detections for " + std::to_string(n) + " key images, the memory has " + std::to_string(count));
    for (KeyImageRecord& k : m.keys) k.detections = memory_read_detections(labl);
    std::vector<Detection> previous = memory_read_detections(labl);
    labl.expect_end("the detections");
    // Only an I_{j-1} held by the selector can become a key image: other detections of
    // the last frame are never read.
    if (m.selector.previous) m.selector.previous->detections = std::move(previous);
    else if (!m.labelled && !previous.empty()) labl.corrupt("detections in a memory without labels");

    auto gcsl = memory_open_section(file, "gcsl");
    std::vector<OdometryPose> poses;
    for (const KeyImageRecord& k : m.keys) poses.push_back(k.pose);
    m.gcs = read_gcs_record(gcsl, poses);
  }
  if (version >= 3) {
    auto dcsn = memory_open_section(file, "dcsn");
    if (version <= 4) read_options_v4_decision(dcsn, m.options);
    m.engine = LoopEngineState::read(dcsn, m.bows.size());
    if (version <= 4) {
      const std::uint32_t n = dcsn.u32("loop edge count");
      if (n != m.loops.size())
        dcsn.corrupt(std::to_string(n) + " confidences for " + std::to_string(m.loops.size()) + " loop edges");
      dcsn.require_items(n, 8, "loop edge count");
      for (LoopEdge& edge : m.loops) edge.link.confidence = read_confidence(dcsn);
    }
    dcsn.expect_end("the decision");
  }
  if (version <= 4) m.options = checked_or_corrupt(opts, m.options);
  if (version >= 4) {
    auto sess = memory_open_section(file, "sess");
    m.sessions = read_sessions_record(sess, count, m.frames);
  } else {
    m.sessions.assign(1, MemorySession{});
  }
  if (!file.at_end()) file.corrupt(std::to_string(file.remaining()) + " unexpected bytes after the last section");
  return m;
}

}  // namespace vmap::detail
