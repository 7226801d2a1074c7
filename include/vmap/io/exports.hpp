#pragma once

// Results in the formats other tools read:
//
//   key images      "frame_index name timestamp" a line
//   TUM trajectory  "timestamp tx ty tz qx qy qz qw" a line (evo, TUM's tools; read back
//                   by load_tum_poses): the key images' poses with their frame times.
//   loop pairs      "query_time match_time query_name match_name inliers" a line: each
//                   loop edge as the two frames' timestamps and names.
//   g2o             "VERTEX_SE3:QUAT id x y z qx qy qz qw" a line per pose, and
//                   "EDGE_SE3:QUAT from to dx dy dz qx qy qz qw I11 I12 .. I66" a line
//                   (g2o's and GTSAM's readers): a constraint between two key images,
//                   the pose of `to` in the frame of `from`, with the upper triangle of
//                   a 6x6 information matrix (translation first, then the quaternion's
//                   vector part, as g2o's EdgeSE3 measures its error).
//
// Numbers are printed in the shortest decimal form that reads back as the same double
// (std::to_chars: "1305031229.528748", not "1305031229.528748035"), in fixed notation and
// independent of the C locale; frame times exactly, from their whole nanoseconds
// (Frame::time_ns: "1403636579.763555584", "1305031229.528748"). Names are one token: white
// space in a name is written as '_', an empty name as '-'.

#include <vmap/core/error.hpp>
#include <vmap/io/poses.hpp>
#include <vmap/io/timestamps.hpp>
#include <vmap/keyframe/visual_map.hpp>

#include <opencv2/core.hpp>

#include <algorithm>
#include <array>
#include <cmath>
#include <cstddef>
#include <cstdint>
#include <charconv>
#include <system_error>
#include <string>
#include <vector>

