#pragma once

// A virtual room standing in for the Webots room of the GCS localization paper
// (Trujillo-Romero 2024: 6 x 6 m, two laps, 164 images). A square room whose four
// walls carry posters (real photos given by the caller) is seen by a pinhole camera;
// a robot drives laps of a square circuit, looks ahead, picks the nearer wall by
// A-KAZE keypoint counts (nearest_wall.hpp) and takes the picture of that wall. The
// true poses and noisy odometry poses are both returned.
//
// World frame: the room is [0, size] x [0, size] on the floor, z up; theta is measured
// from +x counter-clockwise.

#include <vmap/core/concepts.hpp>
#include <vmap/core/error.hpp>
#include <vmap/geometry/pose2.hpp>
#include <vmap/io/frame_source.hpp>
#include <vmap/som/nearest_wall.hpp>

#include <opencv2/core.hpp>
#include <opencv2/imgproc.hpp>

#include <algorithm>
#include <cmath>
#include <cstdint>
#include <filesystem>
#include <limits>
#include <numbers>
#include <random>
#include <string>
#include <utility>
#include <vector>

namespace vmap {

struct VirtualRoomOptions {
  double size_m = 6.0;            ///< side of the square room (the paper's 6 x 6 m)
  double wall_height_m = 2.5;
  double poster_bottom_m = 0.5;   ///< posters hang in the band [bottom, top] of each wall
  double poster_top_m = 1.8;
  int posters_per_wall = 4;       ///< the room needs 4 * posters_per_wall photos
  double camera_height_m = 1.1;
  cv::Size image_size{320, 240};
  double hfov_deg = 60.0;         ///< horizontal field of view of the pinhole camera
  double look_ahead_hfov_deg = 120.0;  ///< field of view of the forward look that picks the nearer wall
  double texture_px_per_m = 300.0;
  int supersample = 2;            ///< render at this factor and shrink (against aliasing on far walls)
};

/// Loads `count` photos spread evenly over an image folder / list (FrameSource order).
inline std::vector<cv::Mat> load_posters(const std::filesystem::path& source, std::size_t count) {
  detail::check(count >= 1, "load_posters: count must be >= 1");
  auto src = FrameSource::open(source);
  std::vector<cv::Mat> all;
  while (auto f = src.next()) all.push_back(f->image);
  detail::check(all.size() >= count, "load_posters: '" + source.string() + "' holds " + std::to_string(all.size()) +
                                         " images, " + std::to_string(count) + " are needed");
  std::vector<cv::Mat> out;
  for (std::size_t i = 0; i < count; ++i) out.push_back(all[i * all.size() / count]);
  return out;
}

class VirtualRoom {
 public:
  /// `posters`: 4 * posters_per_wall photos (any size, 1 or 3 channels), assigned to the
  /// south, east, north, west walls in that order.
  VirtualRoom(const std::vector<cv::Mat>& posters, const VirtualRoomOptions& options = {}) : o_(options) {
    detail::check(o_.size_m > 0.0 && o_.wall_height_m > 0.0, "VirtualRoomOptions: size_m and wall_height_m must be > 0");
    detail::check(o_.poster_bottom_m >= 0.0 && o_.poster_top_m > o_.poster_bottom_m && o_.poster_top_m <= o_.wall_height_m,
                  "VirtualRoomOptions: need 0 <= poster_bottom_m < poster_top_m <= wall_height_m");
    detail::check(o_.camera_height_m > 0.0 && o_.camera_height_m < o_.wall_height_m,
                  "VirtualRoomOptions: camera_height_m must be inside (0, wall_height_m)");
    detail::check(o_.image_size.width >= 16 && o_.image_size.height >= 16, "VirtualRoomOptions: image_size too small");
    detail::check(o_.hfov_deg > 1.0 && o_.hfov_deg < 170.0 && o_.look_ahead_hfov_deg > 1.0 && o_.look_ahead_hfov_deg < 170.0,
                  "VirtualRoomOptions: hfov_deg and look_ahead_hfov_deg must be in (1, 170)");
    detail::check(o_.texture_px_per_m >= 10.0 && o_.texture_px_per_m <= 2000.0,
                  "VirtualRoomOptions: texture_px_per_m must be in [10, 2000]");
    detail::check(o_.supersample >= 1 && o_.supersample <= 4, "VirtualRoomOptions: supersample must be in [1, 4]");
    detail::check(o_.posters_per_wall >= 1, "VirtualRoomOptions: posters_per_wall must be >= 1");
    const auto needed = static_cast<std::size_t>(4 * o_.posters_per_wall);
    detail::check(posters.size() == needed, "VirtualRoom: " + std::to_string(needed) + " posters needed (4 walls x " +
                                                std::to_string(o_.posters_per_wall) + "), got " +
                                                std::to_string(posters.size()));
    build_atlas(posters);
  }

