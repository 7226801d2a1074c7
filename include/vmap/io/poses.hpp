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
#include <vmap/io/timestamps.hpp>

#include <opencv2/core.hpp>

#include <algorithm>
#include <charconv>
#include <cmath>
#include <concepts>
#include <numeric>
#include <cstddef>
#include <cstdint>
#include <cstdio>
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
enum class CameraPoseFormat { tum, kitti, euroc };

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

namespace detail {

/// True when the first line that is not empty or a '#' comment starts with a whole
/// number followed by ',': an ASL / EuRoC CSV (nanosecond times).
inline bool is_euroc_csv(std::string_view text) {
  bool euroc = false, decided = false;
  for_each_line(text, [&](std::string_view line, std::size_t) {
    const std::size_t first = line.find_first_not_of(" \t\r");
    if (decided || first == std::string_view::npos || line[first] == '#') return;
    decided = true;
    const std::size_t comma = line.find(',', first);
    euroc = comma != std::string_view::npos && comma > first &&
            line.substr(first, comma - first).find_first_not_of("0123456789") == std::string_view::npos;
  });
  return euroc;
}

}  // namespace detail

/// Poses from an ASL / EuRoC CSV such as `mav0/state_groundtruth_estimate0/data.csv`:
/// `timestamp [ns], p_x, p_y, p_z, q_w, q_x, q_y, q_z[, ...]` a line (comma-separated,
/// the quaternion's w first; further columns such as velocities and biases are ignored),
/// '#' header lines skipped. The pose is the body's (EuRoC: the IMU's) in the world.
[[nodiscard]] inline std::vector<CameraPose> parse_euroc_poses(std::string_view text,
                                                               const std::string& name = "<poses>") {
  std::vector<CameraPose> out;
  detail::for_each_line(text, [&](std::string_view line, std::size_t line_no) {
    const std::size_t first = line.find_first_not_of(" \t\r");
    if (first == std::string_view::npos || line[first] == '#') return;
    const std::string where = name + ":" + std::to_string(line_no) + ": ";
    std::vector<std::string_view> fields;
    for (std::size_t i = first;;) {
      const std::size_t comma = line.find(',', i);
      std::string_view f = line.substr(i, (comma == std::string_view::npos ? line.size() : comma) - i);
      while (!f.empty() && (f.front() == ' ' || f.front() == '\t')) f.remove_prefix(1);
      while (!f.empty() && (f.back() == ' ' || f.back() == '\t' || f.back() == '\r')) f.remove_suffix(1);
      fields.push_back(f);
      if (comma == std::string_view::npos || fields.size() > 64) break;
      i = comma + 1;
    }
    if (fields.size() < 8)
      detail::fail(where + std::to_string(fields.size()) +
                   " fields, an ASL / EuRoC pose has at least 8 (timestamp [ns], p_x, p_y, p_z, q_w, q_x, q_y, q_z)");
    std::uint64_t ns = 0;
    const auto [tp, tec] = std::from_chars(fields[0].data(), fields[0].data() + fields[0].size(), ns);
    if (tec != std::errc() || tp != fields[0].data() + fields[0].size())
      detail::fail(where + "'" + std::string(fields[0]) + "' is not a timestamp in whole nanoseconds");
    double v[7];
    for (std::size_t k = 0; k < 7; ++k) {
      const std::string_view tok = fields[k + 1];
      const auto [ptr, ec] = std::from_chars(tok.data(), tok.data() + tok.size(), v[k]);
      if (ec != std::errc() || ptr != tok.data() + tok.size() || !std::isfinite(v[k]))
        detail::fail(where + "'" + std::string(tok) + "' is not a finite number");
    }
    if (v[3] * v[3] + v[4] * v[4] + v[5] * v[5] + v[6] * v[6] < 1e-12)
      detail::fail(where + "the quaternion (q_w q_x q_y q_z) is zero");
    out.push_back({seconds_from_nanoseconds(ns), {v[0], v[1], v[2]}, rotation_from_quaternion(v[4], v[5], v[6], v[3])});
  });
  if (out.empty()) detail::fail(name + ": holds no pose");
  return out;
}

/// The format of pose text by its first pose line (8 numbers = TUM, 12 or 13 = KITTI,
/// a whole number and a comma first = ASL / EuRoC CSV).
[[nodiscard]] inline CameraPoseFormat guess_camera_pose_format(std::string_view text,
                                                               const std::string& name = "<poses>") {
  if (detail::is_euroc_csv(text)) return CameraPoseFormat::euroc;
  const auto lines = detail::parse_pose_lines(text, name);
  const std::size_t n = lines.front().values.size();
  if (const auto f = camera_pose_format_for(n)) return *f;
  detail::fail(detail::pose_line_prefix(name, lines.front()) + std::to_string(n) +
               " numbers a line is neither TUM (8) nor KITTI (12 or 13)");
}

[[nodiscard]] inline std::vector<CameraPose> parse_camera_poses(std::string_view text, CameraPoseFormat format,
                                                                const std::string& name = "<poses>") {
  switch (format) {
    case CameraPoseFormat::tum: return parse_tum_poses(text, name);
    case CameraPoseFormat::kitti: return parse_kitti_poses(text, name);
    case CameraPoseFormat::euroc: return parse_euroc_poses(text, name);
  }
  detail::fail(name + ": unknown pose format");
}

/// A TUM pose file; a missing file is an Error naming it.
[[nodiscard]] inline std::vector<CameraPose> load_tum_poses(const std::filesystem::path& path) {
  return parse_tum_poses(read_text_file(path, "pose file"), path.string());
}

