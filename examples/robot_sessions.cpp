// A robot's memory over several runs, through the public API only (include/vmap/memory):
//
//   run 1  maps frames [0, split1) of INPUT (every --stride-th) into a memory store, then
//          the robot stops: nothing survives but the store;
//   run 2  opens the store, starts a new session and maps frames [split2, end), which
//          revisit the end of run 1: the loops between the two runs are found as it maps;
//   run 3  while run 2 maps, another thread opens the store read-only and localizes the
//          frames neither run pushed (the odd ones with --stride 2), reloading the
//          memory as it grows (a reader never blocks the writer, nor the writer it).
//
//   robot_sessions INPUT STORE [--split1 44] [--split2 40] [--end 0] [--stride 2]
//                  [--working-memory 200] [--gt MATRIX] [--within 3]
//
// A run-3 answer is right when its key image is within --within frames of the query, or
// (with --gt, an N x N 0/1 loop matrix such as rtabmap_loop's) when the ground truth marks
// the two frames as the same place.
#include <vmap/io/files.hpp>
#include <vmap/memory/store.hpp>
#include <vmap/vmap.hpp>

#include <CLI/CLI.hpp>

#include <algorithm>
#include <atomic>
#include <chrono>
#include <cstdint>
#include <cstdio>
#include <filesystem>
#include <optional>
#include <sstream>
#include <string>
#include <thread>
#include <vector>