  [[nodiscard]] const VirtualRoomOptions& options() const noexcept { return o_; }

  /// The picture taken by a camera at (x, y) on the floor looking horizontally along
  /// `camera.theta()`. The camera must be inside the room.
  [[nodiscard]] cv::Mat render(const Pose2& camera) const { return render(camera, o_.hfov_deg); }

  /// The same with another horizontal field of view (degrees, in (1, 170)).
  [[nodiscard]] cv::Mat render(const Pose2& camera, double hfov_deg) const {
    detail::check(hfov_deg > 1.0 && hfov_deg < 170.0, "VirtualRoom::render: hfov_deg must be in (1, 170)");
    const double s = o_.size_m;
    detail::check(camera.x() > 0.0 && camera.x() < s && camera.y() > 0.0 && camera.y() < s,
                  "VirtualRoom::render: the camera is outside the room");
    const int ss = o_.supersample;
    const int w = o_.image_size.width * ss, h = o_.image_size.height * ss;
    const double f = (w / 2.0) / std::tan(hfov_deg * std::numbers::pi / 360.0);
    const double cx = (w - 1) / 2.0, cy = (h - 1) / 2.0;
    const double ct = std::cos(camera.theta()), st = std::sin(camera.theta());
    cv::Mat mapx(h, w, CV_32F), mapy(h, w, CV_32F);
    const double ppm = o_.texture_px_per_m;
    for (int u = 0; u < w; ++u) {
      const double xr = (u - cx) / f;  // right, per unit of forward depth
      // horizontal ray: forward + xr * right, right = (sin, -cos)
      const double dx = ct + xr * st, dy = st - xr * ct;
      double t = std::numeric_limits<double>::infinity();
      int wall = 0;
      auto hit = [&](double tt, int id) {
        if (tt > 0.0 && tt < t) {
          t = tt;
          wall = id;
        }
      };
      if (dy < 0) hit(-camera.y() / dy, 0);
      if (dx > 0) hit((s - camera.x()) / dx, 1);
      if (dy > 0) hit((s - camera.y()) / dy, 2);
      if (dx < 0) hit(-camera.x() / dx, 3);
      const double px = camera.x() + t * dx, py = camera.y() + t * dy;
      // texture column: left-to-right as seen from inside the room (not mirrored)
      const double along = wall == 0 ? s - px : wall == 1 ? s - py : wall == 2 ? px : py;
      const auto col = static_cast<float>(along * ppm);
      for (int v = 0; v < h; ++v) {
        const double height = o_.camera_height_m - (v - cy) / f * t;
        float ax = col, ay = 0.0f;
        if (height < 0.0) {
          ax = 2.0f;
          ay = static_cast<float>(floor_row_);
        } else if (height > o_.wall_height_m) {
          ax = 2.0f;
          ay = static_cast<float>(ceiling_row_);
        } else {
          ay = static_cast<float>(wall * wall_rows_ + (o_.wall_height_m - height) * ppm);
        }
        mapx.at<float>(v, u) = ax;
        mapy.at<float>(v, u) = ay;
      }
    }
    cv::Mat big, out;
    cv::remap(atlas_, big, mapx, mapy, cv::INTER_LINEAR, cv::BORDER_REPLICATE);
    if (ss == 1) return big;
    cv::resize(big, out, o_.image_size, 0, 0, cv::INTER_AREA);
    return out;
  }

  /// Distance from (x, y) to the wall hit by a horizontal ray along `theta`.
  [[nodiscard]] double distance_to_wall(const Pose2& from, double theta) const {
    const double dx = std::cos(theta), dy = std::sin(theta), s = o_.size_m;
    double t = std::numeric_limits<double>::infinity();
    if (dy < 0) t = std::min(t, -from.y() / dy);
    if (dx > 0) t = std::min(t, (s - from.x()) / dx);
    if (dy > 0) t = std::min(t, (s - from.y()) / dy);
    if (dx < 0) t = std::min(t, -from.x() / dx);
    return t;
  }

