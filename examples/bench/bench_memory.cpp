// Measurements of the visual memory (include/vmap/memory), on real sequences:
//   - resume: key images and loop edges of a run saved, dropped and loaded again every
//     --every frames equal those of one uninterrupted run (tum_fr1_rpy, rtabmap_loop);
//   - save / load times and file sizes per key image, without images, PNG and JPEG;
//   - localize on held-out frames (every --hold-out-th frame, index % n == n / 2, kept
//     out of the memory): fraction answered with a key image within --within frames of
//     the query, and ms per query.
//
//   bench_memory [--shared DIR] [--every 100] [--every-short 20] [--hold-out 10] [--within 15] [--end N]
// (--every-short for rtabmap_loop, whose 84 frames hold no 100-frame interval to cut)
#include <vmap/io/frame_source.hpp>
#include <vmap/memory/stacks.hpp>
#include <vmap/memory/visual_memory.hpp>

#include <CLI/CLI.hpp>

#include <chrono>
#include <cstdio>
#include <filesystem>
#include <optional>
#include <string>
#include <vector>

namespace {

using Clock = std::chrono::steady_clock;
double ms_since(Clock::time_point t) { return std::chrono::duration<double, std::milli>(Clock::now() - t).count(); }

struct Run {
  std::optional<vmap::OrbVisualMemory> mem;
  std::vector<vmap::Frame> held;
  double push_ms = 0.0, resume_ms = 0.0;
  std::size_t restarts = 0;
};

Run run(const std::filesystem::path& input, std::size_t end, std::size_t every, std::size_t hold_out,
        const std::filesystem::path& file) {
  vmap::MemoryOptions o;
  o.images = vmap::ImageStorage::png;  // keep pixels so that every storage can be measured
  Run r;
  r.mem.emplace(o);
  vmap::FrameSourceOptions so{.grey = true};
  if (end > 0) so.end = end;
  auto src = vmap::FrameSource::open(input, so);
  std::size_t pushed = 0;
  while (auto f = src.next()) {
    if (hold_out > 0 && f->index % hold_out == hold_out / 2) {
      r.held.push_back(std::move(*f));
      continue;
    }
    if (every > 0 && pushed > 0 && pushed % every == 0) {
      const auto t = Clock::now();
      r.mem->save(file);
      r.mem.reset();
      r.mem.emplace(vmap::OrbVisualMemory::load(file));
      r.resume_ms += ms_since(t);
      ++r.restarts;
    }
    const auto t = Clock::now();
    r.mem->push(*f);
    r.push_ms += ms_since(t);
    ++pushed;
  }
  return r;
}

bool same(const vmap::OrbVisualMemory& a, const vmap::OrbVisualMemory& b) {
  if (a.map().key_indices() != b.map().key_indices() || a.loops().size() != b.loops().size()) return false;
  for (std::size_t i = 0; i < a.map().pairs.size(); ++i)
    if (a.map().pairs[i].inliers != b.map().pairs[i].inliers) return false;
  for (std::size_t i = 0; i < a.loops().size(); ++i)
    if (a.loops()[i].from != b.loops()[i].from || a.loops()[i].link.key != b.loops()[i].link.key ||
        a.loops()[i].link.inliers != b.loops()[i].link.inliers)
      return false;
  return true;
}

}  // namespace

int main(int argc, char** argv) {
  std::string shared = VMAP_SHARED_DIR;
  std::size_t every = 100, every_short = 20, hold_out = 10, within = 15, end = 0;
  CLI::App app{"VisualMemory: resume equality, save/load cost, localization of held-out frames"};
  app.add_option("--shared", shared, "The shared data folder");
  app.add_option("--every", every, "Save and reload every n pushed frames in the interrupted run");
  app.add_option("--every-short", every_short, "The same for rtabmap_loop (84 frames)");
  app.add_option("--hold-out", hold_out, "Keep every n-th frame out of the memory and localize it");
  app.add_option("--within", within, "A localization is right when its key image is within this many frames");
  app.add_option("--end", end, "Read frames [0, end) only (0: all)");
  CLI11_PARSE(app, argc, argv);
  const std::filesystem::path dir = std::filesystem::temp_directory_path() / "vmap_bench_memory";
  std::filesystem::create_directories(dir);
  const std::filesystem::path data = std::filesystem::path(shared) / "data";
  struct Seq {
    const char* name;
    std::filesystem::path input;
    std::size_t every;
  };
  for (const Seq& s : {Seq{"tum_fr1_rpy", data / "tum_fr1_rpy/rgb.txt", every},
                       Seq{"rtabmap_loop", data / "rtabmap_loop/images", every_short}}) {
    Run whole = run(s.input, end, 0, hold_out, dir / "m.vmem");
    const Run cut = run(s.input, end, s.every, hold_out, dir / "m.vmem");
    const auto& m = *whole.mem;
    const std::size_t pushed = m.frames();
    std::printf("%s: %zu frames pushed (%zu held out), %zu key images, %zu loop edges, %.1f ms per push\n", s.name, pushed,
                whole.held.size(), m.key_images(), m.loops().size(), whole.push_ms / static_cast<double>(pushed));
    std::printf("  resume: saved and reloaded %zu times (every %zu frames, %.1f ms per restart): key images %zu, loops "
                "%zu -> %s\n",
                cut.restarts, s.every, cut.restarts ? cut.resume_ms / static_cast<double>(cut.restarts) : 0.0,
                cut.mem->key_images(), cut.mem->loops().size(), same(m, *cut.mem) ? "EQUAL" : "DIFFERENT");
    for (auto storage : {vmap::ImageStorage::none, vmap::ImageStorage::jpeg, vmap::ImageStorage::png}) {
      const char* label = storage == vmap::ImageStorage::none ? "none" : storage == vmap::ImageStorage::png ? "png" : "jpeg";
      const auto file = dir / (std::string(s.name) + "_" + label + ".vmem");
      auto t = Clock::now();
      m.save(file, storage);
      const double save_ms = ms_since(t);
      t = Clock::now();
      const auto back = vmap::OrbVisualMemory::load(file);
      const double load_ms = ms_since(t);
      const auto bytes = std::filesystem::file_size(file);
      std::printf("  images %-4s: %9ju bytes, %7.0f bytes per key image, save %7.1f ms, load %7.1f ms (%zu keys)\n", label,
                  static_cast<std::uintmax_t>(bytes), static_cast<double>(bytes) / static_cast<double>(m.key_images()),
                  save_ms, load_ms, back.key_images());
    }
    auto& q = *whole.mem;
    std::size_t localized = 0, near = 0;
    const auto t = Clock::now();
    for (const auto& f : whole.held) {
      const auto a = q.localize(f.image);
      if (!a.ok()) continue;
      ++localized;
      const std::size_t k = q.map().keys[a.best()->key].frame_index;
      if ((k > f.index ? k - f.index : f.index - k) <= within) ++near;
    }
    const double n = static_cast<double>(whole.held.size());
    std::printf("  localize %zu held-out frames: %zu localized (%.1f %%), %zu within %zu frames (%.1f %%), %.1f ms per "
                "query\n",
                whole.held.size(), localized, 100.0 * static_cast<double>(localized) / n, near, within,
                100.0 * static_cast<double>(near) / n, ms_since(t) / n);
  }
  std::filesystem::remove_all(dir);
  return 0;
}
