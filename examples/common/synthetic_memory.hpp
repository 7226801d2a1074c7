#pragma once

// Synthetic large memories for the benchmarks (bench_fleet, bench_view): the records of a
// real memory of one session repeated as further sessions, so that a memory of 100,000 key
// images holds real key images, links, loops and bags of words without mapping 100,000
// frames.

#include <vmap/geometry/pose2.hpp>
#include <vmap/memory/records.hpp>
#include <vmap/memory/visual_memory.hpp>

#include <opencv2/core/affine.hpp>

#include <cstddef>
#include <cstdint>
#include <functional>
#include <variant>

namespace vmap::examples {

/// `r` (the whole records of a memory of one session) repeated `copies` times, each copy a
/// session of its own: synthetic earlier runs, real key images repeated. The copies after
/// the first run_link_candidates keep their bags of words but not their features: a
/// query's candidates are the best heavy scores, ties to the lowest key image, so a
/// copy's features are read only when fewer copies before it tie with it, and no query
/// verifies more than run_link_candidates. This keeps 100,000 key images within a .vmem
/// file's 2 GB and the machine's RAM. `shift(c)`, when given, moves copy c's poses (a
/// translation in the world), so that the runs do not lie on one another on a map.
[[nodiscard]] inline MemoryRecords repeated_records(const MemoryRecords& r, std::size_t copies,
                                                    const std::function<cv::Vec3d(std::size_t)>& shift = {}) {
  MemoryRecords out = r;
  const std::size_t m = r.keys.size();
  std::vector<KeyImageRecord> bare = r.keys;
  for (auto& k : bare) k.key.features = Features{};
  const auto moved = [&](OdometryPose p, std::size_t c) {
    if (!shift) return p;
    const cv::Vec3d d = shift(c);
    if (auto* a = std::get_if<cv::Affine3d>(&p)) *a = cv::Affine3d(a->rotation(), a->translation() + d);
    if (auto* f = std::get_if<Pose2>(&p)) *f = Pose2(f->x() + d[0], f->y() + d[1], f->theta());
    return p;
  };
  for (std::size_t c = 1; c < copies; ++c) {
    const auto& keys = c < run_link_candidates ? r.keys : bare;
    for (KeyImageRecord k : keys) {
      k.pose = moved(k.pose, c);
      out.keys.push_back(std::move(k));
    }
    out.links.push_back(KeyPair{});  // no link across sessions
    out.links.insert(out.links.end(), r.links.begin(), r.links.end());
    for (LoopEdge e : r.loops) {
      e.from = static_cast<std::uint32_t>(e.from + c * m);
      e.link.key = static_cast<std::uint32_t>(e.link.key + c * m);
      out.loops.push_back(e);
    }
    out.bows.insert(out.bows.end(), r.bows.begin(), r.bows.end());
    out.sessions.push_back({c * m, c * r.frames});
  }
  out.frames = copies * r.frames;
  return out;
}

}  // namespace vmap::examples