 private:
  void build_atlas(const std::vector<cv::Mat>& posters) {
    const double ppm = o_.texture_px_per_m;
    const int wall_cols = static_cast<int>(std::lround(o_.size_m * ppm));
    wall_rows_ = static_cast<int>(std::lround(o_.wall_height_m * ppm));
    floor_row_ = 4 * wall_rows_ + 1;
    ceiling_row_ = 4 * wall_rows_ + 4;
    atlas_.create(4 * wall_rows_ + 6, wall_cols, CV_8UC3);
    atlas_.rowRange(floor_row_ - 1, floor_row_ + 2).setTo(cv::Scalar(70, 80, 90));
    atlas_.rowRange(ceiling_row_ - 1, ceiling_row_ + 2).setTo(cv::Scalar(225, 225, 225));
    const cv::Scalar paint[4] = {{170, 185, 200}, {190, 175, 160}, {165, 195, 175}, {200, 200, 175}};
    const double slot = o_.size_m / o_.posters_per_wall;
    const double band = o_.poster_top_m - o_.poster_bottom_m;
    for (int wall = 0; wall < 4; ++wall) {
      cv::Mat tex = atlas_.rowRange(wall * wall_rows_, (wall + 1) * wall_rows_);
      tex.setTo(paint[wall]);
      for (int k = 0; k < o_.posters_per_wall; ++k) {
        const cv::Mat& p = posters[static_cast<std::size_t>(wall * o_.posters_per_wall + k)];
        detail::check(!p.empty(), "VirtualRoom: poster " + std::to_string(wall * o_.posters_per_wall + k) + " is empty");
        cv::Mat bgr;
        if (p.channels() == 1) cv::cvtColor(p, bgr, cv::COLOR_GRAY2BGR);
        else if (p.channels() == 4) cv::cvtColor(p, bgr, cv::COLOR_BGRA2BGR);
        else bgr = p;
        detail::check(bgr.type() == CV_8UC3, "VirtualRoom: posters must be 8-bit images");
        // fit into 90 % of the slot width and the band height, keeping the photo's aspect
        const double aspect = static_cast<double>(bgr.rows) / bgr.cols;
        double pw = 0.9 * slot, ph = pw * aspect;
        if (ph > band) {
          ph = band;
          pw = ph / aspect;
        }
        const double left = k * slot + (slot - pw) / 2.0;
        const double top = o_.wall_height_m - (o_.poster_bottom_m + band / 2.0 + ph / 2.0);
        const cv::Rect r(static_cast<int>(std::lround(left * ppm)), static_cast<int>(std::lround(top * ppm)),
                         static_cast<int>(std::lround(pw * ppm)), static_cast<int>(std::lround(ph * ppm)));
        cv::Mat scaled;
        cv::resize(bgr, scaled, r.size(), 0, 0, cv::INTER_AREA);
        scaled.copyTo(tex(r & cv::Rect(0, 0, tex.cols, tex.rows)));
      }
    }
  }

