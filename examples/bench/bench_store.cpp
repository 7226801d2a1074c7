// The memory store's cost (include/vmap/memory/store.hpp), measured in one run against a
// memory kept only in RAM, on the same frames:
//   - ratio: pushing the first --ratio-frames frames of tum_fr1_rpy (tau 0.3) with a sync
//     after every frame (`vmap build --memory M --save-every 1`) and a flush() after the
//     last (its commit counted), against pushing alone; each configuration --repeats
//     times, alternating, the fastest of each kept. The synced run also prints the time
//     its caller spent in sync() (collecting the rows, and waiting for the previous
//     commit: the writer thread commits while the next frame is pushed);
//   - scale (skipped with --keys 0): tum_fr1_rpy played forward, backward, forward...
//     (frame indices going on) with tau --scale-tau (0.95: nearly every frame a key
//     image) into a store synced at every frame, until --keys key images: the mean time
//     of the sync() call over the 100 key images up to 100, 1,000 and 10,000 (whichever
//     the run reaches), the store's bytes per key image, then the time to open and load
//     the store and to localize 20 frames in it.
//     With --working-memory W (> 0) the memory holds the features of its W most recent
//     key images only (VisualMemory::bound_features) and reads the others from the store
//     when a candidate is verified: the run prints the resident memory at 1,000 and
//     10,000 key images, the peak, and the reads and their time, and loads the store
//     bounded (MemoryStore::load_bounded). Run it once with --working-memory 0 and once
//     with W: each process has its own peak.
//
//   bench_store [--shared DIR] [--ratio-frames 400] [--repeats 3] [--keys 10000] [--scale-tau 0.95]
//               [--working-memory 0] [--dir /tmp/bench_store]
#include <vmap/io/frame_source.hpp>
#include <vmap/memory/stacks.hpp>
#include <vmap/memory/store.hpp>
#include <vmap/memory/visual_memory.hpp>

#include <CLI/CLI.hpp>

#include <algorithm>
#include <chrono>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <optional>
#include <string>
#include <vector>

namespace {

using Clock = std::chrono::steady_clock;
double ms_since(Clock::time_point t) { return std::chrono::duration<double, std::milli>(Clock::now() - t).count(); }

std::vector<vmap::Frame> read_all(const std::filesystem::path& input) {
  auto src = vmap::FrameSource::open(input, {.grey = true});
  std::vector<vmap::Frame> out;
  while (auto f = src.next()) out.push_back(std::move(*f));
  return out;
}

/// A field of /proc/self/status in MiB (VmRSS: resident now, VmHWM: the peak).
double status_mib(const std::string& field) {
  std::ifstream in("/proc/self/status");
  std::string line;
  while (std::getline(in, line))
    if (line.rfind(field + ":", 0) == 0) return std::stod(line.substr(field.size() + 1)) / 1024.0;
  return 0.0;
}

void remove_store(const std::filesystem::path& p) {
  std::error_code ec;
  for (const char* suffix : {"", "-wal", "-shm"}) std::filesystem::remove(p.string() + suffix, ec);
}

struct Timed {
  double total_ms = 0.0;
  double sync_ms = 0.0;  ///< of it, in sync() and the last flush()
};

/// The time to push `frames` (tau 0.3), with a sync after each and a flush after the
/// last when `store` is given.
Timed push_all(const std::vector<vmap::Frame>& frames, const std::filesystem::path* store) {
  vmap::OrbVisualMemory mem;
  std::optional<vmap::MemoryStore> s;
  if (store) {
    remove_store(*store);
    s.emplace(vmap::MemoryStore::create(*store));
  }
  Timed out;
  const auto t = Clock::now();
  for (const auto& f : frames) {
    mem.push(f);
    if (s) {
      const auto ts = Clock::now();
      s->sync(mem);
      out.sync_ms += ms_since(ts);
    }
  }
  if (s) {
    const auto ts = Clock::now();
    s->flush();
    out.sync_ms += ms_since(ts);
  }
  out.total_ms = ms_since(t);
  return out;
}

}  // namespace

