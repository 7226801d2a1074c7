#pragma once

// The codecs of the visual memory's records (memory/records.hpp), which both back-ends
// store as bytes: the single-file format (memory/vmem.hpp) in its sections, the memory
// store (memory/store.hpp) in its rows. Each record is read as the format `version`
// wrote it (1 to memory_format_version); writers write the current version. Every
// reader checks counts against the bytes that remain before allocating and names what is
// wrong (detail::BinaryReader::corrupt). The parts' own codecs are composed here: the
// features and links of keyframe/map_io.hpp, the selector's options and score
// (keyframe/selector.hpp, map_io.hpp), the loop options and the engine's state
// (lcd/loop_engine.hpp), the vocabulary tree's options (place/vocabulary_tree.hpp), the
// GCS (memory/gcs.hpp), detections, poses and images (memory/detail/format.hpp).

#include <vmap/core/error.hpp>
#include <vmap/io/binary.hpp>
#include <vmap/io/timestamps.hpp>
#include <vmap/keyframe/map_io.hpp>
#include <vmap/keyframe/selector.hpp>
#include <vmap/lcd/influence.hpp>
#include <vmap/lcd/label_vector.hpp>
#include <vmap/lcd/loop_engine.hpp>
#include <vmap/memory/detail/format.hpp>
#include <vmap/memory/gcs.hpp>
#include <vmap/memory/records.hpp>
#include <vmap/memory/types.hpp>
#include <vmap/place/database.hpp>
#include <vmap/place/vocabulary.hpp>
#include <vmap/place/vocabulary_tree.hpp>

#include <array>
#include <cmath>
#include <cstddef>
#include <cstdint>
#include <memory>
#include <optional>
#include <string>
#include <vector>