namespace {

using Clock = std::chrono::steady_clock;

double ms_since(Clock::time_point t) { return std::chrono::duration<double, std::milli>(Clock::now() - t).count(); }

struct Args {
  std::string input, store;
  std::size_t split1 = 44, split2 = 40, end = 0, stride = 2, working_memory = 200, within = 3;
  std::string gt;
};

/// An N x N 0/1 matrix, one row per line (rtabmap_loop's gt_loop_matrix_84x84.txt);
/// nullopt, said on stderr, when the file cannot be read (vmap::read_text_file: a FIFO or
/// a device is refused unopened).
std::optional<std::vector<std::vector<int>>> read_matrix(const std::string& file) {
  std::istringstream in;
  try {
    in.str(vmap::read_text_file(file, "ground truth matrix"));
  } catch (const vmap::Error& e) {
    std::fprintf(stderr, "robot_sessions: %s\n", e.what());
    return std::nullopt;
  }
  std::vector<std::vector<int>> m;
  for (std::string line; std::getline(in, line);) {
    std::istringstream row(line);
    std::vector<int> r;
    for (int v = 0; row >> v;) r.push_back(v);
    if (!r.empty()) m.push_back(std::move(r));
  }
  return m;
}

vmap::FrameSource frames(const Args& a, std::size_t start, std::size_t end) {
  vmap::FrameSourceOptions so{.start = start, .stride = a.stride, .grey = true};
  so.end = end;
  return vmap::FrameSource::open(a.input, so);
}

/// Pushes every frame of `src` into the memory, syncing the store after each (one
/// transaction; a crash loses at most that frame). Returns the loop edges found.
std::vector<vmap::LoopEdge> map_run(vmap::FrameSource& src, vmap::OrbVisualMemory& mem, vmap::MemoryStore& store,
                                    std::atomic<bool>* first_synced = nullptr) {
  std::vector<vmap::LoopEdge> found;
  while (auto f = src.next()) {
    auto step = mem.push(*f);
    found.insert(found.end(), step.loops.begin(), step.loops.end());
    store.sync(mem);
    if (first_synced) first_synced->store(true);
  }
  return found;
}

struct Answer {
  std::size_t query = 0;      ///< frame index
  std::size_t snapshot = 0;   ///< key images of the memory it was asked of
  std::optional<std::size_t> key_frame;
  std::size_t session = 0;
  vmap::PlaceStatus status = vmap::PlaceStatus::too_little_evidence;
};

int run(const Args& a) {
  namespace fs = std::filesystem;
  std::vector<std::vector<int>> gt;
  if (!a.gt.empty()) {
    auto m = read_matrix(a.gt);
    if (!m) {
      std::fprintf(stderr, "robot_sessions: --gt: cannot read '%s'\n", a.gt.c_str());
      return 2;
    }
    gt = std::move(*m);
  }
  std::size_t total = 0;
  {
    auto probe = vmap::FrameSource::open(a.input, {});
    total = probe.total().value_or(0);
  }
  const std::size_t end = a.end > 0 ? std::min(a.end, total) : total;
  if (a.split2 > a.split1 || a.split2 >= end) {
    std::fprintf(stderr, "robot_sessions: the runs need --split2 <= --split1 and --split2 < the last frame (%zu)\n", end);
    return 2;
  }
  for (const char* suffix : {"", "-wal", "-shm"}) fs::remove(a.store + suffix);

  // Run 1.
  auto t = Clock::now();
  {
    auto store = vmap::MemoryStore::create(a.store);
    vmap::OrbVisualMemory mem;
    auto src = frames(a, 0, a.split1);
    const auto loops = map_run(src, mem, store);
    store.checkpoint();
    std::printf("run 1: frames 0-%zu, %zu pushed, %zu key images, %zu loop edges, %.0f ms\n", a.split1 - 1,
                mem.frames(), mem.key_images(), loops.size(), ms_since(t));
  }  // the robot stops

  // Run 2: a new session of the same memory, bounded to its working memory.
  auto store = vmap::MemoryStore::open(a.store);
  auto mem = store.load_bounded<vmap::OrbVisualMemory>(a.working_memory);
  mem.start_session();
  const std::size_t first_key = mem.key_images();

  // Run 3, on another thread: read-only, while run 2 maps.
  std::atomic<bool> mapping_started{false}, mapping_done{false};
  std::vector<Answer> answers;
  std::size_t reloads = 0;
  std::thread reader([&] {
    while (!mapping_started.load()) std::this_thread::sleep_for(std::chrono::milliseconds(1));
    vmap::FrameSourceOptions so{.start = 1, .stride = a.stride, .grey = true};
    so.end = end;
    auto queries = vmap::FrameSource::open(a.input, so);
    std::optional<vmap::OrbVisualMemory> snapshot;
    std::size_t asked = 0;
    while (auto f = queries.next()) {
      // A fresh snapshot every 5 queries while the writer goes on.
      if (!snapshot || (asked % 5 == 0 && !mapping_done.load())) {
        auto view = vmap::MemoryStore::open(a.store, vmap::sqlite::Access::read);
        snapshot.emplace(view.load_bounded<vmap::OrbVisualMemory>(a.working_memory));
        ++reloads;
      }
      const auto answer = snapshot->localize(f->image);
      Answer r{f->index, snapshot->key_images(), std::nullopt, 0, answer.status};
      if (answer.ok()) {
        r.key_frame = snapshot->map().keys[answer.best()->key].frame_index;
        r.session = snapshot->session_of(answer.best()->key);
      }
      answers.push_back(r);
      ++asked;
    }
  });

  t = Clock::now();
  std::vector<vmap::LoopEdge> loops;
  try {
    auto src = frames(a, a.split2, end);
    loops = map_run(src, mem, store, &mapping_started);
  } catch (...) {
    mapping_started = true;
    mapping_done = true;
    reader.join();
    throw;
  }
  mapping_done = true;
  const double run2_ms = ms_since(t);
  reader.join();
  store.checkpoint();

  std::size_t across = 0;
  for (const auto& e : loops) across += mem.session_of(e.link.key) == 0 ? 1 : 0;
  std::printf("run 2: frames %zu-%zu as session %zu, %zu pushed, %zu key images (from key %zu), %zu loop edges, %zu of "
              "them into run 1, %.0f ms\n",
              a.split2, end - 1, mem.sessions().size(), mem.frames() - mem.sessions().back().first_frame,
              mem.key_images() - first_key, first_key, loops.size(), across, run2_ms);
  for (const auto& e : loops)
    if (mem.session_of(e.link.key) == 0)
      std::printf("  loop: run 2 frame %zu -> run 1 frame %zu (%d inliers, confidence %.2f)\n",
                  mem.map().keys[e.from].frame_index, mem.map().keys[e.link.key].frame_index, e.link.inliers,
                  e.link.confidence);

  std::size_t accepted = 0, right = 0, in_run1 = 0, in_run2 = 0;
  std::size_t smallest = SIZE_MAX, largest = 0;
  for (const auto& r : answers) {
    smallest = std::min(smallest, r.snapshot);
    largest = std::max(largest, r.snapshot);
    if (!r.key_frame) continue;
    ++accepted;
    (r.session == 0 ? in_run1 : in_run2) += 1;
    const std::size_t k = *r.key_frame, q = r.query;
    const bool near = (k > q ? k - q : q - k) <= a.within;
    const bool marked = q < gt.size() && k < gt[q].size() && (gt[q][k] != 0 || gt[k][q] != 0);
    right += near || marked ? 1 : 0;
  }
  std::printf("run 3 (read-only, while run 2 mapped): %zu frames localized in snapshots of %zu to %zu key images "
              "(%zu loads): %zu accepted (%zu in run 1's key images, %zu in run 2's), %zu right, %zu unknown or "
              "ambiguous\n",
              answers.size(), smallest == SIZE_MAX ? 0 : smallest, largest, reloads, accepted, in_run1, in_run2, right,
              answers.size() - accepted);
  std::printf("memory '%s': %zu sessions, %zu key images, %zu loop edges, %ju bytes\n", a.store.c_str(),
              mem.sessions().size(), mem.key_images(), mem.loops().size(),
              static_cast<std::uintmax_t>(fs::file_size(a.store)));
  return 0;
}

}  // namespace

int main(int argc, char** argv) {
  Args a;
  CLI::App app{"A robot's memory over three runs: map, map again as a new session, localize read-only while mapping"};
  app.add_option("input", a.input, "Image folder, image list or TUM rgb.txt (read three times)")->required();
  app.add_option("store", a.store, "Memory store written (replaced)")->required();
  app.add_option("--split1", a.split1, "Run 1 maps frames [0, split1)")->check(CLI::Range(std::size_t{1}, SIZE_MAX));
  app.add_option("--split2", a.split2, "Run 2 maps frames [split2, end) as a new session");
  app.add_option("--end", a.end, "One past the last frame (0: all)");
  app.add_option("--stride", a.stride, "Runs 1 and 2 read every stride-th frame from their start; run 3 the frames from 1")
      ->check(CLI::Range(1, 1000));
  app.add_option("--working-memory", a.working_memory, "Key images whose features stay in RAM")->check(CLI::Range(1, 1 << 30));
  app.add_option("--gt", a.gt, "N x N 0/1 loop matrix: an answer it marks is right");
  app.add_option("--within", a.within, "An answer within this many frames of the query is right");
  CLI11_PARSE(app, argc, argv);
  try {
    return run(a);
  } catch (const vmap::Error& e) {
    std::fprintf(stderr, "robot_sessions: %s\n", e.what());
    return 1;
  }
}
