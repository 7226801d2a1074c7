// A fleet's memory on PostgreSQL against one SQLite memory, in the same run
// (examples/results/fleet.md has the figures):
//
//   1. same answers: rtabmap_loop cut into three overlapping parts mapped by three robots
//      at the same time, and tum_fr1_rpy cut in two; the loops between robots against
//      the loops between sessions of one SQLite memory built from the same parts in
//      order (both against the ground truth), and every 5th frame, held out, localized in
//      the fleet and in the SQLite memory;
//   2. latency per key image (push, sync and the loop query with verification of the
//      top k: everything AnyMemory::push does) with 0, 1k, 10k and 100k key images of
//      another robot in the database, against the same robot's run into an SQLite store;
//   3. scale on one machine: 1, 2, 4 and 8 robot processes mapping at the same time.
//
//   bench_fleet --shared ../shared --uri postgresql://vmap@127.0.0.1:5432/postgres
//               [--part same|latency|scale|all] [--sizes 1000,10000,100000]
//
// Each run uses a fresh database per section on the server given (created and dropped:
// the user needs CREATEDB). In sections 1 and 2 robots are threads of this program, each
// with its own connections; in section 3 each robot is a process.
#include "common/cli_support.hpp"

#include <vmap/io/frame_source.hpp>
#include <vmap/io/poses.hpp>
#include <vmap/io/postgres.hpp>
#include <vmap/lcd/evaluation.hpp>
#include <vmap/memory/fleet.hpp>
#include <vmap/runtime/fleet.hpp>
#include <vmap/runtime/memory.hpp>
#include <vmap/runtime/stack.hpp>
#include <vmap/runtime/vocabulary.hpp>

#include <CLI/CLI.hpp>

#include <algorithm>
#include <cstdlib>
#include <chrono>
#include <cstdio>
#include <filesystem>
#include <map>
#include <set>
#include <sstream>
#include <string>
#include <thread>
#include <vector>

