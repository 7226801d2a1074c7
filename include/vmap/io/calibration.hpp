#pragma once

// Camera calibration files, read into a vmap::Camera (geometry/camera.hpp):
//
//   ORB-SLAM YAML  OpenCV FileStorage, `Camera.fx` ... (ORB-SLAM2, TUM1-3.yaml) or
//                  `Camera1.fx` ... (ORB-SLAM3 File.version "1.0"); `Camera.type`
//                  "PinHole" (k1 k2 p1 p2 [k3]), "KannalaBrandt8" (fisheye k1..k4) or
//                  "Rectified" (no distortion); `Camera.width` / `Camera.height` optional
//   ROS            camera_info YAML: `camera_matrix: {data: [9]}`, `distortion_model:
//                  plumb_bob | rational_polynomial | equidistant | fisheye`,
//                  `distortion_coefficients: {data: [...]}`, `image_width` / `image_height`
//   KITTI          calib.txt: `P0: <12 numbers>`, the 3x4 projection of rectified camera 0
//                  (no distortion); `read_kitti_camera` takes another P1..P3
//   Kalibr / ASL   a EuRoC `sensor.yaml` (`intrinsics: [fu, fv, cu, cv]`, `resolution:
//                  [w, h]`, `distortion_model: radial-tangential | equidistant`,
//                  `distortion_coefficients: [...]`) or a Kalibr camchain
//                  (`cam0: {intrinsics, resolution, distortion_model: radtan | equidistant,
//                  distortion_coeffs}`; `parse_kalibr_camera` takes another camN)
//
// `read_camera` tells them apart by their content. A bad file is a vmap::Error naming
// the file and the missing or bad key (or "file:line" for KITTI).

#include <vmap/core/error.hpp>
#include <vmap/geometry/camera.hpp>
#include <vmap/io/atomic_file.hpp>
#include <vmap/io/detail/lines.hpp>
#include <vmap/io/yaml_limits.hpp>

#include <opencv2/core.hpp>

#include <algorithm>
#include <charconv>
#include <cmath>
#include <cstddef>
#include <exception>
#include <filesystem>
#include <optional>
#include <string>
#include <string_view>
#include <system_error>
#include <vector>

