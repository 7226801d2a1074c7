#pragma once

// A visual memory's key images and loop edges in the formats other tools read
// (io/exports.hpp), written into a folder:
//
//   key_images.txt   "frame_index name timestamp" a line (every key image)
//   key_images.tum   the key images' poses as a TUM trajectory (only when the memory
//                    holds poses), for evo
//   loops.txt        each loop edge as "query_time match_time query_name match_name
//                    inliers" (a timestamp-pair list)
//   loops.g2o        VERTEX_SE3:QUAT per key image with a pose and EDGE_SE3:QUAT per loop
//                    edge between two such key images (only when the memory holds poses);
//                    the edge's relative pose is the one the two key images' poses give
//                    (odometry or ground truth), not a visual measurement
//
// Times are the key images' exact times (KeyImage::time_ns).

#include <vmap/geometry/pose2.hpp>
#include <vmap/io/atomic_file.hpp>
#include <vmap/io/exports.hpp>
#include <vmap/io/poses.hpp>
#include <vmap/memory/types.hpp>

#include <opencv2/core/affine.hpp>

#include <cmath>
#include <cstdint>
#include <filesystem>
#include <optional>
#include <string>
#include <variant>
#include <vector>

namespace vmap {

/// A key image's pose as a 3D pose: an SE(3) pose as it is, an SE(2) floor pose (x, y,
/// theta) as (x, y, 0) turned by theta about z; nothing without a pose.
[[nodiscard]] inline std::optional<CameraPose> pose3(const OdometryPose& p, double timestamp) {
  if (const auto* a = std::get_if<cv::Affine3d>(&p)) return CameraPose{timestamp, a->translation(), a->rotation()};
  if (const auto* f = std::get_if<Pose2>(&p)) {
    const double c = std::cos(f->theta()), s = std::sin(f->theta());
    return CameraPose{timestamp, {f->x(), f->y(), 0.0}, cv::Matx33d(c, -s, 0, s, c, 0, 0, 0, 1)};
  }
  return std::nullopt;
}

/// Every file name export_memory may write.
[[nodiscard]] inline const std::vector<std::string>& memory_export_files() {
  static const std::vector<std::string> names = {"key_images.txt", "loops.txt", "key_images.tum", "loops.g2o"};
  return names;
}

/// Writes the files of the top of this file for `memory` (a VisualMemory or an AnyMemory)
/// into the folder `dir` (each atomically); key_images.txt only when `key_list`. Returns
/// the names written.
template <class Memory>
std::vector<std::string> export_memory(const Memory& memory, const std::filesystem::path& dir, bool key_list = true) {
  const auto& keys = memory.map().keys;
  std::vector<CameraPose> trajectory;
  std::vector<std::int64_t> times;
  std::vector<std::optional<CameraPose>> posed(keys.size());
  std::string vertices;
  for (std::size_t k = 0; k < keys.size(); ++k) {
    posed[k] = pose3(memory.poses()[k], keys[k].timestamp);
    if (!posed[k]) continue;
    trajectory.push_back(*posed[k]);
    times.push_back(keys[k].time_ns);
    vertices += g2o_vertex_line(k, *posed[k]);
  }
  std::vector<LoopPair> pairs;
  std::string edges;
  for (const auto& e : memory.loops()) {
    const auto& a = keys[e.from];
    const auto& b = keys[e.link.key];
    pairs.push_back({e.from, e.link.key, a.time_ns, b.time_ns, a.name, b.name, e.link.inliers});
    if (posed[e.from] && posed[e.link.key]) edges += g2o_edge_line(e.from, e.link.key, *posed[e.from], *posed[e.link.key]);
  }
  std::vector<std::string> written;
  if (key_list) {
    write_file_atomically(dir / "key_images.txt", key_images_text(keys));
    written.push_back("key_images.txt");
  }
  write_file_atomically(dir / "loops.txt", loop_pairs_text(pairs));
  written.push_back("loops.txt");
  if (!trajectory.empty()) {
    write_file_atomically(dir / "key_images.tum", tum_trajectory_text(trajectory, &times));
    write_file_atomically(dir / "loops.g2o", vertices + edges);
    written.push_back("key_images.tum");
    written.push_back("loops.g2o");
  }
  return written;
}

/// export_memory() into the folder `dir` as a whole (io/atomic_file.hpp's
/// AtomicDirectory): the files appear together, and `dir` must be new, empty or an
/// earlier vmap output holding only its own files, so that an export never replaces a
/// file of anyone else's (`vmap memory export --out` writes its folder so). Returns the
/// names written.
template <class Memory>
std::vector<std::string> export_memory_folder(const Memory& memory, const std::filesystem::path& dir) {
  AtomicDirectory out(dir);
  std::vector<std::string> written = export_memory(memory, out.path());
  out.commit();
  return written;
}

}  // namespace vmap
