// A robot's visual memory through the public API only (include/vmap/memory): stream a
// video or frame list, keep key images and loop edges, save the memory, "restart" (a new
// object loaded from the file), resume the stream after the last frame the memory saw,
// save again, and localize frames that were held out of the memory.
//
//   robot_memory INPUT MEMORY_FILE [--restart-at 0.5] [--hold-out 10] [--images none|png|jpeg]
//                [--tau 0.3] [--end N] [--within 15]
//
// Every --hold-out-th frame (index % hold_out == hold_out / 2) is kept out of the memory
// and localized at the end; "near" counts answers whose key image is within --within
// frames of the query.
#include <vmap/vmap.hpp>

#include <CLI/CLI.hpp>

#include <chrono>
#include <cstdio>
#include <filesystem>
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
};

/// Pushes the frames of `src` into `mem`, keeping the held-out ones aside; stops after
/// frame index `stop` (inclusive) when given.
std::size_t stream(vmap::FrameSource& src, vmap::OrbVisualMemory& mem, const Args& a, std::optional<std::size_t> stop,
                   std::vector<vmap::Frame>& held) {
  std::size_t loops = 0;
  while (auto f = src.next()) {
    if (a.hold_out > 0 && f->index % a.hold_out == a.hold_out / 2)
      held.push_back(std::move(*f));
    else
      loops += mem.push(*f).loops.size();
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

  vmap::FrameSourceOptions so{.grey = true};
  if (a.end > 0) so.end = a.end;
  std::vector<vmap::Frame> held;

  // 1. The first part of the stream.
  auto src = vmap::FrameSource::open(a.input, so);
  const std::size_t total = src.total().value_or(0);
  const auto stop = static_cast<std::size_t>(a.restart_at * static_cast<double>(total));
  std::size_t loops = 0;
  {
    vmap::OrbVisualMemory mem(o);
    auto t = Clock::now();
    loops += stream(src, mem, a, stop, held);
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
    loops += stream(rest, mem, a, std::nullopt, held);
  }
  mem.save(a.memory);
  std::printf("run 2: %zu frames in all, %zu key images, %zu loop edges (%zu found while streaming)\n", mem.frames(),
              mem.key_images(), mem.loops().size(), loops);

  // 3. Localize the held-out frames.
  std::size_t localized = 0, near = 0;
  t = Clock::now();
  for (const auto& f : held) {
    const auto answer = mem.localize(f.image);
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
  CLI11_PARSE(app, argc, argv);
  try {
    return run(a);
  } catch (const vmap::Error& e) {
    std::fprintf(stderr, "robot_memory: %s\n", e.what());
    return 1;
  }
}