namespace vmap {

enum class CalibrationFormat { orbslam, ros, kitti, kalibr };

namespace detail {

/// YAML text with every "indentless" block sequence indented: PyYAML (Kalibr, ROS tools)
/// writes the items of a list at the indentation of its key,
///     T_cn_cnm1:
///     - [1, 0, 0, 0]
/// which is valid YAML that OpenCV's reader rejects; two more spaces make it
/// `  - [1, 0, 0, 0]`, the same document.
inline std::string indent_block_sequences(std::string_view text) {
  std::string out;
  out.reserve(text.size() + 64);
  std::optional<std::size_t> key_indent;  // indentation of a "key:" line opening a list
  bool shifting = false;
  for (std::size_t i = 0; i < text.size();) {
    const std::size_t end = std::min(text.find('\n', i), text.size());
    const std::string_view line = text.substr(i, end - i);
    i = end + 1;
    const std::size_t indent = std::min(line.find_first_not_of(' '), line.size());
    const std::string_view body = line.substr(indent);
    const bool item = body.size() >= 2 && body[0] == '-' && (body[1] == ' ' || body[1] == '\t');
    const bool blank = body.empty() || body[0] == '#' || body[0] == '\r';
    if (!blank) {
      // Inside the list: its items at the key's indentation, and their continuation
      // lines (deeper), move together.
      shifting = key_indent && ((item && indent == *key_indent) || (shifting && indent > *key_indent));
      if (!shifting) {
        std::string_view trimmed = body;
        while (!trimmed.empty() && (trimmed.back() == '\r' || trimmed.back() == ' ')) trimmed.remove_suffix(1);
        key_indent = !item && !trimmed.empty() && trimmed.back() == ':' ? std::optional<std::size_t>(indent) : std::nullopt;
      }
    }
    if (shifting && !blank) out += "  ";
    out += line;
    if (end < text.size()) out += '\n';
  }
  return out;
}

/// OpenCV's YAML reader needs the "%YAML:1.0" directive that ROS files do not have.
/// Size and nesting are bounded first (io/yaml_limits.hpp): OpenCV's parser recurses
/// once per level, and never returns on some top levels that are not a map.
inline cv::FileStorage open_yaml_text(const std::string& text, const std::string& name) {
  check_yaml_limits(text, name);
  std::string yaml = indent_block_sequences(text);
  check_yaml_top_level(yaml, name);
  if (yaml.rfind("%YAML", 0) != 0) yaml = "%YAML:1.0\n" + yaml;
  try {
    cv::FileStorage fs(yaml, cv::FileStorage::READ | cv::FileStorage::MEMORY | cv::FileStorage::FORMAT_YAML);
    if (!fs.isOpened()) fail(name + ": cannot be read as a YAML file");
    // Keys are looked up at the top level: OpenCV asserts (throws) on a lookup in a
    // list or a scalar.
    if (!fs.root().isMap()) fail(name + ": not a YAML map of keys");
    return fs;
  } catch (const cv::Exception& e) {
    fail(name + ": not a valid YAML file (" + e.err + ")");
  } catch (const Error&) {
    throw;
  } catch (const std::exception& e) {  // OpenCV's parser lets std::length_error and the like out
    fail(name + ": not a valid YAML file (" + e.what() + ")");
  }
}

inline std::optional<double> yaml_number(const cv::FileNode& node, const std::string& key, const std::string& name) {
  if (node.empty() || node.isNone()) return std::nullopt;
  if (!node.isReal() && !node.isInt()) fail(name + ": key '" + key + "' is not a number");
  return static_cast<double>(node);
}

inline double yaml_required_number(const cv::FileNode& node, const std::string& key, const std::string& name) {
  const auto v = yaml_number(node, key, name);
  if (!v) fail(name + ": missing key '" + key + "'");
  return *v;
}

/// A `data: [...]` sequence of numbers under `key` (ROS matrices).
inline std::vector<double> yaml_data(const cv::FileStorage& fs, const std::string& key, const std::string& name) {
  const cv::FileNode m = fs[key];
  if (m.empty() || m.isNone()) fail(name + ": missing key '" + key + "'");
  if (!m.isMap()) fail(name + ": key '" + key + "' is not a map with 'data'");
  const cv::FileNode d = m["data"];
  if (!d.isSeq()) fail(name + ": key '" + key + ".data' is missing or not a list");
  std::vector<double> out;
  for (const auto& e : d) {
    if (!e.isReal() && !e.isInt()) fail(name + ": key '" + key + ".data' holds a value that is not a number");
    out.push_back(static_cast<double>(e));
  }
  return out;
}

inline cv::Size yaml_image_size(const cv::FileNode& w, const cv::FileNode& h, const std::string& wkey,
                                const std::string& hkey, const std::string& name) {
  const auto width = yaml_number(w, wkey, name);
  const auto height = yaml_number(h, hkey, name);
  if (width.has_value() != height.has_value())
    fail(name + ": give both '" + wkey + "' and '" + hkey + "' or neither");
  if (!width) return {};
  if (!(*width > 0 && *height > 0 && *width <= 2147483647.0 && *height <= 2147483647.0 && *width == std::floor(*width) &&
        *height == std::floor(*height)))
    fail(name + ": '" + wkey + "' and '" + hkey + "' must be positive whole numbers");
  return {static_cast<int>(*width), static_cast<int>(*height)};
}

inline bool is_kitti_line(std::string_view line) {
  const auto first = line.find_first_not_of(" \t");
  if (first == std::string_view::npos) return false;
  line.remove_prefix(first);
  return (line.size() > 3 && line[0] == 'P' && line[1] >= '0' && line[1] <= '3' && line[2] == ':') ||
         line.rfind("P_rect_0", 0) == 0;
}

}  // namespace detail

/// The calibration format of a file's text: KITTI when a line starts with "P0:".."P3:"
/// (or "P_rect_0"), ROS when it names `camera_matrix`, ORB-SLAM when it names
/// `Camera.fx` or `Camera1.fx`.
[[nodiscard]] inline CalibrationFormat guess_calibration_format(const std::string& text,
                                                                const std::string& name = "<calibration>") {
  bool kitti = false;
  detail::for_each_line(text, [&](std::string_view line, std::size_t) { kitti = kitti || detail::is_kitti_line(line); });
  if (kitti) return CalibrationFormat::kitti;
  if (text.find("camera_matrix") != std::string::npos) return CalibrationFormat::ros;
  if (text.find("Camera.fx") != std::string::npos || text.find("Camera1.fx") != std::string::npos)
    return CalibrationFormat::orbslam;
  if (text.find("intrinsics") != std::string::npos) return CalibrationFormat::kalibr;
  detail::fail(name +
               ": not a camera calibration file vmap knows: expected an ORB-SLAM YAML (Camera.fx ...), a ROS "
               "camera_info YAML (camera_matrix ...), a Kalibr camchain or EuRoC sensor.yaml (intrinsics ...) or a "
               "KITTI calib.txt (P0: ...)");
}

/// An ORB-SLAM2 / ORB-SLAM3 settings file (see the header comment).
[[nodiscard]] inline Camera parse_orbslam_camera(const std::string& text, const std::string& name = "<calibration>") {
  const cv::FileStorage fs = detail::open_yaml_text(text, name);
  const std::string prefix = fs["Camera1.fx"].empty() ? "Camera." : "Camera1.";
  const auto num = [&](const std::string& key) { return detail::yaml_required_number(fs[prefix + key], prefix + key, name); };
  const auto opt = [&](const std::string& key) { return detail::yaml_number(fs[prefix + key], prefix + key, name); };
  std::string type = "PinHole";
  if (const cv::FileNode t = fs["Camera.type"]; !t.empty() && !t.isNone()) {
    if (!t.isString()) detail::fail(name + ": key 'Camera.type' is not a string");
    type = static_cast<std::string>(t);
  }
  Camera c;
  c.fx = num("fx");
  c.fy = num("fy");
  c.cx = num("cx");
  c.cy = num("cy");
  if (type == "KannalaBrandt8") {
    c.lens = LensModel::fisheye;
    c.distortion = {num("k1"), num("k2"), num("k3"), num("k4")};
  } else if (type == "PinHole") {
    const bool any = opt("k1") || opt("k2") || opt("p1") || opt("p2") || opt("k3");
    if (any) {
      c.distortion = {num("k1"), num("k2"), num("p1"), num("p2")};
      if (const auto k3 = opt("k3")) c.distortion.push_back(*k3);
    }
  } else if (type != "Rectified") {
    detail::fail(name + ": key 'Camera.type' is '" + type + "'; vmap reads PinHole, KannalaBrandt8 and Rectified");
  }
  c.image_size = detail::yaml_image_size(fs["Camera.width"], fs["Camera.height"], "Camera.width", "Camera.height", name);
  c.validate(name);
  return c;
}

/// A ROS camera_info YAML (camera_calibration's output, Kalibr's ROS export).
[[nodiscard]] inline Camera parse_ros_camera(const std::string& text, const std::string& name = "<calibration>") {
  const cv::FileStorage fs = detail::open_yaml_text(text, name);
  const std::vector<double> k = detail::yaml_data(fs, "camera_matrix", name);
  if (k.size() != 9)
    detail::fail(name + ": key 'camera_matrix.data' has " + std::to_string(k.size()) + " numbers, a 3x3 matrix has 9");
  if (k[1] != 0.0 || k[3] != 0.0 || k[6] != 0.0 || k[7] != 0.0 || k[8] != 1.0)
    detail::fail(name + ": key 'camera_matrix' is not [fx 0 cx; 0 fy cy; 0 0 1] (vmap does not model skew)");
  Camera c;
  c.fx = k[0];
  c.fy = k[4];
  c.cx = k[2];
  c.cy = k[5];
  std::string model = "plumb_bob";
  if (const cv::FileNode m = fs["distortion_model"]; !m.empty() && !m.isNone()) {
    if (!m.isString()) detail::fail(name + ": key 'distortion_model' is not a string");
    model = static_cast<std::string>(m);
  }
  std::vector<double> d;
  if (const cv::FileNode dn = fs["distortion_coefficients"]; !dn.empty() && !dn.isNone())
    d = detail::yaml_data(fs, "distortion_coefficients", name);
  if (model == "equidistant" || model == "fisheye") {
    c.lens = LensModel::fisheye;
    if (d.size() != 4)
      detail::fail(name + ": key 'distortion_coefficients.data' has " + std::to_string(d.size()) +
                   " numbers, the equidistant model has 4 (k1 k2 k3 k4)");
  } else if (model == "plumb_bob" || model == "rational_polynomial") {
    const bool zero = std::all_of(d.begin(), d.end(), [](double x) { return x == 0.0; });
    if (zero) d.clear();  // ROS writes five zeros for rectified images
  } else {
    detail::fail(name + ": key 'distortion_model' is '" + model +
                 "'; vmap reads plumb_bob, rational_polynomial, equidistant and fisheye");
  }
  c.distortion = d;
  c.image_size = detail::yaml_image_size(fs["image_width"], fs["image_height"], "image_width", "image_height", name);
  c.validate(name);
  return c;
}

/// A KITTI calib.txt: the rectified projection `which` ("P0".."P3"), fx = P(0,0),
/// fy = P(1,1), cx = P(0,2), cy = P(1,2), no distortion.
[[nodiscard]] inline Camera parse_kitti_camera(const std::string& text, const std::string& name = "<calibration>",
                                               const std::string& which = "P0") {
  std::optional<Camera> found;
  const std::string key = which + ":";
  detail::for_each_line(text, [&](std::string_view line, std::size_t line_no) {
    const auto first = line.find_first_not_of(" \t");
    if (found || first == std::string_view::npos || line.substr(first).rfind(key, 0) != 0) return;
    std::vector<double> v;
    const std::string where = name + ":" + std::to_string(line_no) + ": ";
    for (std::size_t i = first + key.size(); i < line.size();) {
      i = line.find_first_not_of(" \t\r", i);
      if (i == std::string_view::npos) break;
      const std::size_t stop = std::min(line.find_first_of(" \t\r", i), line.size());
      const std::string_view tok = line.substr(i, stop - i);
      double x = 0.0;
      const auto [ptr, ec] = std::from_chars(tok.data(), tok.data() + tok.size(), x);
      if (ec != std::errc() || ptr != tok.data() + tok.size() || !std::isfinite(x))
        detail::fail(where + "'" + std::string(tok) + "' in '" + which + "' is not a finite number");
      v.push_back(x);
      i = stop;
    }
    if (v.size() != 12)
      detail::fail(where + "'" + which + "' has " + std::to_string(v.size()) + " numbers, a 3x4 projection has 12");
    Camera c;
    c.fx = v[0];
    c.fy = v[5];
    c.cx = v[2];
    c.cy = v[6];
    found = c;
  });
  if (!found) detail::fail(name + ": no '" + key + "' line (a KITTI calib.txt holds P0: .. P3:)");
  found->validate(name);
  return *found;
}

namespace detail {

/// A YAML list of numbers under `key` of `node` (Kalibr's `intrinsics: [...]`).
inline std::vector<double> yaml_list(const cv::FileNode& node, const std::string& key, const std::string& name) {
  const cv::FileNode l = node[key];
  if (l.empty() || l.isNone()) fail(name + ": missing key '" + key + "'");
  if (!l.isSeq()) fail(name + ": key '" + key + "' is not a list");
  std::vector<double> out;
  for (const auto& e : l) {
    if (!e.isReal() && !e.isInt()) fail(name + ": key '" + key + "' holds a value that is not a number");
    out.push_back(static_cast<double>(e));
  }
  return out;
}

}  // namespace detail

/// A Kalibr camchain (`which`: "cam0", "cam1", ...) or an ASL / EuRoC `sensor.yaml`
/// (the camera at the top level); see the header comment. Kalibr writes
/// `distortion_coeffs`, EuRoC `distortion_coefficients`; the models `radtan` /
/// `radial-tangential` (k1 k2 p1 p2) and `equidistant` / `equi` (fisheye k1..k4).
[[nodiscard]] inline Camera parse_kalibr_camera(const std::string& text, const std::string& name = "<calibration>",
                                                const std::string& which = "cam0") {
  const cv::FileStorage fs = detail::open_yaml_text(text, name);
  cv::FileNode cam = fs.root();
  std::string prefix;
  if (cam["intrinsics"].empty()) {
    cam = fs[which];
    prefix = which + ".";
    if (!cam.isMap()) detail::fail(name + ": no 'intrinsics' and no camera '" + which + "' (a Kalibr camchain)");
  }
  if (const cv::FileNode m = cam["camera_model"]; !m.empty() && !m.isNone()) {
    if (!m.isString() || static_cast<std::string>(m) != "pinhole")
      detail::fail(name + ": key '" + prefix + "camera_model' must be 'pinhole' (vmap reads pinhole cameras)");
  }
  const std::vector<double> k = detail::yaml_list(cam, "intrinsics", name);
  if (k.size() != 4)
    detail::fail(name + ": key '" + prefix + "intrinsics' has " + std::to_string(k.size()) +
                 " numbers, expected 4 (fu fv cu cv)");
  Camera c;
  c.fx = k[0];
  c.fy = k[1];
  c.cx = k[2];
  c.cy = k[3];
  std::string model = "radtan";
  if (const cv::FileNode m = cam["distortion_model"]; !m.empty() && !m.isNone()) {
    if (!m.isString()) detail::fail(name + ": key '" + prefix + "distortion_model' is not a string");
    model = static_cast<std::string>(m);
  }
  const std::string dkey = cam["distortion_coeffs"].empty() ? "distortion_coefficients" : "distortion_coeffs";
  std::vector<double> d;
  if (!cam[dkey].empty()) d = detail::yaml_list(cam, dkey, name);
  if (model == "equidistant" || model == "equi") {
    c.lens = LensModel::fisheye;
    if (d.size() != 4)
      detail::fail(name + ": key '" + prefix + dkey + "' has " + std::to_string(d.size()) +
                   " numbers, the equidistant model has 4 (k1 k2 k3 k4)");
  } else if (model == "radtan" || model == "radial-tangential" || model == "none") {
    if (std::all_of(d.begin(), d.end(), [](double x) { return x == 0.0; })) d.clear();
  } else {
    detail::fail(name + ": key '" + prefix + "distortion_model' is '" + model +
                 "'; vmap reads radtan (radial-tangential) and equidistant");
  }
  c.distortion = d;
  if (!cam["resolution"].empty()) {
    const std::vector<double> r = detail::yaml_list(cam, "resolution", name);
    if (r.size() != 2 || !(r[0] >= 1 && r[1] >= 1 && r[0] <= 2147483647.0 && r[1] <= 2147483647.0) || r[0] != std::floor(r[0]) ||
        r[1] != std::floor(r[1]))
      detail::fail(name + ": key '" + prefix + "resolution' must be two positive whole numbers [width, height]");
    c.image_size = {static_cast<int>(r[0]), static_cast<int>(r[1])};
  }
  c.validate(name);
  return c;
}

/// The camera of calibration text of any of the formats of the header comment; the
/// format is told from the content. `name` names the text in errors.
[[nodiscard]] inline Camera parse_camera(const std::string& text, const std::string& name = "<calibration>") {
  try {
    switch (guess_calibration_format(text, name)) {
      case CalibrationFormat::orbslam: return parse_orbslam_camera(text, name);
      case CalibrationFormat::ros: return parse_ros_camera(text, name);
      case CalibrationFormat::kitti: return parse_kitti_camera(text, name);
      case CalibrationFormat::kalibr: return parse_kalibr_camera(text, name);
    }
  } catch (const cv::Exception& e) {  // an OpenCV lookup on a node of an unexpected kind
    detail::fail(name + ": not a calibration file vmap can read (" + e.err + ")");
  }
  detail::fail(name + ": unknown calibration format");
}

/// The camera of a calibration file (`parse_camera`), read with the bounds of every
/// YAML input (io/yaml_limits.hpp). Missing file: Error naming it.
[[nodiscard]] inline Camera read_camera(const std::filesystem::path& path) {
  return parse_camera(read_text_file(path, "calibration file", max_yaml_bytes), path.string());
}

}  // namespace vmap