namespace {

namespace fs = std::filesystem;
using Clock = std::chrono::steady_clock;

double ms_since(Clock::time_point t0) { return std::chrono::duration<double, std::milli>(Clock::now() - t0).count(); }

double percentile(std::vector<double> v, double p) {
  if (v.empty()) return 0.0;
  std::sort(v.begin(), v.end());
  const auto i = static_cast<std::size_t>(p * static_cast<double>(v.size() - 1) + 0.5);
  return v[std::min(i, v.size() - 1)];
}

std::vector<vmap::Frame> read_grey(const fs::path& input) {
  auto src = vmap::FrameSource::open(input, {.grey = true});
  std::vector<vmap::Frame> out;
  while (auto f = src.next()) out.push_back(std::move(*f));
  return out;
}

/// A database of its own on the server of `uri` for one section (dropped first if left
/// over); the URI of it.
std::string fresh_database(const std::string& uri, const std::string& name) {
  vmap::pg::Connection admin(uri, "server '" + vmap::pg::redacted(uri) + "'");
  admin.exec("DROP DATABASE IF EXISTS " + name + " WITH (FORCE)", "drop the bench database");
  admin.exec("CREATE DATABASE " + name, "create the bench database");
  const std::size_t slash = uri.find('/', uri.find("://") + 3);
  const std::size_t query = uri.find('?', slash);
  return uri.substr(0, slash + 1) + name + (query == std::string::npos ? "" : uri.substr(query));
}

/// The vocabulary's depth (10^depth words; --depth): a larger vocabulary has shorter
/// posting lists, which is what the server's ranking costs.
int vocabulary_depth = 4;

vmap::AnyVocabulary learn_vocabulary(const std::vector<vmap::Frame>& frames) {
  vmap::OrbDescriptor orb;
  std::vector<cv::Mat> sets;
  for (std::size_t i = 0; i < frames.size(); i += 2) sets.push_back(orb.extract(frames[i].image).descriptors);
  return vmap::AnyVocabulary::learn(sets, {.branching = 10, .depth = vocabulary_depth, .seed = 1});
}

struct Part {
  std::size_t first, last;  ///< frames [first, last)
};

/// A loop as the frames of its two key images (smaller first).
using FramePair = std::pair<std::size_t, std::size_t>;
FramePair frame_pair(std::size_t a, std::size_t b) { return {std::min(a, b), std::max(a, b)}; }

struct SameRow {
  std::size_t fleet_loops = 0, fleet_true = 0, sqlite_loops = 0, sqlite_true = 0, both = 0;
  std::size_t held = 0, fleet_placed = 0, sqlite_placed = 0, same_frame = 0;
};

/// Section 1 for one sequence: robots mapping `parts` at once, against one SQLite memory
/// of the parts as sessions.
SameRow same_answers(const std::string& server, const std::string& db, const std::vector<vmap::Frame>& frames,
                     const vmap::LoopGroundTruth& gt, const std::vector<Part>& parts, const fs::path& work) {
  const std::string uri = fresh_database(server, db);
  const vmap::AnyVocabulary vocabulary = learn_vocabulary(frames);
  const vmap::PolicyStack stack;
  vmap::MemoryOptions options;
  const auto held_out = [](std::size_t i) { return i % 5 == 4; };
  SameRow row;
  // The robots, at the same time.
  std::vector<std::thread> robots;
  std::vector<std::string> errors(parts.size());
  for (std::size_t r = 0; r < parts.size(); ++r)
    robots.emplace_back([&, r] {
      try {
        auto m = vmap::AnyMemory::create(uri, stack, options, vocabulary, {.robot = "r" + std::to_string(r)});
        for (std::size_t i = parts[r].first; i < parts[r].last; ++i)
          if (!held_out(i)) (void)m.push(frames[i]);
        m.close();
      } catch (const std::exception& e) {
        errors[r] = e.what();
      }
    });
  for (auto& t : robots) t.join();
  for (const auto& e : errors)
    if (!e.empty()) throw std::runtime_error(e);
  // One SQLite memory, the parts as sessions in order.
  const fs::path file = work / (db + ".vmdb");
  fs::remove(file);
  auto one = vmap::AnyMemory::create(file, stack, options, vocabulary, {});
  for (std::size_t r = 0; r < parts.size(); ++r) {
    if (r > 0) one.start_session();
    for (std::size_t i = parts[r].first; i < parts[r].last; ++i)
      if (!held_out(i)) (void)one.push(frames[i]);
  }
  one.close();
  auto fleet = vmap::FleetMemory::open(uri);
  std::map<std::string, std::size_t> robot_of;
  for (std::size_t r = 0; r < fleet.robots().size(); ++r) robot_of[fleet.robots()[r]] = r;
  std::set<FramePair> by_fleet, by_sqlite;
  for (const auto& l : vmap::fleet_loops(uri)) {
    const auto fa = fleet.memory(robot_of[l.from_robot]).map().keys[l.from_key].frame_index;
    const auto fb = fleet.memory(robot_of[l.to_robot]).map().keys[l.to_key].frame_index;
    by_fleet.insert(frame_pair(fa, fb));
  }
  for (const auto& e : one.loops())
    if (one.session_of(e.from) != one.session_of(e.link.key))
      by_sqlite.insert(frame_pair(one.map().keys[e.from].frame_index, one.map().keys[e.link.key].frame_index));
  // True: the ground truth's revisit, or the same or the next frame (where the parts
  // overlap, two robots saw the same frames; the ground truth lists revisits only).
  const auto truth = [&](const FramePair& p) { return p.second - p.first <= 1 || gt(p.second, p.first); };
  for (const auto& p : by_fleet) row.fleet_true += truth(p) ? 1 : 0;
  for (const auto& p : by_sqlite) row.sqlite_true += truth(p) ? 1 : 0;
  for (const auto& p : by_fleet) row.both += by_sqlite.count(p);
  row.fleet_loops = by_fleet.size();
  row.sqlite_loops = by_sqlite.size();
  // Held-out frames: the frame of the key image each answer names, in both.
  for (std::size_t i = 0; i < frames.size(); ++i) {
    if (!held_out(i)) continue;
    ++row.held;
    const vmap::FleetLocalization f = fleet.localize(frames[i].image);
    const vmap::MemoryLocalization s = one.localize(frames[i].image);
    std::optional<std::size_t> ff, sf;
    if (f.answer.ok()) ff = fleet.memory(f.index).map().keys[f.answer.best()->key].frame_index;
    if (s.ok()) sf = one.map().keys[s.best()->key].frame_index;
    row.fleet_placed += ff ? 1 : 0;
    row.sqlite_placed += sf ? 1 : 0;
    row.same_frame += ff && sf && *ff == *sf ? 1 : 0;
  }
  return row;
}

void same_section(const std::string& server, const fs::path& shared, const fs::path& work) {
  std::printf("\n## 1. Same answers: robots at the same time against one SQLite memory of the parts as sessions\n\n");
  std::printf("| sequence | parts | loops between robots (true) | loops between sessions, SQLite (true) | in both | "
              "held out | placed: fleet, SQLite | same key frame |\n|---|---|---|---|---|---|---|---|\n");
  // Poses within 0.5 m and 30 degrees are one place, however close in time.
  const vmap::PoseLoopOptions pose_gt{.max_distance = 0.5, .max_angle_deg = 30, .window = 0};
  {
    const auto frames = read_grey(shared / "data/rtabmap_loop/images");
    const auto gt = vmap::LoopGroundTruth::load(shared / "data/rtabmap_loop/gt_loop_matrix_84x84.txt", frames.size());
    const std::vector<Part> parts{{0, 34}, {25, 60}, {50, frames.size()}};
    const SameRow r = same_answers(server, "bench_same_rtabmap", frames, gt, parts, work);
    std::printf("| rtabmap_loop | 3: 0-33, 25-59, 50-83 | %zu (%zu) | %zu (%zu) | %zu | %zu | %zu, %zu | %zu |\n",
                r.fleet_loops, r.fleet_true, r.sqlite_loops, r.sqlite_true, r.both, r.held, r.fleet_placed,
                r.sqlite_placed, r.same_frame);
  }
  {
    const auto frames = read_grey(shared / "data/tum_fr1_rpy/rgb.txt");
    std::vector<double> t;
    for (const auto& f : frames) t.push_back(f.timestamp);
    const fs::path poses = shared / "data/tum_fr1_rpy/groundtruth.txt";
    const auto gt = vmap::ground_truth_from_poses(
        vmap::poses_for_frames(vmap::load_tum_poses(poses), t, poses.string(), 0.05, false), pose_gt);
    const std::size_t n = frames.size();
    const std::vector<Part> parts{{0, n * 11 / 20}, {n * 9 / 20, n}};
    const SameRow r = same_answers(server, "bench_same_rpy", frames, gt, parts, work);
    std::printf("| tum_fr1_rpy | 2: 0-%zu, %zu-%zu | %zu (%zu) | %zu (%zu) | %zu | %zu | %zu, %zu | %zu |\n", n * 11 / 20 - 1,
                n * 9 / 20, n - 1, r.fleet_loops, r.fleet_true, r.sqlite_loops, r.sqlite_true, r.both, r.held,
                r.fleet_placed, r.sqlite_placed, r.same_frame);
  }
}

/// Fills the fleet at `uri` with `n` key images of robot "filler": copies of the rows of
/// robot `source` (its key images and their postings), numbered 0 .. n-1, in one
/// transaction. Synthetic: the copies are real key images, repeated.
void fill(const std::string& uri, const std::string& source, std::size_t n) {
  {
    auto store = vmap::MemoryStore::create(uri, {}, "filler");
  }
  vmap::detail::StoreDb db(vmap::pg::Connection(uri, "bench"));
  const auto src = vmap::detail::fleet_robot(db, source), dst = vmap::detail::fleet_robot(db, "filler");
  const std::string s = vmap::detail::robot_schema(*src), d = vmap::detail::robot_schema(*dst);
  vmap::detail::StoreTransaction t(db, "fill the fleet");
  auto count = db.prepare("SELECT count(*) FROM " + s + ".key_images WHERE bow IS NOT NULL", "count");
  (void)count.step();
  const std::int64_t m = count.integer(0);
  count.reset();
  auto keys = db.prepare("INSERT INTO " + d + ".key_images SELECT g.i, k.frame_index, k.timestamp, k.time_ns, k.name, "
                         "k.keypoints, k.record, k.detections, k.crc, k.bow, k.bow_crc FROM generate_series(0, ? - 1) AS g(i) "
                         "JOIN " + s + ".key_images k ON k.id = g.i % ?",
                         "copy key images");
  keys.bind(1, static_cast<std::int64_t>(n)).bind(2, m);
  keys.run();
  auto postings = db.prepare("INSERT INTO vmap.postings(robot, key, word, weight, vocabulary) "
                             "SELECT ?, g.i, p.word, p.weight, p.vocabulary FROM generate_series(0, ? - 1) AS g(i) "
                             "JOIN vmap.postings p ON p.robot = ? AND p.key = g.i % ?",
                             "copy postings");
  postings.bind(1, *dst).bind(2, static_cast<std::int64_t>(n)).bind(3, *src).bind(4, m);
  postings.run();
  t.commit();
  // As the server's autovacuum leaves a table that stopped growing: the index answers
  // the ranking without reading the table (its visibility map set), with fresh statistics.
  db.exec("VACUUM (ANALYZE) vmap.postings", "vacuum");
}

struct Latency {
  std::vector<double> key_ms;  ///< pushes that made a key image
  std::size_t keys = 0, fleet_loops = 0;
  double seconds = 0.0;
};

/// A robot pushes `frames` into `memory`: the time of each push that made a key image.
Latency run_robot(vmap::AnyMemory& memory, const std::vector<vmap::Frame>& frames, std::size_t first, std::size_t last) {
  Latency l;
  const auto t0 = Clock::now();
  for (std::size_t i = first; i < last; ++i) {
    const auto t = Clock::now();
    const vmap::MemoryStep s = memory.push(frames[i]);
    if (s.new_key) {
      l.key_ms.push_back(ms_since(t));
      ++l.keys;
    }
    l.fleet_loops += s.fleet_loops.size();
  }
  memory.close();
  l.seconds = ms_since(t0) / 1000.0;
  return l;
}

void latency_section(const std::string& server, const fs::path& shared, const fs::path& work,
                     const std::vector<std::size_t>& sizes) {
  std::printf("\n## 2. Latency per key image (push + sync + loop query with verification of the top k)\n\n");
  const auto frames = read_grey(shared / "data/tum_fr1_rpy/rgb.txt");
  const vmap::AnyVocabulary vocabulary = learn_vocabulary(frames);
  const vmap::PolicyStack stack;
  const std::size_t probe_first = 300, probe_last = 500;
  // The SQLite store: the same robot's run, alone.
  Latency sqlite;
  {
    const fs::path file = work / "latency.vmdb";
    fs::remove(file);
    auto m = vmap::AnyMemory::create(file, stack, {}, vocabulary, {});
    sqlite = run_robot(m, frames, probe_first, probe_last);
  }
  std::printf("| key images of other robots in the database | p50 ms | p99 ms | p50 / SQLite | p99 / SQLite | loops "
              "to other robots | server's ranking, p50 ms | one candidate's features, p50 ms |\n"
              "|---|---|---|---|---|---|---|---|\n");
  std::printf("| SQLite store (one robot) | %.1f | %.1f | 1.00 | 1.00 | - | - | - |\n", percentile(sqlite.key_ms, 0.5),
              percentile(sqlite.key_ms, 0.99));
  std::vector<std::size_t> all{0};
  all.insert(all.end(), sizes.begin(), sizes.end());
  for (const std::size_t n : all) {
    const std::string uri = fresh_database(server, "bench_latency_" + std::to_string(n));
    // A robot that mapped the first 300 frames gives the rows the filler repeats.
    {
      auto seed = vmap::AnyMemory::create(uri, stack, {}, vocabulary, {.robot = "seed"});
      for (std::size_t i = 0; i < probe_first; ++i) (void)seed.push(frames[i]);
      seed.close();
    }
    if (n > 0) {
      const auto t0 = Clock::now();
      fill(uri, "seed", n);
      std::fprintf(stderr, "bench_fleet: %zu key images written in %.1f s\n", n, ms_since(t0) / 1000.0);
    }
    auto m = vmap::AnyMemory::create(uri, stack, {}, vocabulary, {.robot = "probe"});
    const Latency l = run_robot(m, frames, probe_first, probe_last);
    const double p50 = percentile(l.key_ms, 0.5), p99 = percentile(l.key_ms, 0.99);
    // The two server-side parts of a loop query, alone: the ranking in the inverted file,
    // and reading one candidate's features.
    std::vector<double> rank_ms, fetch_ms;
    {
      vmap::FleetIndex fleet(uri, "probe");
      vmap::detail::StoreDb db(vmap::pg::Connection(uri, "bench"));
      auto q = db.prepare("SELECT vocabulary FROM vmap.postings p JOIN vmap.robots r ON r.id = p.robot "
                          "WHERE r.name = 'probe' LIMIT 1", "read the vocabulary");
      const std::int64_t crc = q.step() ? q.integer(0) : 0;
      for (const vmap::BowVector& bow : m.records().bows) {
        const auto t = Clock::now();
        const auto ranked = fleet.candidates(bow, 5, crc);
        rank_ms.push_back(ms_since(t));
        if (ranked.empty()) continue;
        const auto tf = Clock::now();
        (void)fleet.features(ranked[0]);
        fetch_ms.push_back(ms_since(tf));
      }
    }
    std::printf("| %zu (+ %zu of the seed robot) | %.1f | %.1f | %.2f | %.2f | %zu | %.1f | %.2f |\n", n, probe_first, p50,
                p99, p50 / percentile(sqlite.key_ms, 0.5), p99 / percentile(sqlite.key_ms, 0.99), l.fleet_loops,
                percentile(rank_ms, 0.5), percentile(fetch_ms, 0.5));
    std::fflush(stdout);
  }
}

constexpr std::size_t scale_frames = 80;  ///< frames each robot of the scale section pushes

/// One robot process of the scale section (`--robot-run`): robot `name` pushes
/// scale_frames frames of tum_fr1_rpy from `first` into `uri`, with the vocabulary file
/// `vocabulary`; prints the time of each push that made a key image, one per line.
int robot_process(const std::string& uri, const fs::path& shared, const std::string& name, std::size_t first,
                  const std::string& vocabulary) {
  // Only its own frames are read (decoding the whole sequence in every process would
  // count in the rate).
  auto src = vmap::FrameSource::open(shared / "data/tum_fr1_rpy/rgb.txt",
                                     {.start = first, .end = first + scale_frames, .grey = true});
  std::vector<vmap::Frame> frames;
  while (auto f = src.next()) frames.push_back(std::move(*f));
  auto m = vmap::AnyMemory::create(uri, vmap::PolicyStack{}, {}, vmap::AnyVocabulary::load(vocabulary), {.robot = name});
  const Latency l = run_robot(m, frames, 0, frames.size());
  for (const double ms : l.key_ms) std::printf("%.3f\n", ms);
  return 0;
}

void scale_section(const std::string& server, const fs::path& shared, const fs::path& work, const std::string& self) {
  std::printf("\n## 3. Robot processes mapping at the same time on one machine (%u cores)\n\n",
              std::thread::hardware_concurrency());
  const auto frames = read_grey(shared / "data/tum_fr1_rpy/rgb.txt");
  const fs::path vocabulary = work / "scale_vocabulary.bin";
  fs::remove(vocabulary);
  learn_vocabulary(frames).save(vocabulary);
  std::printf("| robots | key images | seconds | key images / s (all robots) | p50 ms | p99 ms | loops between robots "
              "|\n|---|---|---|---|---|---|---|\n");
  for (const std::size_t n : {1, 2, 4, 8}) {
    const std::string uri = fresh_database(server, "bench_scale_" + std::to_string(n));
    // Each robot a process of its own (this program with --robot-run), all started at once.
    std::vector<FILE*> robots;
    const auto t0 = Clock::now();
    for (std::size_t r = 0; r < n; ++r) {
      const std::size_t first = (r * 83) % (frames.size() - scale_frames);
      const std::string cmd = "'" + self + "' --uri '" + server + "' --shared '" + shared.string() + "' --robot-run r" +
                              std::to_string(r) + " --first " + std::to_string(first) + " --vocabulary-file '" +
                              vocabulary.string() + "' --robot-uri '" + uri + "'";
      FILE* p = popen(cmd.c_str(), "r");
      if (!p) throw std::runtime_error("cannot start a robot process");
      robots.push_back(p);
    }
    std::vector<double> all;
    for (FILE* p : robots) {
      char line[64];
      while (std::fgets(line, sizeof line, p)) all.push_back(std::strtod(line, nullptr));
      if (pclose(p) != 0) throw std::runtime_error("a robot process failed");
    }
    const double seconds = ms_since(t0) / 1000.0;
    std::printf("| %zu | %zu | %.1f | %.1f | %.1f | %.1f | %zu |\n", n, all.size(), seconds,
                static_cast<double>(all.size()) / seconds, percentile(all, 0.5), percentile(all, 0.99),
                vmap::fleet_loops(uri).size());
    std::fflush(stdout);
  }
}

}  // namespace

