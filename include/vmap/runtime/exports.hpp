#pragma once

// A visual memory's key images and loop edges in the formats other tools read
// (io/exports.hpp), written into a folder:
//
//   key_images.txt   "frame_index name timestamp" a line (every key image)
//   key_images.tum   the key images' poses as a TUM trajectory (only when the memory
//                    holds poses), for evo
//   loops.txt        each loop edge as "query_time match_time query_name match_name
//                    inliers" (a timestamp-pair list)
//   loops.g2o        a pose graph (only when the memory holds poses): VERTEX_SE3:QUAT per
//                    key image with a pose (its pose, the initial estimate), an
//                    EDGE_SE3:QUAT odometry edge between consecutive key images of a
//                    session (their poses' relative motion, with the information of
//                    G2oExportOptions' odometry noise), and an EDGE_SE3:QUAT per loop edge
//                    whose metric pose the memory measures (VisualMemory::loop_pose: the
//                    newer key image placed by PnP against the points of the one it
//                    revisits; the information is the inverse of that pose's covariance).
//                    An optimizer (g2o, GTSAM, Ceres) takes it as it is.
//
// Times are the key images' exact times (KeyImage::time_ns).

#include <vmap/geometry/metric_pose.hpp>
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

/// The pose graph's odometry noise: the poses a memory is given come without an
/// uncertainty, so each odometry edge states this one (standard deviations of the
/// relative motion between consecutive key images, in the poses' units and degrees).
struct G2oExportOptions {
  double odometry_translation_sigma = 0.01;
  double odometry_rotation_sigma_deg = 0.5;
};

/// What export_memory wrote into loops.g2o.
struct G2oExportCounts {
  std::size_t vertices = 0;
  std::size_t odometry_edges = 0;
  std::size_t loop_edges = 0;      ///< loop edges with a metric pose
  std::size_t loops_unmeasured = 0;  ///< loop edges between posed key images without one (PoseAnswer's reason)
};

/// The loop edge's measurement for loops.g2o: the pose of `from` (placed by PnP) in the
/// frame of `to`'s pose, and the information of its covariance in its own frame.
struct LoopMeasurement {
  cv::Matx33d rotation;
  cv::Vec3d translation;
  cv::Matx66d information;
};

/// `from`'s metric pose (`measured`, in the frame of `to`'s session) relative to `to`'s
/// pose, with its information (g2o_information of the covariance carried into `from`'s
/// own frame: a position and a rotation perturbation in the world become R^T of them).
[[nodiscard]] inline LoopMeasurement loop_measurement(const MetricPose& measured, const CameraPose& to) {
  const cv::Matx33d R = measured.rotation();
  cv::Matx66d B = cv::Matx66d::zeros();
  for (int i = 0; i < 3; ++i)
    for (int j = 0; j < 3; ++j) B(i, j) = B(3 + i, 3 + j) = R(j, i);
  return {to.rotation.t() * R, to.rotation.t() * (measured.position() - to.position),
          g2o_information(B * measured.covariance * B.t())};
}

/// Every file name export_memory may write.
[[nodiscard]] inline const std::vector<std::string>& memory_export_files() {
  static const std::vector<std::string> names = {"key_images.txt", "loops.txt", "key_images.tum", "loops.g2o"};
  return names;
}

/// Writes the files of the top of this file for `memory` (a VisualMemory or an AnyMemory)
/// into the folder `dir` (each atomically); key_images.txt only when `key_list`. Returns
/// the names written; `counts`, when given, what loops.g2o holds.
template <class Memory>
std::vector<std::string> export_memory(const Memory& memory, const std::filesystem::path& dir, bool key_list = true,
                                       const G2oExportOptions& g2o = {}, G2oExportCounts* counts = nullptr) {
  detail::check(g2o.odometry_translation_sigma > 0 && g2o.odometry_rotation_sigma_deg > 0,
                "G2oExportOptions: the odometry's standard deviations must be > 0");
  const auto& keys = memory.map().keys;
  G2oExportCounts n;
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
    ++n.vertices;
  }
  // Odometry: consecutive key images of one session, both posed.
  std::string edges;
  const double st = g2o.odometry_translation_sigma, sr = g2o.odometry_rotation_sigma_deg * CV_PI / 180.0;
  cv::Matx66d odometry = cv::Matx66d::zeros();
  for (int i = 0; i < 6; ++i) odometry(i, i) = i < 3 ? st * st : sr * sr;
  const cv::Matx66d odometry_information = g2o_information(odometry, 0.0);
  for (std::size_t k = 1; k < keys.size(); ++k) {
    if (!posed[k - 1] || !posed[k] || memory.session_of(k) != memory.session_of(k - 1)) continue;
    const CameraPose& a = *posed[k - 1];
    const CameraPose& b = *posed[k];
    edges += g2o_edge_line(k - 1, k, a.rotation.t() * b.rotation, a.rotation.t() * (b.position - a.position),
                           odometry_information);
    ++n.odometry_edges;
  }
  std::vector<LoopPair> pairs;
  for (const auto& e : memory.loops()) {
    const auto& a = keys[e.from];
    const auto& b = keys[e.link.key];
    pairs.push_back({e.from, e.link.key, a.time_ns, b.time_ns, a.name, b.name, e.link.inliers});
    if (!posed[e.from] || !posed[e.link.key]) continue;
    const PoseAnswer measured = memory.loop_pose(e);
    if (!measured.pose) {
      ++n.loops_unmeasured;
      continue;
    }
    const LoopMeasurement z = loop_measurement(*measured.pose, *posed[e.link.key]);
    edges += g2o_edge_line(e.link.key, e.from, z.rotation, z.translation, z.information);
    ++n.loop_edges;
  }
  if (counts) *counts = n;
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
