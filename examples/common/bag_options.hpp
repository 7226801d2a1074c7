#pragma once

// Robot bags on the command line: --topic and --record-time, added once to every
// subcommand that reads frames (add_bag_options) and applied wherever a frame source is
// opened (open_frames, with_bag_options); a bag's damage reported on stderr; the calibration of a bag's
// CameraInfo topic when no --camera is given (camera_option).

#include "common/cli_support.hpp"

#include <vmap/io/bag/bag.hpp>
#include <vmap/io/frame_source.hpp>

#include <CLI/CLI.hpp>

#include <cstdio>
#include <filesystem>
#include <optional>
#include <string>

namespace vmap::examples {

/// --topic and --record-time of this run (one subcommand runs per process).
struct BagSelection {
  std::string topic;
  bool record_time = false;
};

inline BagSelection& bag_selection() {
  static BagSelection s;
  return s;
}

inline void add_bag_options(CLI::App& app) {
  app.add_option("--topic", bag_selection().topic,
                 "Image topic of a bag (.bag, .db3, .mcap or a rosbag2 folder) that has several (vmap bag info lists them)");
  app.add_flag("--record-time", bag_selection().record_time,
               "Time a bag's frames by when they were recorded instead of by their header stamps");
}

/// `o` with --topic and --record-time, for a frame source opened on `input` (here or by
/// the library's run-time layer); a bag's damage (a truncated file, a corrupt chunk) is a
/// warning on stderr. --topic on an input that is not a bag is a usage error.
inline FrameSourceOptions with_bag_options(const std::filesystem::path& input, FrameSourceOptions o = {}) {
  const BagSelection& b = bag_selection();
  if (!b.topic.empty() && !is_bag(input))
    usage_error("--topic: '" + input.string() + "' is not a bag (.bag, .db3, .mcap or a rosbag2 folder)");
  o.topic = b.topic;
  o.record_time = b.record_time;
  if (!o.on_warning) o.on_warning = [](const std::string& w) { std::fprintf(stderr, "vmap: warning: %s\n", w.c_str()); };
  return o;
}

/// FrameSource::open with --topic and --record-time (with_bag_options).
inline FrameSource open_frames(const std::filesystem::path& input, FrameSourceOptions o = {}) {
  return FrameSource::open(input, with_bag_options(input, std::move(o)));
}

/// --camera FILE, or else the calibration of the CameraInfo topic beside a bag's image
/// topic (said on stderr, with where it came from), or none.
inline std::optional<CameraOption> camera_option(const std::string& camera, const std::string& input) {
  if (!camera.empty() || input.empty() || !is_bag(input)) return load_camera_option(camera);
  std::string note;
  const auto found = bag_camera(input, bag_selection().topic, &note);
  if (!note.empty()) std::fprintf(stderr, "vmap: %s; the frames are used as raw pixels\n", note.c_str());
  if (!found) return std::nullopt;
  std::fprintf(stderr, "vmap: camera calibration from %s (--camera FILE overrides it)\n", found->source.c_str());
  return CameraOption{bag_camera_source(input, found->topic), found->camera};
}

}  // namespace vmap::examples
