// A robot's visual memory through the public API only (include/vmap/memory): stream a
// video or frame list, keep key images and loop edges, save the memory, "restart" (a new
// object loaded from the file), resume the stream after the last frame the memory saw,
// save again, and localize frames that were held out of the memory.
//
//   robot_memory INPUT MEMORY_FILE [--restart-at 0.5] [--hold-out 10] [--images none|png|jpeg]
//                [--tau 0.3] [--end N] [--within 15] [--detections FILE] [--label-sample 20]
//                [--poses FILE] [--gcs]
//
// Every --hold-out-th frame (index % hold_out == hold_out / 2) is kept out of the memory
// and localized at the end; "near" counts answers whose key image is within --within
// frames of the query.
//
// --detections: object detections per frame (hooks/precomputed_detections.hpp's file,
// e.g. from `vmap detect`): loops are then searched through LFM-LCD's label tree, its
// schema learned from the first --label-sample key images. --poses: a TUM ground-truth
// file standing in for odometry (the pose nearest in time, as an SE(2) floor pose);
// --gcs then trains the GCS localizer on the key images after the restart, and the
// held-out frames get a position estimate too (error against their pose reported).
#include <vmap/vmap.hpp>

#include <CLI/CLI.hpp>

#include <algorithm>
#include <chrono>
#include <cstdio>
#include <filesystem>
#include <iterator>
#include <map>
#include <optional>
#include <string>
#include <vector>

namespace {

using Clock = std::chrono::steady_clock;

double ms_since(Clock::time_point t) { return std::chrono::duration<double, std::milli>(Clock::now() - t).count(); }

struct Args {
  std::string input, memory;
  double restart_at = 0.5;
  std::size_t hold_out = 10;
  std::string images = "none";
  double tau = 0.3;
  std::size_t end = 0;
  std::size_t within = 15;
  std::string detections;
  std::size_t label_sample = 20;
  std::string poses;
  bool gcs = false;
};

/// The odometry stand-in: the pose of `poses` (sorted by time) nearest to `t`.
std::optional<vmap::Pose2> pose_at(const std::vector<vmap::TimedPose>& poses, double t) {
  if (poses.empty()) return std::nullopt;
  auto it = std::lower_bound(poses.begin(), poses.end(), t,
                             [](const vmap::TimedPose& p, double v) { return p.timestamp < v; });
  if (it == poses.end()) --it;
  if (it != poses.begin() && t - std::prev(it)->timestamp < it->timestamp - t) --it;
  return it->pose;
}

struct Inputs {
  std::optional<vmap::PrecomputedDetections> detections;
  std::vector<vmap::TimedPose> poses;
};

vmap::MemoryStep push(vmap::OrbVisualMemory& mem, const vmap::Frame& f, const Inputs& in) {
  vmap::OdometryPose pose;
  if (const auto p = pose_at(in.poses, f.timestamp)) pose = *p;
  if (in.detections) return mem.push(f, pose, in.detections->at(f.index));
  return mem.push(f, pose);
}

/// Pushes the frames of `src` into `mem`, keeping the held-out ones aside; stops after
/// frame index `stop` (inclusive) when given.
std::size_t stream(vmap::FrameSource& src, vmap::OrbVisualMemory& mem, const Args& a, const Inputs& in,
                   std::optional<std::size_t> stop, std::vector<vmap::Frame>& held) {
  std::size_t loops = 0;
  while (auto f = src.next()) {
    if (a.hold_out > 0 && f->index % a.hold_out == a.hold_out / 2)
      held.push_back(std::move(*f));
    else
      loops += push(mem, *f, in).loops.size();
    if (stop && f->index >= *stop) break;
  }
  return loops;
}

int run(const Args& a) {
  vmap::MemoryOptions o;
  o.selector.tau = a.tau;
  const std::map<std::string, vmap::ImageStorage> storage{
      {"none", vmap::ImageStorage::none}, {"png", vmap::ImageStorage::png}, {"jpeg", vmap::ImageStorage::jpeg}};
  o.images = storage.at(a.images);
  o.labels.sample = a.label_sample;
  Inputs in;
  if (!a.detections.empty()) in.detections = vmap::PrecomputedDetections::load(a.detections);
  if (!a.poses.empty()) {
    in.poses = vmap::read_tum_poses(a.poses);
    std::sort(in.poses.begin(), in.poses.end(),
              [](const vmap::TimedPose& x, const vmap::TimedPose& y) { return x.timestamp < y.timestamp; });
  }

  vmap::FrameSourceOptions so{.grey = true};
  if (a.end > 0) so.end = a.end;
  std::vector<vmap::Frame> held;

  // 1. The first part of the stream.
  auto src = vmap::FrameSource::open(a.input, so);
  // total() counts the whole input; --end cuts it.
  const std::size_t total = a.end > 0 ? std::min(a.end, src.total().value_or(a.end)) : src.total().value_or(0);
  const auto stop = static_cast<std::size_t>(a.restart_at * static_cast<double>(total));
  std::size_t loops = 0;
  {
    vmap::OrbVisualMemory mem(o);
    auto t = Clock::now();
    loops += stream(src, mem, a, in, stop, held);
    const double push_ms = ms_since(t);
    t = Clock::now();
    mem.save(a.memory);
    std::printf("run 1: %zu frames, %zu key images, %zu loop edges, %.1f ms per frame; saved in %.1f ms, %ju bytes "
                "(%.0f bytes per key image)\n",
                mem.frames(), mem.key_images(), mem.loops().size(), push_ms / static_cast<double>(mem.frames()),
                ms_since(t), static_cast<std::uintmax_t>(std::filesystem::file_size(a.memory)),
                static_cast<double>(std::filesystem::file_size(a.memory)) / static_cast<double>(mem.key_images()));
  }  // the robot stops: nothing of run 1 survives but the file

  // 2. Restart: a new memory from the file; the stream resumes after its last frame.
  auto t = Clock::now();
  auto mem = vmap::OrbVisualMemory::load(a.memory);
  std::printf("restart: loaded %zu key images in %.1f ms; resuming after frame %zu\n", mem.key_images(), ms_since(t),
              mem.last_frame_index().value_or(0));
  so.start = mem.last_frame_index().value_or(0) + 1;
  if (so.start < so.end) {
    auto rest = vmap::FrameSource::open(a.input, so);
    loops += stream(rest, mem, a, in, std::nullopt, held);
  }
  if (a.gcs) {
    t = Clock::now();
    const auto stats = mem.train_gcs();
    std::printf("GCS: %zu cells trained on %zu key images in %.1f ms\n", stats.cells, mem.gcs_keys().size(),
                ms_since(t));
  }
  mem.save(a.memory);
  std::printf("run 2: %zu frames in all, %zu key images, %zu loop edges (%zu found while streaming)\n", mem.frames(),
              mem.key_images(), mem.loops().size(), loops);
  if (mem.label_schema()) {
    std::printf("labels: schema of %zu labels (", mem.label_schema()->size());
    for (int l : mem.label_schema()->labels()) std::printf(" %d", l);
    std::printf(" ), %zu key images in the tree\n", mem.label_tree().size());
  }

  // 3. Localize the held-out frames.
  std::size_t localized = 0, near = 0, positions = 0;
  double position_error = 0.0;
  t = Clock::now();
  for (const auto& f : held) {
    const auto answer = mem.localize(f.image);
    const auto truth = pose_at(in.poses, f.timestamp);
    if (answer.position && truth) {
      ++positions;
      position_error += (answer.position->pose.translation() - truth->translation()).norm();
    }
    if (!answer.ok()) continue;
    ++localized;
    const std::size_t k = mem.map().keys[answer.best()->key].frame_index;
    if ((k > f.index ? k - f.index : f.index - k) <= a.within) ++near;
  }
  const double per_query = held.empty() ? 0.0 : ms_since(t) / static_cast<double>(held.size());
  std::printf("localize: %zu held-out frames, %zu localized, %zu to a key image within %zu frames (%.1f %%), "
              "%.1f ms per query\n",
              held.size(), localized, near, a.within,
              held.empty() ? 0.0 : 100.0 * static_cast<double>(near) / static_cast<double>(held.size()), per_query);
  if (positions > 0)
    std::printf("GCS: %zu held-out frames with a position, mean error %.3f m\n", positions,
                position_error / static_cast<double>(positions));
  return 0;
}

}  // namespace

