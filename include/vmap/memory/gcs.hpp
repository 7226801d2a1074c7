#pragma once

// The visual memory's GCS localizer (Trujillo-Romero 2024, examples/methods.md, sec. 3;
// VisualMemory::train_gcs): trained by som/'s train_pose_map on the key images' own
// features, kept with what it was trained with and on, and written to and read from the
// memory's section "gcsl" (examples/memory.md, "The single-file format (.vmem)") here.

#include <vmap/core/error.hpp>
#include <vmap/core/features.hpp>
#include <vmap/geometry/pose2.hpp>
#include <vmap/io/binary.hpp>
#include <vmap/memory/types.hpp>
#include <vmap/place/vocabulary_tree.hpp>
#include <vmap/som/gcs.hpp>
#include <vmap/som/histogram.hpp>
#include <vmap/som/pose_map.hpp>

#include <cstddef>
#include <cstdint>
#include <string>
#include <utility>
#include <variant>
#include <vector>

namespace vmap {

/// A GCS trained on a memory's key images: the histogram (its vocabulary learned on
/// them), the network with a pose per neuron, and the neuron each key image won.
struct MemoryGcs {
  MemoryGcsOptions options;
  BowHistogram histogram;
  PoseMap<GcsXf> map;
  std::vector<std::uint32_t> keys;   ///< the key images trained on (ascending)
  std::vector<std::size_t> winners;  ///< the neuron each of them won (Algorithm 4)

  /// The position of a query's features (Algorithm 5 with the one image).
  [[nodiscard]] Localization localize(const Features& query) const { return map.localize({histogram(query)}); }

  /// The trained GCS as "gcsl" holds it after its flag: the histogram's options and
  /// vocabulary, the network (which holds its GcsOptions), each key image and winner.
  [[nodiscard]] std::string bytes() const {
    detail::BinaryWriter w;
    const BowHistogramOptions& h = options.histogram;
    w.i32(h.vocabulary.branching);  // depth is always 1: not stored
    w.i32(h.vocabulary.iterations);
    w.u64(h.vocabulary.max_descriptors);
    w.u64(h.vocabulary.seed);
    w.u8(static_cast<std::uint8_t>(h.norm));
    const std::string voc = histogram.vocabulary().serialize();
    w.u64(voc.size());
    w.bytes(voc);
    const std::string net = map.network().serialize();
    w.u64(net.size());
    w.bytes(net);
    w.u32(static_cast<std::uint32_t>(keys.size()));
    for (std::size_t i = 0; i < keys.size(); ++i) {
      w.u32(keys[i]);
      w.u64(winners[i]);
    }
    return std::move(w).take();
  }

  /// Reads bytes() (to the end of the section) for a memory whose key images have
  /// `poses`: the key images trained on must be increasing key images with SE(2) poses,
  /// at least 3, each winning a neuron of the network.
  [[nodiscard]] static MemoryGcs read(detail::BinaryReader& r, const std::vector<OdometryPose>& poses) {
    MemoryGcsOptions o;
    o.histogram.vocabulary.branching = r.i32("histogram words");
    o.histogram.vocabulary.iterations = r.i32("histogram iterations");
    o.histogram.vocabulary.max_descriptors = static_cast<std::size_t>(r.u64("histogram max_descriptors"));
    o.histogram.vocabulary.seed = r.u64("histogram seed");
    const std::uint8_t norm = r.u8("histogram norm");
    if (norm > 1) r.corrupt("unknown histogram norm");
    o.histogram.norm = static_cast<HistogramNorm>(norm);
    const std::uint64_t vlen = r.u64("histogram vocabulary length");
    BinaryVocabularyTree voc = BinaryVocabularyTree::deserialize(r.bytes(vlen, "histogram vocabulary"),
                                                                 r.source() + " histogram vocabulary");
    if (voc.size() == 0) r.corrupt("the histogram vocabulary has no words");
    const std::uint64_t nlen = r.u64("network length");
    GcsXf net = GcsXf::deserialize(r.bytes(nlen, "network"), r.source() + " network");
    if (net.empty()) r.corrupt("the network is not trained");
    if (net.dimension() != voc.size()) r.corrupt("the network's dimension is not the histogram's");
    o.gcs = net.options();
    const std::uint32_t n = r.u32("GCS key count");
    r.require_items(n, 12, "GCS key count");
    std::vector<std::uint32_t> keys(n);
    std::vector<std::size_t> winners(n);
    std::vector<Pose2> key_poses;
    for (std::uint32_t i = 0; i < n; ++i) {
      keys[i] = r.u32("GCS key");
      winners[i] = static_cast<std::size_t>(r.u64("GCS winner"));
      if (keys[i] >= poses.size() || (i > 0 && keys[i] <= keys[i - 1]))
        r.corrupt("GCS key images are not increasing key images");
      const auto* p = std::get_if<Pose2>(&poses[keys[i]]);
      if (!p) r.corrupt("GCS key image " + std::to_string(keys[i]) + " has no SE(2) pose");
      if (winners[i] >= net.size()) r.corrupt("a GCS winner is not a neuron");
      key_poses.push_back(*p);
    }
    r.expect_end("the GCS key images");
    if (n < 3) r.corrupt("a GCS trained on fewer than 3 key images");
    return MemoryGcs{o, BowHistogram(std::move(voc), o.histogram),
                     PoseMap<GcsXf>::from_assignments(std::move(net), winners, key_poses), std::move(keys),
                     std::move(winners)};
  }
};

}  // namespace vmap
