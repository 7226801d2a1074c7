#pragma once

// 3-D camera poses from trajectory files, shared by every method that needs ground
// truth (loop ground truth in lcd/, floor poses for the GCS map in som/):
//
//   TUM RGB-D  "timestamp tx ty tz qx qy qz qw"   camera centre + unit quaternion
//   KITTI      "[time] r11 r12 r13 tx r21 r22 r23 ty r31 r32 r33 tz"
//                                                 row-major 3x4 [R | t]
//
// Both store the camera-to-world transform: a point p in camera coordinates is
// R p + t in the world, so t is the camera centre and R's columns are the camera's
// axes in the world (x right, y down, z = optical axis).
//
// Empty lines and lines starting with '#' are skipped. Any other line must hold exactly
// the format's numbers, all finite; otherwise the Error names "file:line" and what was
// wrong. A file (or text) with no pose at all is an Error too: every caller needs poses.

#include <vmap/core/error.hpp>
#include <vmap/io/atomic_file.hpp>
#include <vmap/io/detail/lines.hpp>

#include <opencv2/core.hpp>

#include <algorithm>
#include <charconv>
#include <cmath>
#include <cstddef>
#include <filesystem>
#include <optional>
#include <string>
#include <string_view>
#include <system_error>
#include <utility>
#include <vector>

namespace vmap {

/// A camera pose: where the camera centre is and how the camera is turned, camera to
/// world (p_world = rotation * p_camera + position).
struct CameraPose {
  double timestamp = 0.0;  ///< file time (seconds); the 0-based pose index for KITTI files without one
  cv::Vec3d position;      ///< camera centre in world coordinates
  cv::Matx33d rotation = cv::Matx33d::eye();  ///< camera to world; column k = camera axis k in the world