int main(int argc, char** argv) {
  CLI::App app{"The memory store's cost against a memory in RAM"};
  std::string shared = "../shared";
  std::size_t ratio_frames = 400, repeats = 3, keys = 10000;
  double scale_tau = 0.95;
  std::string dir = "/tmp/bench_store";
  std::size_t working_memory = 0;
  app.add_option("--shared", shared, "The shared folder (data/tum_fr1_rpy)");
  app.add_option("--ratio-frames", ratio_frames, "Frames of the ratio run (0: skip it)");
  app.add_option("--repeats", repeats, "Runs of each configuration in the ratio run");
  app.add_option("--keys", keys, "Key images of the scale run (0: skip it)");
  app.add_option("--scale-tau", scale_tau, "tau of the scale run");
  app.add_option("--dir", dir, "Folder for the stores");
  app.add_option("--working-memory", working_memory,
                 "Scale run: key images whose features stay in RAM (0: all; the others are read from the store)");
  CLI11_PARSE(app, argc, argv);
  std::filesystem::create_directories(dir);

  const auto frames = read_all(std::filesystem::path(shared) / "data/tum_fr1_rpy/rgb.txt");
  const std::filesystem::path ratio_store = std::filesystem::path(dir) / "ratio.vmdb";
  if (ratio_frames > 0) {
    const std::vector<vmap::Frame> first(frames.begin(), frames.begin() + static_cast<std::ptrdiff_t>(std::min(ratio_frames, frames.size())));
    double ram = 1e300;
    Timed synced{1e300, 0.0};
    for (std::size_t r = 0; r < repeats; ++r) {
      const double in_ram = push_all(first, nullptr).total_ms;
      ram = std::min(ram, in_ram);
      const Timed run = push_all(first, &ratio_store);
      std::fprintf(stderr, "ratio: run %zu: in RAM %.0f ms, synced %.0f ms (%.0f ms in sync())\n", r + 1, in_ram,
                   run.total_ms, run.sync_ms);
      if (run.total_ms < synced.total_ms) synced = run;
    }
    std::printf("ratio: %zu frames of tum_fr1_rpy, fastest of %zu: in RAM %.0f ms, synced at every frame %.0f ms "
                "(%.0f ms of it in sync()): %.3fx\n",
                first.size(), repeats, ram, synced.total_ms, synced.sync_ms, synced.total_ms / ram);
  }
  if (keys == 0) return 0;

  // The scale run.
  vmap::MemoryOptions o;
  o.selector.tau = scale_tau;
  vmap::OrbVisualMemory mem(o);
  const std::filesystem::path scale_store = std::filesystem::path(dir) / "scale.vmdb";
  remove_store(scale_store);
  auto store = vmap::MemoryStore::create(scale_store);
  std::size_t reads = 0;  // released key images' features read from the store
  double read_ms = 0.0;
  if (working_memory > 0)
    mem.bound_features(working_memory, [&, source = store.features()](std::uint32_t k) {
      const auto t = Clock::now();
      vmap::Features f = source(k);
      read_ms += ms_since(t);
      ++reads;
      return f;
    });
  std::vector<double> sync_ms;  // per key image: the sync that wrote it
  std::vector<std::pair<std::size_t, double>> rss;  // (key images, VmRSS MiB) at 1,000 and 10,000
  const double rss_before = status_mib("VmRSS");     // the frames of tum_fr1_rpy, read once, are most of it
  std::size_t pushed = 0;
  double push_ms = 0.0;
  const auto t_run = Clock::now();
  for (std::size_t lap = 0; mem.key_images() < keys; ++lap) {
    for (std::size_t i = 0; i < frames.size() && mem.key_images() < keys; ++i) {
      vmap::Frame f = frames[lap % 2 == 0 ? i : frames.size() - 1 - i];
      f.index = pushed;
      f.timestamp = static_cast<double>(pushed) / 30.0;
      const auto t = Clock::now();
      const auto step = mem.push(f);
      push_ms += ms_since(t);
      const auto ts = Clock::now();
      store.sync(mem);
      const double s = ms_since(ts);
      if (step.new_key) sync_ms.push_back(s);
      if (step.new_key && (mem.key_images() == 1000 || mem.key_images() == 10000))
        rss.emplace_back(mem.key_images(), status_mib("VmRSS"));
      ++pushed;
      if (pushed % 1000 == 0)
        std::fprintf(stderr, "scale: %zu frames, %zu key images, %.0f s\n", pushed, mem.key_images(),
                     std::chrono::duration<double>(Clock::now() - t_run).count());
    }
  }
  store.checkpoint();
  const auto bytes = std::filesystem::file_size(scale_store);
  std::printf("scale: %zu frames pushed (tau %.2f), %zu key images, %zu loop edges; push %.1f ms per frame\n", pushed,
              scale_tau, mem.key_images(), mem.loops().size(), push_ms / static_cast<double>(pushed));
  for (std::size_t at : {std::size_t{100}, std::size_t{1000}, std::size_t{10000}}) {
    if (sync_ms.size() < at) continue;
    double sum = 0.0;
    for (std::size_t k = at - 100; k < at; ++k) sum += sync_ms[k];
    std::printf("  sync per key image at %5zu key images: %.2f ms (mean of the 100 up to it)\n", at, sum / 100.0);
  }
  std::printf("  store: %.1f MB, %.1f KB per key image\n", static_cast<double>(bytes) / 1e6,
              static_cast<double>(bytes) / 1e3 / static_cast<double>(mem.key_images()));
  std::printf("  working memory %s: resident %.1f MiB before the first frame;",
              working_memory ? std::to_string(working_memory).c_str() : "unbounded", rss_before);
  for (const auto& [k, mib] : rss) std::printf(" resident %.1f MiB at %zu key images;", mib, k);
  std::printf(" peak %.1f MiB before loading\n", status_mib("VmHWM"));
  if (working_memory > 0)
    std::printf("  features read from the store: %zu (%.3f ms each, %.2f ms per pushed frame)\n", reads,
                reads ? read_ms / static_cast<double>(reads) : 0.0, read_ms / static_cast<double>(pushed));

  const double rss_before_load = status_mib("VmRSS");
  const auto t_open = Clock::now();
  auto reader = vmap::MemoryStore::open(scale_store, vmap::sqlite::Access::read);
  auto loaded = working_memory > 0 ? reader.load_bounded<vmap::OrbVisualMemory>(working_memory)
                                   : reader.load<vmap::OrbVisualMemory>();
  const double load_ms = ms_since(t_open);
  std::printf("  load %s: resident %+.1f MiB after it, peak %.1f MiB\n",
              working_memory > 0 ? "bounded" : "whole", status_mib("VmRSS") - rss_before_load, status_mib("VmHWM"));
  const bool same = loaded.key_images() == mem.key_images() && loaded.loops().size() == mem.loops().size();
  std::printf("  open + load: %.0f ms (%zu key images, %s)\n", load_ms, loaded.key_images(),
              same ? "equal key images and loop edges" : "DIFFERENT");
  double localize_ms = 0.0;
  std::size_t accepted = 0;
  for (std::size_t q = 0; q < 20; ++q) {
    const auto t = Clock::now();
    const auto answer = loaded.localize(frames[(q * 37 + 11) % frames.size()].image);
    localize_ms += ms_since(t);
    accepted += answer.ok() ? 1 : 0;
  }
  std::printf("  localize: %.1f ms per query (20 frames of the sequence, %zu accepted)\n", localize_ms / 20.0, accepted);
  return same ? 0 : 1;
}