/// A KITTI pose file (e.g. poses/07.txt); a missing file is an Error naming it.
[[nodiscard]] inline std::vector<CameraPose> load_kitti_poses(const std::filesystem::path& path) {
  return parse_kitti_poses(read_text_file(path, "pose file"), path.string());
}

/// A TUM, KITTI or ASL / EuRoC pose file, the format guessed from its first pose line.
[[nodiscard]] inline std::vector<CameraPose> load_camera_poses(const std::filesystem::path& path) {
  const std::string text = read_text_file(path, "pose file");
  return parse_camera_poses(text, guess_camera_pose_format(text, path.string()), path.string());
}

/// Anything with a time in seconds: CameraPose, som's TimedPose, ...
template <class P>
concept Timestamped = requires(const P& p) {
  { p.timestamp } -> std::convertible_to<double>;
};

/// Ground truth by timestamp: for each frame time, the index of the pose nearest in time
/// if it is at most `tolerance` seconds away, else nullopt (the frame has no ground
/// truth). TUM's ground truth runs at 100 Hz and its images at 30 Hz, and TUM's own
/// associate.py pairs them this way with a 0.02 s default. Equally near poses: the
/// earlier one. The poses need not be sorted. A slack of 1 us on the tolerance absorbs
/// the rounding of printed Unix times (a double resolves 0.24 us at 1.3e9 s).
/// Error: a negative or non-finite tolerance, or a non-finite frame time.
template <Timestamped P>
[[nodiscard]] std::vector<std::optional<std::size_t>> associate_by_timestamp(const std::vector<P>& poses,
                                                                             const std::vector<double>& frame_times,
                                                                             double tolerance = 0.02) {
  detail::check(std::isfinite(tolerance) && tolerance >= 0,
                "associate_by_timestamp: the tolerance must be a finite number >= 0 seconds, got " +
                    std::to_string(tolerance));
  std::vector<std::size_t> order(poses.size());
  std::iota(order.begin(), order.end(), std::size_t{0});
  std::stable_sort(order.begin(), order.end(), [&](std::size_t i, std::size_t j) {
    return static_cast<double>(poses[i].timestamp) < static_cast<double>(poses[j].timestamp);
  });
  std::vector<double> times(order.size());
  for (std::size_t k = 0; k < order.size(); ++k) times[k] = static_cast<double>(poses[order[k]].timestamp);
  const double limit = tolerance + 1e-6;
  std::vector<std::optional<std::size_t>> out(frame_times.size());
  for (std::size_t f = 0; f < frame_times.size(); ++f) {
    const double t = frame_times[f];
    detail::check(std::isfinite(t), "associate_by_timestamp: frame " + std::to_string(f) + " has no finite time");
    const auto it = std::lower_bound(times.begin(), times.end(), t);
    std::optional<std::size_t> best;
    double best_dt = limit;
    if (it != times.begin()) {  // the pose just before t (the earlier one wins a tie)
      const auto k = static_cast<std::size_t>(it - times.begin()) - 1;
      // The first of equal times, so that duplicates resolve to the file's first line.
      std::size_t first = k;
      while (first > 0 && times[first - 1] == times[k]) --first;
      if (t - times[k] <= best_dt) {
        best = order[first];
        best_dt = t - times[k];
      }
    }
    if (it != times.end() && *it - t <= limit && (!best || *it - t < best_dt))
      best = order[static_cast<std::size_t>(it - times.begin())];
    out[f] = best;
  }
  return out;
}

/// The poses of the frames: by order when there are as many poses as frames and
/// `by_order_if_counts_match` (key-frame sets, KITTI, lists without times), otherwise by
/// timestamp (associate_by_timestamp). Every frame must get one: a frame without a pose
/// within the tolerance is an Error naming `poses_name`, the frame and the nearest miss.
template <Timestamped P>
[[nodiscard]] std::vector<P> poses_for_frames(const std::vector<P>& poses, const std::vector<double>& frame_times,
                                              const std::string& poses_name, double tolerance = 0.02,
                                              bool by_order_if_counts_match = true) {
  if (by_order_if_counts_match && poses.size() == frame_times.size()) return poses;
  const auto match = associate_by_timestamp(poses, frame_times, tolerance);
  std::vector<P> out;
  out.reserve(match.size());
  for (std::size_t f = 0; f < match.size(); ++f) {
    if (!match[f]) {
      // Both time ranges: a clock offset or a unit mistake shows at a glance.
      const auto range = [](auto begin, auto end) {
        const auto [lo, hi] = std::minmax_element(begin, end);
        char buf[96];
        std::snprintf(buf, sizeof buf, "%.6f .. %.6f s", *lo, *hi);
        return std::string(buf);
      };
      std::vector<double> pose_times;
      pose_times.reserve(poses.size());
      for (const auto& p : poses) pose_times.push_back(static_cast<double>(p.timestamp));
      char t[48];
      std::snprintf(t, sizeof t, "%.6f", frame_times[f]);
      detail::fail(poses_name + ": no pose within " + std::to_string(tolerance) + " s of frame " + std::to_string(f) +
                   " (time " + t + " s); the " + std::to_string(poses.size()) + " poses cover " +
                   (poses.empty() ? std::string("nothing") : range(pose_times.begin(), pose_times.end())) + ", the " +
                   std::to_string(frame_times.size()) + " frames " + range(frame_times.begin(), frame_times.end()) +
                   " (are both on one clock?)");
    }
    out.push_back(poses[*match[f]]);
  }
  return out;
}

}  // namespace vmap