namespace vmap::detail {

// ---- options ---------------------------------------------------------------------------

/// MemoryOptions that a memory can run with, or an Error naming the option: the one
/// check of the constructor and of every reader.
[[nodiscard]] inline MemoryOptions checked_memory_options(MemoryOptions o) {
  check(o.vocabulary_after >= 1, "MemoryOptions.vocabulary_after must be >= 1");
  check(o.localize_top_k >= 1, "MemoryOptions.localize_top_k must be >= 1");
  check_loop_options(o.loops, "MemoryOptions.loops");
  check(o.loops.top_k >= 1, "MemoryOptions.loops.top_k must be >= 1");
  check(o.jpeg_quality >= 1 && o.jpeg_quality <= 100,
        [&] { return "MemoryOptions.jpeg_quality must be in 1..100, got " + std::to_string(o.jpeg_quality); });
  check(o.images <= ImageStorage::jpeg, "MemoryOptions.images is not a known ImageStorage");
  check(std::isfinite(o.selector.tau) && o.selector.tau > 0.0 && o.selector.tau <= 1.0,
        [&] { return "MemoryOptions.selector.tau must be in (0, 1], got " + std::to_string(o.selector.tau); });
  check(o.scoring <= BowScoring::cosine, "MemoryOptions.scoring is not a known BowScoring");
  try {
    check_vocabulary_tree_options(o.vocabulary);
  } catch (const Error& e) {
    fail(std::string("MemoryOptions.vocabulary: ") + e.what());
  }
  const MemoryLabelOptions& l = o.labels;
  check_influence_options(l.influence);
  check(l.sample >= 1, "MemoryOptions.labels.sample must be >= 1");
  check(uses_labels(o.loops.index), [&] {
    return "MemoryOptions.loops.index must be tree or tree_ranked (the source with detections), got " +
           std::string(to_string(o.loops.index));
  });
  try {
    (void)LabelSchema(l.order);
  } catch (const Error& e) {
    fail(std::string("MemoryOptions.labels.order: ") + e.what());
  }
  o.selector.keep_images = o.images != ImageStorage::none;
  return o;
}

inline void write_label_list(BinaryWriter& w, const std::vector<int>& labels) {
  w.u32(static_cast<std::uint32_t>(labels.size()));
  for (const int l : labels) w.i32(l);
}

inline std::vector<int> read_label_list(BinaryReader& r, const char* what) {
  const std::uint32_t n = r.u32(what);
  r.require_items(n, 4, what);
  std::vector<int> labels(n);
  for (int& l : labels) l = r.i32(what);
  return labels;
}

/// MemoryOptions whole (version 5; key images' storage as given: a file may be written
/// without the pixels the memory keeps).
inline void write_memory_options(BinaryWriter& w, const MemoryOptions& o, ImageStorage storage) {
  static_assert(field_count<MemoryOptions>() == 9 && field_count<MemoryLabelOptions>() == 3 &&
                    field_count<InfluenceOptions>() == 2,
                "a new MemoryOptions field must be written and read here");
  write_selector_options(w, o.selector);
  w.u8(static_cast<std::uint8_t>(storage));
  w.i32(o.jpeg_quality);
  w.u64(o.vocabulary_after);
  write_vocabulary_tree_options(w, o.vocabulary);
  w.u8(static_cast<std::uint8_t>(o.scoring));
  write_loop_options(w, o.loops);
  w.u64(o.localize_top_k);
  w.u64(o.labels.sample);
  w.f64(o.labels.influence.min_influence);
  w.f64(o.labels.influence.max_influence);
  write_label_list(w, o.labels.order);
}

/// What the options of every version begin with: the selector's, the storage, the
/// vocabulary's and the scoring.
inline MemoryOptions read_options_head(BinaryReader& r) {
  MemoryOptions o;
  o.selector = read_selector_options(r);
  const std::uint8_t images = r.u8("image storage");
  if (images > 2) r.corrupt("unknown image storage " + std::to_string(images));
  o.images = static_cast<ImageStorage>(images);
  o.jpeg_quality = r.i32("jpeg quality");
  o.vocabulary_after = static_cast<std::size_t>(r.u64("vocabulary_after"));
  o.vocabulary = read_vocabulary_tree_options(r);
  const std::uint8_t scoring = r.u8("scoring");
  if (scoring > 2) r.corrupt("unknown scoring " + std::to_string(scoring));
  o.scoring = static_cast<BowScoring>(scoring);
  return o;
}

inline MemoryOptions checked_or_corrupt(BinaryReader& r, const MemoryOptions& o) {
  try {
    return checked_memory_options(o);
  } catch (const Error& e) {
    r.corrupt(e.what());
  }
}

/// write_memory_options()'s bytes, checked.
inline MemoryOptions read_memory_options(BinaryReader& r) {
  MemoryOptions o = read_options_head(r);
  o.loops = read_loop_options(r, "MemoryOptions.loops");
  o.localize_top_k = static_cast<std::size_t>(r.u64("localize_top_k"));
  o.labels.sample = static_cast<std::size_t>(r.u64("label sample"));
  o.labels.influence.min_influence = r.f64("min_influence");
  o.labels.influence.max_influence = r.f64("max_influence");
  o.labels.order = read_label_list(r, "label order");
  r.expect_end("the options");
  return checked_or_corrupt(r, o);
}

/// The options of versions 1 to 4, whose loop options are spread over three records:
/// here the window, the top k and the inlier floor (the rest at their defaults until
/// read_options_v4_labels and read_options_v4_decision fill them in). Not checked: the
/// caller checks them once all are read.
inline MemoryOptions read_options_v4(BinaryReader& r, std::uint32_t version) {
  MemoryOptions o = read_options_head(r);
  o.loops.window = static_cast<std::size_t>(r.u64("window"));
  o.loops.top_k = static_cast<std::size_t>(r.u64("top k"));
  o.loops.decision.min_inliers = r.i32("min_loop_inliers");
  o.localize_top_k = static_cast<std::size_t>(r.u64("localize_top_k"));
  // Version 2 had a separate floor for localization; version 3 one floor for both.
  if (const int again = r.i32("min_localize_inliers"); version >= 3 && again != o.loops.decision.min_inliers)
    r.corrupt("the two inlier floors differ");
  r.expect_end("the options");
  // The revisit ratio is in the decision's record from version 3 on (0.2 by default then);
  // an older file reads as the same memory written again in version 3.
  o.loops.left_ratio = 0.2;
  return o;
}

/// The label options versions 2 to 4 kept at the start of the labels' record.
inline void read_options_v4_labels(BinaryReader& r, MemoryOptions& o) {
  o.loops.labels.min_score = r.f32("label min_score");
  o.labels.sample = static_cast<std::size_t>(r.u64("label sample"));
  o.labels.influence.min_influence = r.f64("min_influence");
  o.labels.influence.max_influence = r.f64("max_influence");
  const std::uint8_t index = r.u8("label candidate source");
  if (index > static_cast<std::uint8_t>(CandidateIndex::brute_force)) r.corrupt("unknown candidate source");
  o.loops.index = static_cast<CandidateIndex>(index);
  o.loops.min_candidates = static_cast<std::size_t>(r.u64("min_candidates"));
  o.labels.order = read_label_list(r, "label order");
}

/// The decision's options versions 3 and 4 kept at the start of the decision's record.
inline void read_options_v4_decision(BinaryReader& r, MemoryOptions& o) {
  LoopOptions& l = o.loops;
  l.temporal_consistency = static_cast<std::size_t>(r.u64("temporal_consistency"));
  l.temporal_tolerance = static_cast<std::size_t>(r.u64("temporal_tolerance"));
  l.min_bow_score = r.f64("min_bow_score");
  l.left_ratio = r.f64("left_ratio");
  l.decision.min_confidence = r.f64("min_confidence");
  l.decision.chance_inlier_rate = r.f64("chance_inlier_rate");
  l.decision.half_significance = r.f64("half_significance");
  l.decision.spread_grid = r.i32("spread_grid");
  l.decision.full_spread = r.f64("full_spread");
  l.decision.ambiguity_ratio = r.f64("ambiguity_ratio");
}

// ---- key images ------------------------------------------------------------------------

/// A key image and its pose (version 5): u64 frame index, f64 time (s), i64 time (ns),
/// str name, features (map_io.hpp), image (none, PNG or JPEG), pose. `features` are the
/// key image's (a memory that released them passes them read back).
inline void write_key_record(BinaryWriter& w, const KeyImage& k, const Features& features, const OdometryPose& pose,
                             ImageStorage storage, int jpeg_quality) {
  w.u64(k.frame_index);
  w.f64(k.timestamp);
  w.i64(k.time_ns);
  w.str(k.name, map_max_string, "VisualMemory::save: a key image name");
  write_features(w, features);
  write_memory_image(w, k.image, storage, jpeg_quality);
  memory_write_pose(w, pose);
}

/// How key images are read: the pixel limits (MapLoadOptions, summed over the memory in
/// `total_pixels`), whether their features are kept (false: skipped, as a bounded load
/// keeps them), and where a skipped decode of pixels is reported.
struct KeyReading {
  const MapLoadOptions& limits;
  std::uint64_t& total_pixels;
  bool* pixels_skipped = nullptr;
  bool features = true;
};

/// Reads write_key_record()'s bytes as `version` wrote them (before 5: no time in ns, it
/// is then the seconds rounded).
inline KeyImageRecord read_key_record(BinaryReader& r, std::uint32_t version, const KeyReading& how) {
  KeyImageRecord out;
  KeyImage& k = out.key;
  const std::uint64_t index = r.u64("frame index");
  if (index > memory_max_frames) r.corrupt("frame index " + std::to_string(index) + " is above 2^40");
  k.frame_index = static_cast<std::size_t>(index);
  k.timestamp = r.f64("timestamp");
  k.time_ns = version >= 5 ? r.i64("timestamp in nanoseconds") : nanoseconds_from_seconds(k.timestamp);
  k.name = r.str("name", map_max_string);
  k.features = read_features(r, how.features);
  k.image = read_memory_image(r, how.limits, how.total_pixels, how.pixels_skipped);
  out.pose = memory_read_pose(r);
  return out;
}

// ---- loop edges ------------------------------------------------------------------------

/// A loop edge (version 5): u32 from, u32 to, the link (format.hpp), f64 confidence.
/// Versions 1 to 4 kept the confidences apart (read_loop_record leaves them 0).
inline void write_loop_record(BinaryWriter& w, const LoopEdge& e) {
  w.u32(e.from);
  w.u32(e.link.key);
  memory_write_link(w, e.link);
  w.f64(e.link.confidence);
}

/// A place decision's confidence, in [0, 1].
inline double read_confidence(BinaryReader& r) {
  const double c = r.f64("loop confidence");
  if (!(c >= 0.0 && c <= 1.0)) r.corrupt("a loop confidence outside [0, 1]");
  return c;
}

/// Reads a loop edge of a memory of `keys` key images.
inline LoopEdge read_loop_record(BinaryReader& r, std::uint32_t version, std::size_t keys) {
  LoopEdge e;
  e.from = r.u32("loop from");
  const std::uint32_t to = r.u32("loop to");
  if (e.from >= keys || to >= e.from) r.corrupt("loop edge between invalid key images");
  e.link = memory_read_link(r);
  e.link.key = to;
  if (version >= 5) e.link.confidence = read_confidence(r);
  return e;
}

// ---- the selector ----------------------------------------------------------------------

/// The selector's record: u8 has I_{j-1}; [its key record (with pose)]; its score
/// (map_io.hpp's write_previous_score); u8 has last frame; [u64 last frame index].
inline void write_selector_record(BinaryWriter& w, const SelectorRecord& s, ImageStorage storage, int jpeg_quality) {
  w.u8(s.previous ? 1 : 0);
  if (s.previous) write_key_record(w, s.previous->key, s.previous->key.features, s.previous->pose, storage, jpeg_quality);
  SelectorState<Features> score;
  if (s.previous) score.previous.emplace();
  score.previous_score = s.previous_score;
  score.degeneracy_deferred = s.degeneracy_deferred;
  write_previous_score(w, score);
  w.u8(s.last_frame_index ? 1 : 0);
  if (s.last_frame_index) w.u64(*s.last_frame_index);
}

/// Reads write_selector_record()'s bytes for a memory whose last key image is at frame
/// `last_key_frame` (nullopt without key images). I_{j-1}'s detections are the labels'.
inline SelectorRecord read_selector_record(BinaryReader& r, std::uint32_t version, const KeyReading& how,
                                           std::optional<std::size_t> last_key_frame) {
  SelectorRecord s;
  const std::uint8_t has_previous = r.u8("previous frame flag");
  if (has_previous > 1) r.corrupt("previous frame flag is not 0 or 1");
  if (has_previous == 1) {
    if (!last_key_frame) r.corrupt("a previous frame without a key image");
    s.previous = read_key_record(r, version, {how.limits, how.total_pixels, how.pixels_skipped, true});
    if (s.previous->key.frame_index <= *last_key_frame) r.corrupt("previous frame is not after the key image");
  }
  SelectorState<Features> score;
  if (s.previous) score.previous.emplace();
  read_previous_score(r, score);
  s.previous_score = std::move(score.previous_score);
  s.degeneracy_deferred = score.degeneracy_deferred;
  const std::uint8_t has_last = r.u8("last frame flag");
  if (has_last > 1 || (has_last == 0 && last_key_frame)) r.corrupt("invalid last frame flag");
  if (has_last == 1) {
    const std::uint64_t last = r.u64("last frame index");
    if (last > memory_max_frames) r.corrupt("last frame index " + std::to_string(last) + " is above 2^40");
    s.last_frame_index = static_cast<std::size_t>(last);
    const std::size_t at_least = s.previous ? s.previous->key.frame_index : last_key_frame.value_or(0);
    if (*s.last_frame_index < at_least) r.corrupt("the last frame index is before the selector's frames");
  }
  r.expect_end("the selector state");
  return s;
}

// ---- labels ----------------------------------------------------------------------------

/// The labels' record (version 5): u8 labelled, u8 has schema, [the schema's labels].
/// Each key image's detections are kept with it, I_{j-1}'s with the selector.
inline void write_labels_record(BinaryWriter& w, bool labelled, const std::optional<LabelSchema>& schema) {
  w.u8(labelled ? 1 : 0);
  w.u8(schema ? 1 : 0);
  if (schema) write_label_list(w, schema->labels());
}

/// Reads the labelled flag and the schema (all versions keep them so), checked against
/// the options' label order.
inline void read_labels_record(BinaryReader& r, const MemoryOptions& o, bool& labelled,
                               std::optional<LabelSchema>& schema) {
  const std::uint8_t flag = r.u8("labelled flag");
  if (flag > 1) r.corrupt("labelled flag is not 0 or 1");
  labelled = flag == 1;
  const std::uint8_t has_schema = r.u8("schema flag");
  if (has_schema > 1) r.corrupt("schema flag is not 0 or 1");
  if (has_schema == 1) {
    std::vector<int> labels = read_label_list(r, "schema label count");
    if (!o.labels.order.empty() && labels != o.labels.order) r.corrupt("the schema is not the given label order");
    try {
      schema = LabelSchema(std::move(labels));
    } catch (const Error& e) {
      r.corrupt(e.what());
    }
  } else if (!o.labels.order.empty()) {
    r.corrupt("a given label order but no schema");
  }
}

// ---- sessions --------------------------------------------------------------------------

/// The sessions after the first (which starts at key image 0 and frame 0): u32 n, n x {u64
/// first key image, u64 first frame}.
inline void write_sessions_record(BinaryWriter& w, const std::vector<MemorySession>& sessions) {
  w.u32(static_cast<std::uint32_t>(sessions.size() - 1));
  for (std::size_t i = 1; i < sessions.size(); ++i) {
    w.u64(sessions[i].first_key);
    w.u64(sessions[i].first_frame);
  }
}

/// Checks that session `s` (index i > 0) starts after `before` and at or before the end of
/// a memory of `keys` key images and `frames` frames: the first frame of a session is a
/// key image, so every session but the last holds one, and the last holds none only
/// while no frame was pushed into it.
inline void check_session(BinaryReader& r, std::size_t i, const MemorySession& s, const MemorySession& before,
                          std::size_t keys, std::size_t frames) {
  if (s.first_key <= before.first_key || s.first_frame <= before.first_frame || s.first_key > keys ||
      s.first_frame > frames || (s.first_key == keys) != (s.first_frame == frames))
    r.corrupt("session " + std::to_string(i) + " does not start after session " + std::to_string(i - 1) +
              " (key image " + std::to_string(s.first_key) + ", frame " + std::to_string(s.first_frame) + ")");
}

inline std::vector<MemorySession> read_sessions_record(BinaryReader& r, std::size_t keys, std::size_t frames) {
  const std::uint32_t n = r.u32("session count");
  r.require_items(n, 16, "session count");
  std::vector<MemorySession> out(1);
  for (std::uint32_t i = 0; i < n; ++i) {
    MemorySession s;
    s.first_key = static_cast<std::size_t>(r.u64("session's first key image"));
    s.first_frame = static_cast<std::size_t>(r.u64("session's first frame"));
    check_session(r, i + 1, s, out.back(), keys, frames);
    out.push_back(s);
  }
  r.expect_end("the sessions");
  return out;
}

// ---- the vocabulary --------------------------------------------------------------------

/// u8 has vocabulary; [u64 length, its file's bytes (place/vocabulary.hpp)].
inline void write_vocabulary_record(BinaryWriter& w, const AnyVocabulary& v) {
  w.u8(v.empty() ? 0 : 1);
  if (v.empty()) return;
  const std::string bytes = v.serialize();
  w.u64(bytes.size());
  w.bytes(bytes);
}

inline std::shared_ptr<const AnyVocabulary> read_vocabulary_record(BinaryReader& r) {
  const std::uint8_t has = r.u8("vocabulary flag");
  if (has > 1) r.corrupt("vocabulary flag is not 0 or 1");
  auto out = std::make_shared<const AnyVocabulary>();
  if (has == 1) {
    const std::uint64_t len = r.u64("vocabulary length");
    out = std::make_shared<const AnyVocabulary>(AnyVocabulary::deserialize(r.bytes(len, "vocabulary"), r.source() + " vocabulary"));
  }
  r.expect_end("the vocabulary");
  return out;
}

// ---- the GCS ---------------------------------------------------------------------------

/// u8 has GCS; [MemoryGcs::bytes()].
inline void write_gcs_record(BinaryWriter& w, const std::optional<MemoryGcs>& gcs) {
  w.u8(gcs ? 1 : 0);
  if (gcs) w.bytes(gcs->bytes());
}

/// Reads write_gcs_record()'s bytes for key images with these poses.
inline std::optional<MemoryGcs> read_gcs_record(BinaryReader& r, const std::vector<OdometryPose>& poses) {
  const std::uint8_t has = r.u8("GCS flag");
  if (has > 1) r.corrupt("GCS flag is not 0 or 1");
  if (has == 0) {
    r.expect_end("the GCS flag");
    return std::nullopt;
  }
  return MemoryGcs::read(r, poses);
}

}  // namespace vmap::detail