  /// The optical axis (camera +z) in world coordinates: rotation's third column.
  [[nodiscard]] cv::Vec3d viewing_direction() const { return {rotation(0, 2), rotation(1, 2), rotation(2, 2)}; }
  /// A point given in camera coordinates, in world coordinates.
  [[nodiscard]] cv::Vec3d to_world(const cv::Vec3d& camera_point) const { return rotation * camera_point + position; }
};

/// The rotation of the quaternion (x, y, z, w), normalised first (TUM files print 4
/// decimals, so their quaternions are unit only to ~1e-4). A zero or non-finite
/// quaternion has no rotation: Error.
[[nodiscard]] inline cv::Matx33d rotation_from_quaternion(double x, double y, double z, double w) {
  const double n2 = x * x + y * y + z * z + w * w;
  detail::check(std::isfinite(n2) && n2 >= 1e-12, "rotation_from_quaternion: the quaternion (" + std::to_string(x) +
                                                       ", " + std::to_string(y) + ", " + std::to_string(z) + ", " +
                                                       std::to_string(w) + ") is zero or not finite");
  // The standard form scaled by 2/|q|^2 (= 2 for a unit quaternion) normalises in one step.
  const double s = 2.0 / n2;
  return {1 - s * (y * y + z * z), s * (x * y - w * z),     s * (x * z + w * y),
          s * (x * y + w * z),     1 - s * (x * x + z * z), s * (y * z - w * x),
          s * (x * z - w * y),     s * (y * z + w * x),     1 - s * (x * x + y * y)};
}

/// The trajectory formats `guess_camera_pose_format` tells apart.
enum class CameraPoseFormat { tum, kitti };

/// The format whose lines hold `numbers` values: 8 = TUM, 12 or 13 = KITTI.
[[nodiscard]] inline std::optional<CameraPoseFormat> camera_pose_format_for(std::size_t numbers) {
  if (numbers == 8) return CameraPoseFormat::tum;
  if (numbers == 12 || numbers == 13) return CameraPoseFormat::kitti;
  return std::nullopt;
}

namespace detail {

/// One pose line of a file: its 1-based line number and its numbers.
struct PoseLine {
  std::size_t line = 0;
  std::vector<double> values;
};

/// The numbers of each line that is neither empty nor a '#' comment. A token that is
/// not a whole number, or a non-finite one, is an Error naming "name:line". Numbers are
/// read with std::from_chars: independent of the C locale (a ',' decimal separator
/// must not silently split 1.5 into 1 and 5).
[[nodiscard]] inline std::vector<PoseLine> parse_pose_lines(std::string_view text, const std::string& name) {
  std::vector<PoseLine> out;
  for_each_line(text, [&](std::string_view line, std::size_t line_no) {
    const std::size_t first = line.find_first_not_of(" \t\r");
    if (first == std::string_view::npos || line[first] == '#') return;
    PoseLine pl{line_no, {}};
    for (std::size_t i = first; i < line.size();) {
      const std::size_t stop = std::min(line.find_first_of(" \t\r", i), line.size());
      const std::string_view tok = line.substr(i, stop - i);
      i = std::min(line.find_first_not_of(" \t\r", stop), line.size());
      const auto where = name + ":" + std::to_string(line_no) + ": ";
      // from_chars takes no leading '+', which printf-style writers may emit.
      const std::string_view digits = tok.size() > 1 && tok[0] == '+' && tok[1] != '-' ? tok.substr(1) : tok;
      double v = 0.0;
      const auto [ptr, ec] = std::from_chars(digits.data(), digits.data() + digits.size(), v);
      if (ec != std::errc() || ptr != digits.data() + digits.size())
        fail(where + "'" + std::string(tok) + "' is not a number");
      if (!std::isfinite(v)) fail(where + "'" + std::string(tok) + "' is not finite");
      pl.values.push_back(v);
    }
    out.push_back(std::move(pl));
  });
  if (out.empty()) fail(name + ": holds no pose");
  return out;
}

[[nodiscard]] inline std::string pose_line_prefix(const std::string& name, const PoseLine& l) {
  return name + ":" + std::to_string(l.line) + ": ";
}

}  // namespace detail

/// Poses from TUM text, `timestamp tx ty tz qx qy qz qw` a line (e.g. TUM's
/// groundtruth.txt). `name` (the file) prefixes error messages.
[[nodiscard]] inline std::vector<CameraPose> parse_tum_poses(std::string_view text,
                                                             const std::string& name = "<poses>") {
  std::vector<CameraPose> out;
  for (const auto& l : detail::parse_pose_lines(text, name)) {
    const auto& v = l.values;
    if (v.size() != 8)
      detail::fail(detail::pose_line_prefix(name, l) + std::to_string(v.size()) +
                   " numbers, a TUM pose has 8 (timestamp tx ty tz qx qy qz qw)");
    if (v[4] * v[4] + v[5] * v[5] + v[6] * v[6] + v[7] * v[7] < 1e-12)
      detail::fail(detail::pose_line_prefix(name, l) + "the quaternion (qx qy qz qw) is zero");
    out.push_back({v[0], {v[1], v[2], v[3]}, rotation_from_quaternion(v[4], v[5], v[6], v[7])});
  }
  return out;
}

/// Poses from KITTI text: 12 numbers, the row-major 3x4 [R | t] (camera to world), or
/// 13 with a leading time. Without a time a pose's timestamp is its 0-based index.
/// R must be a rotation up to print precision (|R^T R - I| <= 1e-3 per entry, det > 0):
/// anything else is a misread file, not a pose.
[[nodiscard]] inline std::vector<CameraPose> parse_kitti_poses(std::string_view text,
                                                               const std::string& name = "<poses>") {
  std::vector<CameraPose> out;
  for (const auto& l : detail::parse_pose_lines(text, name)) {
    const auto& v = l.values;
    if (v.size() != 12 && v.size() != 13)
      detail::fail(detail::pose_line_prefix(name, l) + std::to_string(v.size()) +
                   " numbers, a KITTI pose has 12 (r11 r12 r13 tx r21 r22 r23 ty r31 r32 r33 tz) or 13 (time first)");
    const std::size_t o = v.size() == 13 ? 1 : 0;
    CameraPose p;
    p.timestamp = o ? v[0] : static_cast<double>(out.size());
    for (int r = 0; r < 3; ++r) {
      for (int c = 0; c < 3; ++c) p.rotation(r, c) = v[o + 4 * static_cast<std::size_t>(r) + static_cast<std::size_t>(c)];
      p.position[r] = v[o + 4 * static_cast<std::size_t>(r) + 3];
    }
    const cv::Matx33d e = p.rotation.t() * p.rotation - cv::Matx33d::eye();
    double worst = 0.0;
    for (int k = 0; k < 9; ++k) worst = std::max(worst, std::abs(e.val[k]));
    if (worst > 1e-3 || cv::determinant(p.rotation) <= 0)
      detail::fail(detail::pose_line_prefix(name, l) + "the 3x3 part is not a rotation (|R^T R - I| up to " +
                   std::to_string(worst) + ", det " + std::to_string(cv::determinant(p.rotation)) + ")");
    out.push_back(p);
  }
  return out;
}

/// The format of pose text by its first pose line (8 numbers = TUM, 12 or 13 = KITTI).
[[nodiscard]] inline CameraPoseFormat guess_camera_pose_format(std::string_view text,
                                                               const std::string& name = "<poses>") {
  const auto lines = detail::parse_pose_lines(text, name);
  const std::size_t n = lines.front().values.size();
  if (const auto f = camera_pose_format_for(n)) return *f;
  detail::fail(detail::pose_line_prefix(name, lines.front()) + std::to_string(n) +
               " numbers a line is neither TUM (8) nor KITTI (12 or 13)");
}

[[nodiscard]] inline std::vector<CameraPose> parse_camera_poses(std::string_view text, CameraPoseFormat format,
                                                                const std::string& name = "<poses>") {
  return format == CameraPoseFormat::tum ? parse_tum_poses(text, name) : parse_kitti_poses(text, name);
}

/// A TUM pose file; a missing file is an Error naming it.
[[nodiscard]] inline std::vector<CameraPose> load_tum_poses(const std::filesystem::path& path) {
  return parse_tum_poses(read_text_file(path, "pose file"), path.string());
}

/// A KITTI pose file (e.g. poses/07.txt); a missing file is an Error naming it.
[[nodiscard]] inline std::vector<CameraPose> load_kitti_poses(const std::filesystem::path& path) {
  return parse_kitti_poses(read_text_file(path, "pose file"), path.string());
}

/// A TUM or KITTI pose file, the format guessed from its first pose line.
[[nodiscard]] inline std::vector<CameraPose> load_camera_poses(const std::filesystem::path& path) {
  const std::string text = read_text_file(path, "pose file");
  return parse_camera_poses(text, guess_camera_pose_format(text, path.string()), path.string());
}

}  // namespace vmap
