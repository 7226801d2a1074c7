#pragma once

// Reading training poses: TUM RGB-D ground truth, KITTI odometry poses, or a plain
// "x y theta" list, each turned into floor poses (Pose2).
//
// Ground planes: TUM's motion-capture frame has z up (in freiburg3_cabinet the camera
// height stays at 1.12 +- 0.10 m (sd) while x and y span metres), so the floor is (x, y)
// and the heading is the camera's optical axis (its z column) projected onto it.
// KITTI's world is camera 0's first frame (x right, y down, z forward), so the floor is
// (x, z) and the heading is the optical axis projected onto (x, z), angle from +x.

#include <vmap/core/error.hpp>
#include <vmap/geometry/pose2.hpp>

#include <Eigen/Core>
#include <Eigen/Geometry>

#include <cmath>
#include <filesystem>
#include <fstream>
#include <initializer_list>
#include <sstream>
#include <stdexcept>
#include <string>
#include <utility>
#include <vector>

namespace vmap {

struct TimedPose {
  double timestamp = 0.0;  ///< TUM / KITTI time, or the line index for x y theta lists
  Pose2 pose;
};

enum class PoseFormat { tum, kitti, xytheta };

namespace detail {

// Numbers of each non-empty, non-comment line; a line with a non-number is an Error.
inline std::vector<std::vector<double>> numeric_lines(const std::filesystem::path& path) {
  std::ifstream in(path);
  if (!in) fail("cannot open pose file '" + path.string() + "'");
  std::vector<std::vector<double>> out;
  std::size_t no = 0;
  for (std::string line; std::getline(in, line);) {
    ++no;
    const auto b = line.find_first_not_of(" \t\r");
    if (b == std::string::npos || line[b] == '#') continue;
    std::istringstream ss(line);
    std::vector<double> v;
    std::string tok;
    while (ss >> tok) {
      try {
        std::size_t used = 0;
        v.push_back(std::stod(tok, &used));
        if (used != tok.size()) throw std::invalid_argument(tok);
      } catch (const std::exception&) {
        fail("pose file '" + path.string() + "' line " + std::to_string(no) + ": '" + tok + "' is not a number");
      }
      if (!std::isfinite(v.back()))
        fail("pose file '" + path.string() + "' line " + std::to_string(no) + ": non-finite value");
    }
    out.push_back(std::move(v));
  }
  if (out.empty()) fail("pose file '" + path.string() + "' holds no pose");
  return out;
}

inline void expect_fields(const std::filesystem::path& path, std::size_t line, std::size_t got,
                          std::initializer_list<std::size_t> allowed, const char* format) {
  for (std::size_t a : allowed)
    if (got == a) return;
  fail("pose file '" + path.string() + "' pose " + std::to_string(line + 1) + ": " + std::to_string(got) +
       " numbers do not make a " + format + " pose");
}

}  // namespace detail

/// TUM: "timestamp tx ty tz qx qy qz qw" (camera to world).
inline std::vector<TimedPose> read_tum_poses(const std::filesystem::path& path) {
  std::vector<TimedPose> out;
  const auto lines = detail::numeric_lines(path);
  for (std::size_t i = 0; i < lines.size(); ++i) {
    const auto& v = lines[i];
    detail::expect_fields(path, i, v.size(), {8}, "TUM");
    Eigen::Quaterniond q(v[7], v[4], v[5], v[6]);
    if (q.norm() < 1e-9) detail::fail("pose file '" + path.string() + "' pose " + std::to_string(i + 1) + ": zero quaternion");
    const Eigen::Vector3d axis = q.normalized().toRotationMatrix().col(2);
    out.push_back({v[0], Pose2(v[1], v[2], std::atan2(axis.y(), axis.x()))});
  }
  return out;
}

/// KITTI: 12 numbers "r11 r12 r13 tx r21 r22 r23 ty r31 r32 r33 tz" (camera to world),
/// optionally preceded by a time.
inline std::vector<TimedPose> read_kitti_poses(const std::filesystem::path& path) {
  std::vector<TimedPose> out;
  const auto lines = detail::numeric_lines(path);
  for (std::size_t i = 0; i < lines.size(); ++i) {
    const auto& v = lines[i];
    detail::expect_fields(path, i, v.size(), {12, 13}, "KITTI");
    const std::size_t o = v.size() == 13 ? 1 : 0;
    const double time = o ? v[0] : static_cast<double>(i);
    // optical axis = third column (r13, r23, r33); floor = (x, z)
    out.push_back({time, Pose2(v[o + 3], v[o + 11], std::atan2(v[o + 10], v[o + 2]))});
  }
  return out;
}

/// "x y theta" (metres, radians) a line.
inline std::vector<TimedPose> read_xytheta_poses(const std::filesystem::path& path) {
  std::vector<TimedPose> out;
  const auto lines = detail::numeric_lines(path);
  for (std::size_t i = 0; i < lines.size(); ++i) {
    detail::expect_fields(path, i, lines[i].size(), {3}, "x y theta");
    out.push_back({static_cast<double>(i), Pose2(lines[i][0], lines[i][1], lines[i][2])});
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
  const auto n = detail::numeric_lines(path).front().size();
  if (n == 8) return PoseFormat::tum;
  if (n == 12 || n == 13) return PoseFormat::kitti;
  if (n == 3) return PoseFormat::xytheta;
  detail::fail("pose file '" + path.string() + "': " + std::to_string(n) +
               " numbers a line is none of TUM (8), KITTI (12/13), x y theta (3)");
}

}  // namespace vmap