namespace vmap {

/// The unit quaternion (x, y, z, w) of a rotation matrix, w >= 0 (Shepperd's method:
/// the largest of the four diagonal combinations is divided by, for accuracy).
[[nodiscard]] inline std::array<double, 4> quaternion_from_rotation(const cv::Matx33d& r) {
  const double t = r(0, 0) + r(1, 1) + r(2, 2);
  double x = 0, y = 0, z = 0, w = 0;
  if (t > r(0, 0) && t > r(1, 1) && t > r(2, 2)) {
    const double s = 2.0 * std::sqrt(1.0 + t);
    w = 0.25 * s;
    x = (r(2, 1) - r(1, 2)) / s;
    y = (r(0, 2) - r(2, 0)) / s;
    z = (r(1, 0) - r(0, 1)) / s;
  } else if (r(0, 0) >= r(1, 1) && r(0, 0) >= r(2, 2)) {
    const double s = 2.0 * std::sqrt(std::max(0.0, 1.0 + r(0, 0) - r(1, 1) - r(2, 2)));
    w = (r(2, 1) - r(1, 2)) / s;
    x = 0.25 * s;
    y = (r(0, 1) + r(1, 0)) / s;
    z = (r(0, 2) + r(2, 0)) / s;
  } else if (r(1, 1) >= r(2, 2)) {
    const double s = 2.0 * std::sqrt(std::max(0.0, 1.0 + r(1, 1) - r(0, 0) - r(2, 2)));
    w = (r(0, 2) - r(2, 0)) / s;
    x = (r(0, 1) + r(1, 0)) / s;
    y = 0.25 * s;
    z = (r(1, 2) + r(2, 1)) / s;
  } else {
    const double s = 2.0 * std::sqrt(std::max(0.0, 1.0 + r(2, 2) - r(0, 0) - r(1, 1)));
    w = (r(1, 0) - r(0, 1)) / s;
    x = (r(0, 2) + r(2, 0)) / s;
    y = (r(1, 2) + r(2, 1)) / s;
    z = 0.25 * s;
  }
  const double n = std::sqrt(x * x + y * y + z * z + w * w);
  detail::check(std::isfinite(n) && n > 0, "quaternion_from_rotation: the matrix is not a rotation");
  const double sign = w < 0 ? -1.0 : 1.0;
  return {sign * x / n, sign * y / n, sign * z / n, sign * w / n};
}

namespace detail {

inline std::string shortest(double v) {
  char buf[400];  // a fixed-notation double has at most ~330 characters
  const auto r = std::to_chars(buf, buf + sizeof buf, v, std::chars_format::fixed);
  return r.ec == std::errc() ? std::string(buf, r.ptr) : std::string("nan");
}

/// A name as one token of a line: white space as '_', empty as '-'.
inline std::string name_token(std::string s) {
  for (char& c : s)
    if (c == ' ' || c == '\t' || c == '\n' || c == '\r' || c == '\v' || c == '\f') c = '_';
  return s.empty() ? std::string("-") : s;
}

// Appends " field". Written as two appends, not `" " + field`: GCC 12 at -O3 reports a
// false -Wrestrict on operator+(const char*, string&&).
inline void append_field(std::string& out, const std::string& field) {
  out += ' ';
  out += field;
}

}  // namespace detail

/// A TUM trajectory of `poses` (their timestamps, positions and rotations), with a '#'
/// header line. `times_ns` (one per pose, when given) are the exact times printed instead
/// of the poses' seconds.
[[nodiscard]] inline std::string tum_trajectory_text(const std::vector<CameraPose>& poses,
                                                     const std::vector<std::int64_t>* times_ns = nullptr) {
  detail::check(!times_ns || times_ns->size() == poses.size(), "tum_trajectory_text: one time per pose");
  std::string out = "# timestamp tx ty tz qx qy qz qw\n";
  for (std::size_t i = 0; i < poses.size(); ++i) {
    const CameraPose& p = poses[i];
    const auto q = quaternion_from_rotation(p.rotation);
    out += times_ns ? seconds_text((*times_ns)[i]) : detail::shortest(p.timestamp);
    for (double v : {p.position[0], p.position[1], p.position[2], q[0], q[1], q[2], q[3]}) detail::append_field(out, detail::shortest(v));
    out += "\n";
  }
  return out;
}

/// "frame_index name timestamp" per key image, with a '#' header line: the frame each key
/// image came from, its name (file name, "<video>#<index>") and its time in seconds,
/// exact to the nanosecond.
[[nodiscard]] inline std::string key_images_text(const std::vector<KeyImage>& keys) {
  std::string out = "# frame_index name timestamp\n";
  for (const auto& k : keys) {
    out += std::to_string(k.frame_index);
    detail::append_field(out, detail::name_token(k.name));
    detail::append_field(out, seconds_text(k.time_ns));
    out += '\n';
  }
  return out;
}

/// One loop edge between two frames, for the exports.
struct LoopPair {
  std::size_t from = 0;  ///< the newer key image (its index)
  std::size_t to = 0;    ///< the older key image it revisits
  std::int64_t from_time_ns = 0, to_time_ns = 0;  ///< the two frames' times (Frame::time_ns)
  std::string from_name, to_name;
  int inliers = 0;
};

/// The loop edges as frame timestamps and names, with a '#' header line.
[[nodiscard]] inline std::string loop_pairs_text(const std::vector<LoopPair>& loops) {
  std::string out = "# query_time match_time query_name match_name inliers\n";
  for (const auto& l : loops) {
    out += seconds_text(l.from_time_ns);
    detail::append_field(out, seconds_text(l.to_time_ns));
    detail::append_field(out, detail::name_token(l.from_name));
    detail::append_field(out, detail::name_token(l.to_name));
    detail::append_field(out, std::to_string(l.inliers));
    out += '\n';
  }
  return out;
}

/// A g2o VERTEX_SE3:QUAT line: vertex `id` at `pose` (its position and rotation).
[[nodiscard]] inline std::string g2o_vertex_line(std::size_t id, const CameraPose& pose) {
  const auto q = quaternion_from_rotation(pose.rotation);
  std::string out = "VERTEX_SE3:QUAT";
  detail::append_field(out, std::to_string(id));
  for (double v : {pose.position[0], pose.position[1], pose.position[2], q[0], q[1], q[2], q[3]})
    detail::append_field(out, detail::shortest(v));
  out += '\n';
  return out;
}

/// A g2o EDGE_SE3:QUAT line between vertices `from_id` and `to_id`: the measured pose of
/// `to` in the frame of `from` (`rotation`, `translation`), with the upper triangle of
/// the 6x6 `information` matrix over g2o's error (translation, then the quaternion's
/// vector part: g2o_information).
[[nodiscard]] inline std::string g2o_edge_line(std::size_t from_id, std::size_t to_id, const cv::Matx33d& rotation,
                                               const cv::Vec3d& translation, const cv::Matx66d& information) {
  const auto q = quaternion_from_rotation(rotation);
  std::string out = "EDGE_SE3:QUAT";
  detail::append_field(out, std::to_string(from_id));
  detail::append_field(out, std::to_string(to_id));
  for (double v : {translation[0], translation[1], translation[2], q[0], q[1], q[2], q[3]})
    detail::append_field(out, detail::shortest(v));
  for (int i = 0; i < 6; ++i)
    for (int j = i; j < 6; ++j) detail::append_field(out, detail::shortest(information(i, j)));
  out += '\n';
  return out;
}

/// A g2o EDGE_SE3:QUAT line: the pose of `to` in the frame of `from` (T_from^-1 T_to)
/// between vertices `from_id` and `to_id`, with a diagonal information matrix
/// (`translation_information` for x y z, `rotation_information` for the rotation).
[[nodiscard]] inline std::string g2o_edge_line(std::size_t from_id, std::size_t to_id, const CameraPose& from,
                                               const CameraPose& to, double translation_information = 1.0,
                                               double rotation_information = 1.0) {
  cv::Matx66d information = cv::Matx66d::zeros();
  for (int i = 0; i < 6; ++i) information(i, i) = i < 3 ? translation_information : rotation_information;
  return g2o_edge_line(from_id, to_id, from.rotation.t() * to.rotation, from.rotation.t() * (to.position - from.position),
                       information);
}

/// The information matrix of an EDGE_SE3:QUAT whose measurement has covariance
/// `covariance` over a small motion in the measurement's own frame (T exp(e), e = the
/// translation, then a rotation vector): g2o's error for an SE(3) edge is the translation
/// and the vector part of the quaternion (g2o's toVectorMQT), which is half the rotation
/// vector for a small rotation, so the rotation rows are scaled by 1/2 before the inverse.
/// `floor` is added to the variances so that an exact measurement (no residual) keeps a
/// finite information.
[[nodiscard]] inline cv::Matx66d g2o_information(const cv::Matx66d& covariance, double floor = 1e-8) {
  cv::Matx66d J = cv::Matx66d::eye();
  for (int i = 3; i < 6; ++i) J(i, i) = 0.5;
  cv::Matx66d c = J * covariance * J.t();
  for (int i = 0; i < 6; ++i) c(i, i) += floor;
  cv::Matx66d info;
  cv::invert(c, info, cv::DECOMP_SVD);
  return 0.5 * (info + info.t());
}

}  // namespace vmap
