#pragma once

// A EuRoC / ASL folder made from TUM frames, as the EuRoC MAV data set lays it out:
//
//   mav0/cam0/data/<ns>.png                   8-bit grey images named by their time
//   mav0/cam0/data.csv                        "#timestamp [ns],filename" then "<ns>,<ns>.png"
//   mav0/cam0/sensor.yaml                     the camera (intrinsics, radial-tangential)
//   mav0/state_groundtruth_estimate0/data.csv "#timestamp, p_RS_R_x [m], ..." 17 columns
//
// The times are the TUM times in nanoseconds, the camera TUM's published freiburg1
// calibration, the ground truth TUM's groundtruth.txt with the quaternion's w first.

#include <vmap/core/error.hpp>
#include <vmap/io/frame_source.hpp>

#include <opencv2/imgcodecs.hpp>

#include <cmath>
#include <cstdint>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <sstream>
#include <string>

namespace vmap::test {

/// The freiburg1 camera as EuRoC's sensor.yaml writes a camera (its k3 has no place in
/// EuRoC's four radial-tangential coefficients): examples/data/tum_fr1_sensor.yaml.
inline std::filesystem::path euroc_sensor_yaml() {
  return std::filesystem::path(VMAP_TEST_SOURCE_DIR) / "examples/data/tum_fr1_sensor.yaml";
}

/// Nanoseconds of a TUM time printed with 6 decimals, exactly (no double rounding).
inline std::uint64_t tum_time_ns(const std::string& t) {
  const auto dot = t.find('.');
  std::string frac = dot == std::string::npos ? "" : t.substr(dot + 1);
  frac.resize(9, '0');
  return std::stoull(t.substr(0, dot)) * 1000000000ULL + std::stoull(frac);
}

/// Writes `root`/mav0 from the first `frames` lines of a TUM rgb.txt and, when
/// `groundtruth` is given, its ground truth. Returns `root`/mav0.
inline std::filesystem::path make_euroc_layout(const std::filesystem::path& root, const std::filesystem::path& rgb_txt,
                                               std::size_t frames, const std::filesystem::path& groundtruth = {}) {
  namespace fs = std::filesystem;
  const fs::path mav0 = root / "mav0", cam0 = mav0 / "cam0";
  fs::create_directories(cam0 / "data");
  std::ifstream list(rgb_txt);
  std::ofstream csv(cam0 / "data.csv");
  csv << "#timestamp [ns],filename\n";
  std::string line;
  std::size_t written = 0;
  while (written < frames && std::getline(list, line)) {
    if (line.empty() || line[0] == '#') continue;
    std::istringstream in(line);
    std::string t, path;
    in >> t >> path;
    const std::uint64_t ns = tum_time_ns(t);
    const std::string name = std::to_string(ns) + ".png";
    const cv::Mat grey = cv::imread((rgb_txt.parent_path() / path).string(), cv::IMREAD_GRAYSCALE);
    detail::check(!grey.empty(), "make_euroc_layout: cannot read " + path);
    cv::imwrite((cam0 / "data" / name).string(), grey);
    csv << ns << ',' << name << "\r\n";  // EuRoC's files end their lines with CR LF
    ++written;
  }
  fs::copy_file(euroc_sensor_yaml(), cam0 / "sensor.yaml", fs::copy_options::overwrite_existing);
  if (!groundtruth.empty()) {
    fs::create_directories(mav0 / "state_groundtruth_estimate0");
    std::ofstream gt(mav0 / "state_groundtruth_estimate0" / "data.csv");
    gt << "#timestamp, p_RS_R_x [m], p_RS_R_y [m], p_RS_R_z [m], q_RS_w [], q_RS_x [], q_RS_y [], q_RS_z [], "
          "v_RS_R_x [m s^-1], v_RS_R_y [m s^-1], v_RS_R_z [m s^-1], b_w_RS_S_x [rad s^-1], b_w_RS_S_y [rad s^-1], "
          "b_w_RS_S_z [rad s^-1], b_a_RS_S_x [m s^-2], b_a_RS_S_y [m s^-2], b_a_RS_S_z [m s^-2]\n";
    std::ifstream in(groundtruth);
    while (std::getline(in, line)) {
      if (line.empty() || line[0] == '#') continue;
      std::istringstream row(line);
      std::string t, x, y, z, qx, qy, qz, qw;
      row >> t >> x >> y >> z >> qx >> qy >> qz >> qw;
      gt << tum_time_ns(t) << ',' << x << ',' << y << ',' << z << ',' << qw << ',' << qx << ',' << qy << ',' << qz
         << ",0,0,0,0,0,0,0,0,0\r\n";
    }
  }
  return mav0;
}

}  // namespace vmap::test
