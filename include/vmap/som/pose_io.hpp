#pragma once

// Reading training poses: TUM RGB-D ground truth, KITTI odometry poses (both read as
// 3-D camera poses by io/poses.hpp), or a plain "x y theta" list, each turned into
// floor poses (Pose2).
//
// Ground planes: TUM's motion-capture frame has z up (in freiburg3_cabinet the camera
// height stays at 1.12 +- 0.10 m (sd) while x and y span metres), so the floor is (x, y)
// and the heading is the camera's optical axis (its z column) projected onto it.
// KITTI's world is camera 0's first frame (x right, y down, z forward), so the floor is
// (x, z) and the heading is the optical axis projected onto (x, z), angle from +x.

#include <vmap/core/error.hpp>
#include <vmap/geometry/pose2.hpp>
#include <vmap/io/atomic_file.hpp>
#include <vmap/io/poses.hpp>

#include <cmath>
#include <filesystem>
#include <string>
#include <vector>

namespace vmap {

struct TimedPose {
  double timestamp = 0.0;  ///< TUM / KITTI time, or the line index for x y theta lists
  Pose2 pose;
};

enum class PoseFormat { tum, kitti, xytheta };

/// The floor pose of a camera in a z-up world (TUM): (x, y) and the optical axis's
/// heading in that plane.
[[nodiscard]] inline Pose2 floor_pose_z_up(const CameraPose& camera) {
  const cv::Vec3d d = camera.viewing_direction();
  return Pose2(camera.position[0], camera.position[1], std::atan2(d[1], d[0]));
}

/// The floor pose of a camera in a y-down world (KITTI): (x, z) and the optical axis's
/// heading in that plane, angle from +x.
[[nodiscard]] inline Pose2 floor_pose_y_down(const CameraPose& camera) {
  const cv::Vec3d d = camera.viewing_direction();
  return Pose2(camera.position[0], camera.position[2], std::atan2(d[2], d[0]));
}

/// TUM: "timestamp tx ty tz qx qy qz qw" (camera to world), projected onto (x, y).
inline std::vector<TimedPose> read_tum_poses(const std::filesystem::path& path) {
  std::vector<TimedPose> out;
  for (const CameraPose& c : load_tum_poses(path)) out.push_back({c.timestamp, floor_pose_z_up(c)});
  return out;
}

/// KITTI: 12 numbers "r11 r12 r13 tx r21 r22 r23 ty r31 r32 r33 tz" (camera to world),
/// optionally preceded by a time, projected onto (x, z).
inline std::vector<TimedPose> read_kitti_poses(const std::filesystem::path& path) {
  std::vector<TimedPose> out;
  for (const CameraPose& c : load_kitti_poses(path)) out.push_back({c.timestamp, floor_pose_y_down(c)});
  return out;
}

/// "x y theta" (metres, radians) a line.
inline std::vector<TimedPose> read_xytheta_poses(const std::filesystem::path& path) {
  std::vector<TimedPose> out;
  for (const auto& l : detail::parse_pose_lines(read_text_file(path, "pose file"), path.string())) {
    if (l.values.size() != 3)
      detail::fail(detail::pose_line_prefix(path.string(), l) + std::to_string(l.values.size()) +
                   " numbers, an x y theta pose has 3");
    out.push_back({static_cast<double>(out.size()), Pose2(l.values[0], l.values[1], l.values[2])});
  }
  return out;
}

inline std::vector<TimedPose> read_poses(const std::filesystem::path& path, PoseFormat format) {
  switch (format) {
    case PoseFormat::tum: return read_tum_poses(path);
    case PoseFormat::kitti: return read_kitti_poses(path);
    case PoseFormat::xytheta: return read_xytheta_poses(path);
  }
  detail::fail("read_poses: unknown format");
}

/// The format of a pose file by its first pose line: 8 numbers = TUM, 12 or 13 =
/// KITTI, 3 = x y theta.
inline PoseFormat guess_pose_format(const std::filesystem::path& path) {
  const auto lines = detail::parse_pose_lines(read_text_file(path, "pose file"), path.string());
  const std::size_t n = lines.front().values.size();
  if (n == 3) return PoseFormat::xytheta;
  if (const auto f = camera_pose_format_for(n)) return *f == CameraPoseFormat::tum ? PoseFormat::tum : PoseFormat::kitti;
  detail::fail(detail::pose_line_prefix(path.string(), lines.front()) + std::to_string(n) +
               " numbers a line is none of TUM (8), KITTI (12 or 13), x y theta (3)");
}

}  // namespace vmap