int main(int argc, char** argv) {
  CLI::App app{"bench_fleet: a fleet's memory on PostgreSQL against one SQLite memory"};
  std::string shared = "../shared", uri, part = "all", work = "build/bench_fleet";
  std::vector<std::size_t> sizes{1000, 10000};
  app.add_option("--shared", shared, "The shared data folder");
  app.add_option("--uri", uri, "A PostgreSQL server (its user may create databases)")->required();
  app.add_option("--part", part, "same, latency, scale or all")->check(CLI::IsMember({"same", "latency", "scale", "all"}));
  app.add_option("--sizes", sizes, "Key images of another robot in the database for the latency section")->delimiter(',');
  app.add_option("--work", work, "Folder for the SQLite memories");
  app.add_option("--depth", vocabulary_depth, "Vocabulary depth: 10^depth words, learned from the sequence")
      ->check(CLI::Range(2, 6));
  // One robot process of the scale section (started by this program).
  std::string robot_run, robot_uri, vocabulary_file;
  std::size_t first = 0;
  app.add_option("--robot-run", robot_run, "(internal) map as this robot, then print each key image's time");
  app.add_option("--robot-uri", robot_uri, "(internal) the fleet the robot maps into");
  app.add_option("--first", first, "(internal) the robot's first frame");
  app.add_option("--vocabulary-file", vocabulary_file, "(internal) the fleet's vocabulary");
  CLI11_PARSE(app, argc, argv);
  try {
    if (!robot_run.empty()) return robot_process(robot_uri, shared, robot_run, first, vocabulary_file);
    fs::create_directories(work);
    std::printf("# bench_fleet (%s, vocabulary of 10^%d words)\n", vmap::pg::redacted(uri).c_str(), vocabulary_depth);
    if (part == "same" || part == "all") same_section(uri, shared, work);
    if (part == "latency" || part == "all") latency_section(uri, shared, work, sizes);
    if (part == "scale" || part == "all") scale_section(uri, shared, work, fs::canonical("/proc/self/exe").string());
  } catch (const std::exception& e) {
    std::fprintf(stderr, "bench_fleet: %s\n", e.what());
    return 1;
  }
  return 0;
}