  VirtualRoomOptions o_;
  cv::Mat atlas_;
  int wall_rows_ = 0;
  int floor_row_ = 0;
  int ceiling_row_ = 0;
};

// ---- the circuit ----------------------------------------------------------------------

/// Laps of a square path inside the room, counter-clockwise, with noise.
struct CircuitOptions {
  double margin_m = 1.0;             ///< distance of the path from the walls
  std::size_t laps = 2;
  std::size_t images_per_lap = 82;   ///< 2 x 82 = the paper's 164 images
  double phase = 0.0;                ///< samples shifted along the path by this fraction of a step
  double path_noise_m = 0.02;        ///< sd of the true position's deviation from the ideal path
  double heading_noise_deg = 2.0;    ///< sd of the true heading's deviation
  double odometry_noise_m = 0.005;   ///< sd of the translation error per odometry step
  double odometry_noise_deg = 0.2;   ///< sd of the rotation error per odometry step
  std::uint64_t seed = 1;
};

/// One sample of the robot: where it really was, and where its odometry says it was.
struct CircuitSample {
  Pose2 truth;
  Pose2 odometry;
};

/// The circuit: truth poses along the square with noise; odometry = the truth
/// increments (Pose2::between) with per-step noise, integrated from the true start.
inline std::vector<CircuitSample> square_circuit(const VirtualRoomOptions& room, const CircuitOptions& c) {
  const double side = room.size_m - 2.0 * c.margin_m;
  detail::check(std::isfinite(c.margin_m) && c.margin_m > 0.0 && side > 0.0,
                "the path's distance from the walls (CircuitOptions.margin_m) must be more than 0 and less than half "
                "the room's size (" + std::to_string(room.size_m / 2.0) + " m), got " + std::to_string(c.margin_m) + " m");
  detail::check(std::isfinite(c.phase), "the circuit's phase (CircuitOptions.phase) is not a finite number");
  detail::check(c.laps >= 1 && c.images_per_lap >= 4, "CircuitOptions: need laps >= 1 and images_per_lap >= 4");
  for (const auto& [value, name] : {std::pair{c.path_noise_m, "path_noise_m"}, std::pair{c.heading_noise_deg, "heading_noise_deg"},
                                    std::pair{c.odometry_noise_m, "odometry_noise_m"},
                                    std::pair{c.odometry_noise_deg, "odometry_noise_deg"}})
    detail::check(std::isfinite(value) && value >= 0.0, std::string("the noise level CircuitOptions.") + name +
                                                            " must be a finite number >= 0, got " + std::to_string(value));
  std::mt19937_64 rng(c.seed);
  std::normal_distribution<double> n01(0.0, 1.0);
  const double deg = std::numbers::pi / 180.0;
  const double step = 4.0 * side / static_cast<double>(c.images_per_lap);
  std::vector<Pose2> truth;
  for (std::size_t k = 0; k < c.laps * c.images_per_lap; ++k) {
    double arc = std::fmod((static_cast<double>(k) + c.phase) * step, 4.0 * side);
    const int edge = std::min(3, static_cast<int>(arc / side));
    arc -= edge * side;
    const double lo = c.margin_m, hi = c.margin_m + side;
    double x = 0, y = 0;
    const double heading = edge * std::numbers::pi / 2.0;
    switch (edge) {
      case 0: x = lo + arc; y = lo; break;
      case 1: x = hi; y = lo + arc; break;
      case 2: x = hi - arc; y = hi; break;
      default: x = lo; y = hi - arc; break;
    }
    x += c.path_noise_m * n01(rng);
    y += c.path_noise_m * n01(rng);
    truth.emplace_back(x, y, heading + c.heading_noise_deg * deg * n01(rng));
  }
  std::vector<CircuitSample> out;
  out.reserve(truth.size());
  Pose2 odo = truth.front();
  out.push_back({truth.front(), odo});
  for (std::size_t k = 1; k < truth.size(); ++k) {
    const Pose2 inc = truth[k - 1].between(truth[k]);
    const Pose2 noisy(inc.x() + c.odometry_noise_m * n01(rng), inc.y() + c.odometry_noise_m * n01(rng),
                      inc.theta() + c.odometry_noise_deg * deg * n01(rng));
    odo = odo * noisy;
    out.push_back({truth[k], odo});
  }
  return out;
}

/// What the robot's camera records at one pose.
struct RoomView {
  cv::Mat image;             ///< the picture of the chosen wall
  Pose2 camera;              ///< the camera pose it was taken from
  NearestWall choice;        ///< keypoint counts of the forward look
};

/// The paper's capture step: look ahead, count A-KAZE keypoints per image half, turn
/// the camera 90 degrees to the side with more (plus `pan_rad`), take the picture.
template <Descriptor D>
RoomView capture_view(const VirtualRoom& room, D& descriptor, const Pose2& robot, double pan_rad = 0.0) {
  detail::check(std::isfinite(pan_rad), "the camera's pan angle (pan_rad) is not a finite number, got " +
                                            std::to_string(pan_rad));
  RoomView v;
  v.choice = nearest_wall(descriptor, room.render(robot, room.options().look_ahead_hfov_deg));
  const double turn = (v.choice.side == WallSide::left ? 1.0 : -1.0) * std::numbers::pi / 2.0;
  v.camera = Pose2(robot.translation(), robot.theta() + turn + pan_rad);
  v.image = room.render(v.camera);
  return v;
}

/// Images and poses recorded along a circuit.
struct RoomRecording {
  std::vector<cv::Mat> images;
  std::vector<Pose2> truth;     ///< robot poses (heading = direction of travel)
  std::vector<Pose2> odometry;  ///< the same by noisy odometry: what the robot believes
  std::vector<NearestWall> choices;
};

/// capture_view at every sample of the circuit.
template <Descriptor D>
RoomRecording record_circuit(const VirtualRoom& room, D& descriptor, const std::vector<CircuitSample>& circuit,
                             double pan_rad = 0.0) {
  RoomRecording r;
  for (const auto& s : circuit) {
    auto v = capture_view(room, descriptor, s.truth, pan_rad);
    r.images.push_back(std::move(v.image));
    r.truth.push_back(s.truth);
    r.odometry.push_back(s.odometry);
    r.choices.push_back(v.choice);
  }
  return r;
}

}  // namespace vmap
