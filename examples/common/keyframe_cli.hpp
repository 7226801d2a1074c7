#pragma once

// Options and helpers shared by `vmap build` and `vmap sweep` (and the key-image
// benchmark): the policy choice from the command line, the F-matrix options, and a
// progress line on stderr.

#include "common/policies.hpp"

#include <vmap/core/error.hpp>
#include <vmap/geometry/fundamental.hpp>
#include <vmap/keyframe/selector.hpp>

#include <CLI/CLI.hpp>

#include <unistd.h>

#include <cstddef>
#include <cstdio>
#include <optional>
#include <string>

namespace vmap::examples {

/// What both subcommands read from the command line.
struct KeyframeArgs {
  std::string input;
  std::string features = "orb";
  std::string model;
  int nfeatures = 1000;
  std::string estimator = "magsac";
  std::string rule = "previous";
  std::size_t start = 0;
  std::size_t end = 0;  // 0: to the end
  std::size_t stride = 1;
  bool json = false;

  [[nodiscard]] DescriptorChoice descriptor() const { return {features, nfeatures, model}; }
};

inline void add_keyframe_options(CLI::App& app, KeyframeArgs& a) {
  app.add_option("INPUT", a.input, "Video file, image folder, list of image paths, or TUM rgb.txt")->required();
  app.add_option("--features", a.features, "Descriptor: orb, akaze, sift, xfeat or xfeat-dense (the last two need --model)")->capture_default_str();
  app.add_option("--model", a.model, "Model file of a learned descriptor");
  app.add_option("--nfeatures", a.nfeatures, "Keypoint budget per image (ORB, SIFT; top-k for XFeat)")
      ->capture_default_str()
      ->check(CLI::PositiveNumber);
  app.add_option("--estimator", a.estimator, "F-matrix estimation: magsac, ransac, lmeds or 8point")
      ->capture_default_str();
  app.add_option("--rule", a.rule, "New key image: previous (eq. 6) or current (Algorithm 1) frame")
      ->capture_default_str();
  app.add_option("--start", a.start, "First frame index to read");
  app.add_option("--end", a.end, "One past the last frame index to read (0: to the end)");
  app.add_option("--stride", a.stride, "Read every stride-th frame")->check(CLI::PositiveNumber);
  app.add_flag("--json", a.json, "Print one JSON object instead of tables");
}

inline KeyRule parse_rule(const std::string& name) {
  if (name == "previous") return KeyRule::previous_frame;
  if (name == "current") return KeyRule::current_frame;
  detail::fail("--rule: unknown rule '" + name + "' (choose previous or current)");
}

/// The paper's verification: F-matrix, 1 px, 0.99; the homography degeneracy check is
/// off because the selection does not use it.
inline FundamentalEstimator make_estimator(const std::string& method) {
  return FundamentalEstimator({.method = parse_method(method), .check_degeneracy = false});
}

inline FrameSourceOptions source_options(const KeyframeArgs& a, bool grey) {
  FrameSourceOptions o;
  o.start = a.start;
  if (a.end > 0) o.end = a.end;
  o.stride = a.stride;
  o.grey = grey;
  o.on_skip = [](const SkippedFrame& s) {
    std::fprintf(stderr, "vmap: skipping frame %zu (%s): %s\n", s.index, s.name.c_str(), s.reason.c_str());
  };
  return o;
}

/// "frame 120/723, 19 key images" on stderr, rewritten in place, only on a terminal.
class Progress {
 public:
  explicit Progress(std::optional<std::size_t> total) : total_(total), tty_(isatty(STDERR_FILENO) != 0) {}
  void update(std::size_t frames, std::size_t keys) {
    if (!tty_ || (frames % 10 != 0)) return;
    if (total_)
      std::fprintf(stderr, "\rframe %zu/%zu, %zu key images ", frames, *total_, keys);
    else
      std::fprintf(stderr, "\rframe %zu, %zu key images ", frames, keys);
    std::fflush(stderr);
    shown_ = true;
  }
  void done() {
    if (shown_) std::fprintf(stderr, "\r%60s\r", "");
    shown_ = false;
  }
  ~Progress() { done(); }

 private:
  std::optional<std::size_t> total_;
  bool tty_;
  bool shown_ = false;
};

}  // namespace vmap::examples
