#pragma once

// The visual memory's object labels (LFM-LCD, Zhu et al., Sensors 2021, sec. 3.2-3.3;
// DESIGN.md sec. 1.2; MemoryOptions::labels): whether the frames come with detections,
// each key image's detections, those of the last pushed frame, and the label schema once
// fixed; written to and read from the memory's section "labl" (examples/memory.md, "The
// single-file format (.vmem)") here. The tree is not kept: the loop engine rebuilds it
// from the schema and the key images' detections (LoopEngine::restore).

#include <vmap/core/error.hpp>
#include <vmap/hooks/detection.hpp>
#include <vmap/io/binary.hpp>
#include <vmap/lcd/label_vector.hpp>
#include <vmap/lcd/loop_engine.hpp>
#include <vmap/memory/detail/format.hpp>
#include <vmap/memory/types.hpp>

#include <cstddef>
#include <cstdint>
#include <optional>
#include <string>
#include <utility>
#include <vector>

namespace vmap {

/// What the memory knows of its frames' object labels.
struct MemoryLabels {
  bool labelled = false;                               ///< frames come with detections (the first frame decides)
  std::vector<std::vector<Detection>> key_detections;  ///< per key image
  std::vector<Detection> previous_detections;          ///< of the last pushed frame (eq. 6's I_{j-1})
  std::optional<LabelSchema> schema;                   ///< the given order, or eq. 5's after the sample

  /// "labl" up to the key images' detections: the label options of `options` (with the
  /// loop engine's score threshold, candidate source and m), whether the frames are
  /// labelled, the schema.
  [[nodiscard]] std::string head_bytes(const MemoryOptions& options) const {
    static_assert(detail::field_count<MemoryLabelOptions>() == 3 && detail::field_count<InfluenceOptions>() == 2,
                  "a new label option must be written here and read by read()");
    const MemoryLabelOptions& o = options.labels;
    detail::BinaryWriter w;
    w.f32(options.loops.labels.min_score);
    w.u64(o.sample);
    w.f64(o.influence.min_influence);
    w.f64(o.influence.max_influence);
    w.u8(static_cast<std::uint8_t>(options.loops.index));
    w.u64(options.loops.min_candidates);
    const auto write_labels = [&](const std::vector<int>& labels) {
      w.u32(static_cast<std::uint32_t>(labels.size()));
      for (const int l : labels) w.i32(l);
    };
    write_labels(o.order);
    w.u8(labelled ? 1 : 0);
    w.u8(schema ? 1 : 0);
    if (schema) write_labels(schema->labels());
    return std::move(w).take();
  }

  /// "labl"'s last part: the detections of I_{j-1} only while the selector holds it
  /// (`has_previous`; not when the last frame is the last key image): the only case a
  /// later key image can be that frame.
  [[nodiscard]] std::string previous_bytes(bool has_previous) const {
    detail::BinaryWriter w;
    detail::memory_write_detections(w, has_previous ? previous_detections : std::vector<Detection>{});
    return std::move(w).take();
  }

  /// The whole of "labl".
  [[nodiscard]] std::string bytes(const MemoryOptions& options, bool has_previous) const {
    detail::BinaryWriter w;
    w.bytes(head_bytes(options));
    w.u32(static_cast<std::uint32_t>(key_detections.size()));
    for (const auto& d : key_detections) detail::memory_write_detections(w, d);
    w.bytes(previous_bytes(has_previous));
    return std::move(w).take();
  }

  /// Reads "labl" for a memory of `m` key images whose selector holds an I_{j-1}
  /// (`has_previous`) or not. The label options read replace those of `options`, which
  /// `check` (the memory's check of its options) validates before the rest is read.
  template <class Check>
  [[nodiscard]] static MemoryLabels read(detail::BinaryReader& r, MemoryOptions& options, std::uint32_t m,
                                         bool has_previous, const Check& check) {
    MemoryLabels out;
    MemoryLabelOptions o;
    MemoryOptions all = options;
    all.loops.labels.min_score = r.f32("label min_score");
    o.sample = static_cast<std::size_t>(r.u64("label sample"));
    o.influence.min_influence = r.f64("min_influence");
    o.influence.max_influence = r.f64("max_influence");
    const std::uint8_t index = r.u8("label candidate source");
    if (index > static_cast<std::uint8_t>(CandidateIndex::brute_force)) r.corrupt("unknown candidate source");
    all.loops.index = static_cast<CandidateIndex>(index);
    all.loops.min_candidates = static_cast<std::size_t>(r.u64("min_candidates"));
    const auto read_labels = [&](const char* what) {
      const std::uint32_t n = r.u32(what);
      r.require_items(n, 4, what);
      std::vector<int> labels(n);
      for (int& l : labels) l = r.i32(what);
      return labels;
    };
    o.order = read_labels("label order");
    all.labels = o;
    try {
      options = check(all);
      if (!o.order.empty()) out.schema = LabelSchema(o.order);
    } catch (const Error& e) {
      r.corrupt(e.what());
    }
    const std::uint8_t labelled = r.u8("labelled flag");
    if (labelled > 1) r.corrupt("labelled flag is not 0 or 1");
    out.labelled = labelled == 1;
    const std::uint8_t has_schema = r.u8("schema flag");
    if (has_schema > 1) r.corrupt("schema flag is not 0 or 1");
    if (has_schema == 1) {
      std::vector<int> labels = read_labels("schema label count");
      if (!o.order.empty() && labels != o.order) r.corrupt("the schema is not the given label order");
      try {
        out.schema = LabelSchema(std::move(labels));
      } catch (const Error& e) {
        r.corrupt(e.what());
      }
    } else if (!o.order.empty()) {
      r.corrupt("a given label order but no schema");
    }
    const std::uint32_t n = r.u32("key detection count");
    if (n != m) r.corrupt("detections for " + std::to_string(n) + " key images, the memory has " + std::to_string(m));
    for (std::uint32_t k = 0; k < m; ++k) out.key_detections.push_back(detail::memory_read_detections(r));
    out.previous_detections = detail::memory_read_detections(r);
    r.expect_end("the detections");
    if (!out.labelled) {
      for (const auto& d : out.key_detections)
        if (!d.empty()) r.corrupt("detections in a memory without labels");
      if (!out.previous_detections.empty()) r.corrupt("detections in a memory without labels");
    }
    // Without an I_{j-1} in the selector no later key image can be that frame: its
    // detections are never read.
    if (!has_previous) out.previous_detections.clear();
    if (out.schema && o.order.empty() && (!out.labelled || m < o.sample)) r.corrupt("a schema before its sample");
    if (out.labelled && o.order.empty() && !out.schema && m >= o.sample) r.corrupt("no schema after the sample");
    return out;
  }
};

}  // namespace vmap