int main(int argc, char** argv) {
  Args a;
  CLI::App app{"A robot's visual memory: stream, save, restart, resume, localize"};
  app.add_option("input", a.input, "Video, image folder, image list or TUM rgb.txt")->required();
  app.add_option("memory", a.memory, "Memory file written (and read back)")->required();
  app.add_option("--restart-at", a.restart_at, "Fraction of the stream after which the robot restarts")
      ->check(CLI::Range(0.0, 1.0));
  app.add_option("--hold-out", a.hold_out, "Keep every n-th frame out of the memory and localize it (0: none)");
  app.add_option("--images", a.images, "Key image pixels kept and saved")->check(CLI::IsMember({"none", "png", "jpeg"}));
  app.add_option("--tau", a.tau, "Key-image threshold tau of eq. 6")->check(CLI::Range(0.0, 1.0));
  app.add_option("--end", a.end, "Read frames [0, end) only (0: all)");
  app.add_option("--within", a.within, "A localization is near when its key image is within this many frames");
  app.add_option("--detections", a.detections, "Detections per frame (labels file): loops through the label tree");
  app.add_option("--label-sample", a.label_sample, "Key images whose detections fix the label schema (eq. 5)");
  app.add_option("--poses", a.poses, "TUM ground truth used as odometry (nearest pose in time, SE(2))");
  app.add_flag("--gcs", a.gcs, "Train the GCS localizer on the key images' poses after the restart (needs --poses)");
  CLI11_PARSE(app, argc, argv);
  try {
    return run(a);
  } catch (const vmap::Error& e) {
    std::fprintf(stderr, "robot_memory: %s\n", e.what());
    return 1;
  }
}
