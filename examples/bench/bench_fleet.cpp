// A fleet's memory on PostgreSQL against one SQLite memory, in the same run
// (examples/results/fleet.md has the figures):
//
//   1. same answers: rtabmap_loop cut into three overlapping parts mapped by three robot
//      processes at the same time, and tum_fr1_rpy cut in two; the loops between robots
//      against the loops between sessions of one SQLite memory built from the same parts
//      in order (pair for pair, with their inliers, and against the ground truth), and
//      every 5th frame, held out, localized in the fleet and in the SQLite memory;
//   2. latency per key image (push, sync and the loop query with verification of the
//      candidates: everything AnyMemory::push does) with 0, 1k, 10k and 100k key images of
//      other runs in the memory: on the server another robot's, in an SQLite store earlier
//      sessions' (synthetic: real key images repeated);
//   3. scale on one machine: 1, 2, 4 and 8 robot processes mapping at the same time.
//
//   bench_fleet --shared ../shared --uri postgresql://vmap@127.0.0.1:5432/postgres
//               [--part same|latency|scale|all] [--sizes 1000,10000,100000]
//
// Each run uses a fresh database per section on the server given (created and dropped:
// the user needs CREATEDB). Robots are processes (this program started again with
// --robot-run), each with its own connections.
#include "common/cli_support.hpp"
#include "common/synthetic_memory.hpp"

#include <vmap/io/frame_source.hpp>
#include <vmap/io/poses.hpp>
#include <vmap/io/postgres.hpp>
#include <vmap/lcd/evaluation.hpp>
#include <vmap/memory/fleet.hpp>
#include <vmap/memory/records.hpp>
#include <vmap/memory/vmem.hpp>
#include <vmap/place/heavy_words.hpp>
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
#include <fstream>
#include <map>
#include <optional>
#include <string>
#include <thread>
#include <tuple>
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

/// Every 5th frame is held out of the maps and localized.
bool held_out(std::size_t i) { return i % 5 == 4; }

/// The robot processes: this program (`self`) once per robot with --robot-run, all
/// started at once; each maps frames [first, last) of `input` (skipping the held-out ones
/// when `hold`) into the fleet at `uri` with the vocabulary file `vocabulary`. The time of
/// each push that made a key image, of every robot.
std::vector<double> run_robot_processes(const std::string& self, const std::string& uri, const fs::path& input,
                                        const std::vector<Part>& parts, bool hold, const fs::path& vocabulary) {
  std::vector<FILE*> robots;
  for (std::size_t r = 0; r < parts.size(); ++r) {
    const std::string cmd = "'" + self + "' --uri '" + uri + "' --robot-run r" + std::to_string(r) + " --input '" +
                            input.string() + "' --first " + std::to_string(parts[r].first) + " --last " +
                            std::to_string(parts[r].last) + (hold ? " --hold" : "") + " --vocabulary-file '" +
                            vocabulary.string() + "' --robot-uri '" + uri + "'";
    FILE* p = popen(cmd.c_str(), "r");
    if (!p) throw std::runtime_error("cannot start a robot process");
    robots.push_back(p);
  }
  std::vector<double> all;
  bool failed = false;
  for (FILE* p : robots) {
    char line[64];
    while (std::fgets(line, sizeof line, p)) all.push_back(std::strtod(line, nullptr));
    failed |= pclose(p) != 0;
  }
  if (failed) throw std::runtime_error("a robot process failed");
  return all;
}

/// A loop between two runs: (run, frame of its key image) of each end, the lower run
/// first; and the verification's inliers.
using RunKey = std::pair<std::size_t, std::size_t>;
using RunPairs = std::map<std::pair<RunKey, RunKey>, int>;
void add_pair(RunPairs& pairs, RunKey a, RunKey b, int inliers) {
  if (b < a) std::swap(a, b);
  pairs[{a, b}] = inliers;
}

/// Of the queries of the place rule between runs, the most candidates one had (key
/// images of the runs it asks whose heavy score reached run_link_min_score), and how many
/// had more than run_link_candidates: between sessions a run asks the runs before it,
/// between robots (`all`) every other run.
std::pair<std::size_t, std::size_t> most_candidates(const std::vector<std::vector<std::vector<vmap::HeavyWord>>>& runs,
                                                   bool all) {
  const std::uint64_t min = vmap::heavy_units(vmap::run_link_min_score);
  std::size_t most = 0, over = 0;
  for (std::size_t r = 0; r < runs.size(); ++r)
    for (const auto& q : runs[r]) {
      std::size_t n = 0;
      for (std::size_t o = 0; o < (all ? runs.size() : r); ++o)
        if (o != r)
          for (const auto& k : runs[o]) n += vmap::heavy_score_units(q, k) >= min ? 1 : 0;
      most = std::max(most, n);
      over += n > vmap::run_link_candidates ? 1 : 0;
    }
  return {most, over};
}

/// The heavy words of each key image of `memory` (those of session `session` only, or all).
std::vector<std::vector<vmap::HeavyWord>> heavy_of(const vmap::AnyMemory& memory, const vmap::AnyVocabulary& vocabulary,
                                                   std::optional<std::size_t> session = std::nullopt) {
  std::vector<std::vector<vmap::HeavyWord>> out;
  for (std::size_t k = 0; k < memory.key_images(); ++k)
    if (!session || memory.session_of(k) == *session)
      out.push_back(vmap::heavy_words(vocabulary.transform(memory.key_features(static_cast<std::uint32_t>(k)).descriptors)));
  return out;
}

struct SameRow {
  std::size_t fleet_loops = 0, fleet_true = 0, sqlite_loops = 0, sqlite_true = 0, both = 0, same_inliers = 0;
  std::size_t fleet_most = 0, fleet_over = 0, sqlite_most = 0, sqlite_over = 0;
  std::size_t held = 0, fleet_placed = 0, sqlite_placed = 0, same_frame = 0;
};

/// Section 1 for one sequence: robot processes mapping `parts` at once, against one SQLite
/// memory of the parts as sessions.
SameRow same_answers(const std::string& server, const std::string& db, const fs::path& input,
                     const std::vector<vmap::Frame>& frames, const vmap::LoopGroundTruth& gt,
                     const std::vector<Part>& parts, const fs::path& work, const std::string& self) {
  const std::string uri = fresh_database(server, db);
  const vmap::AnyVocabulary vocabulary = learn_vocabulary(frames);
  const fs::path vocabulary_file = work / (db + "_vocabulary.bin");
  fs::remove(vocabulary_file);
  vocabulary.save(vocabulary_file);
  const vmap::PolicyStack stack;
  SameRow row;
  (void)run_robot_processes(self, uri, input, parts, true, vocabulary_file);
  // One SQLite memory, the parts as sessions in order.
  const fs::path file = work / (db + ".vmdb");
  fs::remove(file);
  auto one = vmap::AnyMemory::create(file, stack, {}, vocabulary, {});
  for (std::size_t r = 0; r < parts.size(); ++r) {
    if (r > 0) one.start_session();
    for (std::size_t i = parts[r].first; i < parts[r].last; ++i)
      if (!held_out(i)) (void)one.push(frames[i]);
  }
  one.close();
  auto fleet = vmap::FleetMemory::open(uri);
  std::map<std::string, std::size_t> robot_of;
  for (std::size_t r = 0; r < fleet.robots().size(); ++r) robot_of[fleet.robots()[r]] = r;
  const auto run_of = [&](const std::string& robot) { return static_cast<std::size_t>(std::stoul(robot.substr(1))); };
  RunPairs by_fleet, by_sqlite;
  for (const auto& l : vmap::fleet_loops(uri)) {
    const auto fa = fleet.memory(robot_of[l.from_robot]).map().keys[l.from_key].frame_index;
    const auto fb = fleet.memory(robot_of[l.to_robot]).map().keys[l.to_key].frame_index;
    add_pair(by_fleet, {run_of(l.from_robot), fa}, {run_of(l.to_robot), fb}, l.link.inliers);
  }
  for (const auto& e : one.loops())
    if (one.session_of(e.from) != one.session_of(e.link.key))
      add_pair(by_sqlite, {one.session_of(e.from), one.map().keys[e.from].frame_index},
               {one.session_of(e.link.key), one.map().keys[e.link.key].frame_index}, e.link.inliers);
  // True: the ground truth's revisit, or the same or the next frame (where the parts
  // overlap, two robots saw the same frames; the ground truth lists revisits only).
  const auto truth = [&](const auto& p) {
    const std::size_t a = std::min(p.first.first.second, p.first.second.second);
    const std::size_t b = std::max(p.first.first.second, p.first.second.second);
    return b - a <= 1 || gt(b, a);
  };
  for (const auto& p : by_fleet) row.fleet_true += truth(p) ? 1 : 0;
  for (const auto& p : by_sqlite) row.sqlite_true += truth(p) ? 1 : 0;
  for (const auto& [pair, inliers] : by_fleet) {
    const auto it = by_sqlite.find(pair);
    row.both += it != by_sqlite.end() ? 1 : 0;
    row.same_inliers += it != by_sqlite.end() && it->second == inliers ? 1 : 0;
  }
  row.fleet_loops = by_fleet.size();
  row.sqlite_loops = by_sqlite.size();
  // The candidates each query had, on both sides.
  std::vector<std::vector<std::vector<vmap::HeavyWord>>> sessions, robots(parts.size());
  for (std::size_t r = 0; r < parts.size(); ++r) sessions.push_back(heavy_of(one, vocabulary, r));
  for (std::size_t r = 0; r < fleet.robots().size(); ++r)
    robots[run_of(fleet.robots()[r])] = heavy_of(fleet.memory(r), vocabulary);
  std::tie(row.sqlite_most, row.sqlite_over) = most_candidates(sessions, false);
  std::tie(row.fleet_most, row.fleet_over) = most_candidates(robots, true);
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

void print_same(const char* name, const std::string& cut, const SameRow& r) {
  std::printf("| %s | %s | %zu (%zu) | %zu (%zu) | %zu | %zu | %zu, %zu | %zu, %zu | %zu | %zu, %zu | %zu |\n", name,
              cut.c_str(), r.fleet_loops, r.fleet_true, r.sqlite_loops, r.sqlite_true, r.both, r.same_inliers,
              r.fleet_most, r.fleet_over, r.sqlite_most, r.sqlite_over, r.held, r.fleet_placed, r.sqlite_placed,
              r.same_frame);
  std::fflush(stdout);
}

void same_section(const std::string& server, const fs::path& shared, const fs::path& work, const std::string& self) {
  std::printf("\n## 1. Same answers: robot processes at the same time against one SQLite memory of the parts as "
              "sessions\n\n");
  std::printf("| sequence | parts | loops between robots (true) | loops between sessions, SQLite (true) | in both | "
              "same inliers | most candidates of a query, over %zu: fleet | SQLite | held out | placed: fleet, SQLite | "
              "same key frame |\n|---|---|---|---|---|---|---|---|---|---|---|\n",
              vmap::run_link_candidates);
  // Poses within 0.5 m and 30 degrees are one place, however close in time.
  const vmap::PoseLoopOptions pose_gt{.max_distance = 0.5, .max_angle_deg = 30, .window = 0};
  {
    const fs::path input = shared / "data/rtabmap_loop/images";
    const auto frames = read_grey(input);
    const auto gt = vmap::LoopGroundTruth::load(shared / "data/rtabmap_loop/gt_loop_matrix_84x84.txt", frames.size());
    const std::vector<Part> parts{{0, 34}, {25, 60}, {50, frames.size()}};
    print_same("rtabmap_loop", "3: 0-33, 25-59, 50-83",
               same_answers(server, "bench_same_rtabmap", input, frames, gt, parts, work, self));
  }
  {
    const fs::path input = shared / "data/tum_fr1_rpy/rgb.txt";
    const auto frames = read_grey(input);
    std::vector<double> t;
    for (const auto& f : frames) t.push_back(f.timestamp);
    const fs::path poses = shared / "data/tum_fr1_rpy/groundtruth.txt";
    const auto gt = vmap::ground_truth_from_poses(
        vmap::poses_for_frames(vmap::load_tum_poses(poses), t, poses.string(), 0.05, false), pose_gt);
    const std::size_t n = frames.size();
    const std::vector<Part> parts{{0, n * 11 / 20}, {n * 9 / 20, n}};
    print_same("tum_fr1_rpy",
               "2: 0-" + std::to_string(n * 11 / 20 - 1) + ", " + std::to_string(n * 9 / 20) + "-" + std::to_string(n - 1),
               same_answers(server, "bench_same_rpy", input, frames, gt, parts, work, self));
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
  std::size_t keys = 0;
  std::size_t between_runs = 0;  ///< loops to other runs: other robots' (fleet) or earlier sessions' (SQLite)
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
    l.between_runs += s.fleet_loops.size();
    for (const auto& e : s.loops) l.between_runs += memory.session_of(e.from) != memory.session_of(e.link.key) ? 1 : 0;
  }
  memory.close();
  l.seconds = ms_since(t0) / 1000.0;
  return l;
}

void latency_section(const std::string& server, const fs::path& shared, const fs::path& work,
                     const std::vector<std::size_t>& sizes) {
  std::printf("\n## 2. Latency per key image (push + sync + the loop queries with verification of the candidates)\n\n");
  const auto frames = read_grey(shared / "data/tum_fr1_rpy/rgb.txt");
  const vmap::AnyVocabulary vocabulary = learn_vocabulary(frames);
  const vmap::PolicyStack stack;
  const std::size_t probe_first = 300, probe_last = 500;
  // The runs repeated: frames 0-299 mapped once.
  const fs::path seed_file = work / "latency_seed.vmdb";
  fs::remove(seed_file);
  vmap::MemoryRecords seed;
  {
    auto m = vmap::AnyMemory::create(seed_file, stack, {}, vocabulary, {});
    for (std::size_t i = 0; i < probe_first; ++i) (void)m.push(frames[i]);
    seed = m.records();
    m.close();
  }
  const std::size_t per_run = seed.keys.size();
  std::printf("| key images of other runs | SQLite p50 ms | p99 ms | fleet p50 ms | p99 ms | p50 fleet / SQLite | p99 fleet "
              "/ SQLite | loops to other runs: fleet, SQLite | server's ranking, p50 ms | one candidate's features, p50 "
              "ms |\n|---|---|---|---|---|---|---|---|---|---|\n");
  std::vector<std::size_t> all{0};
  all.insert(all.end(), sizes.begin(), sizes.end());
  for (const std::size_t wanted : all) {
    // Whole runs: copies of the seed's key images.
    const std::size_t copies = wanted == 0 ? 0 : std::max<std::size_t>(1, (wanted + per_run / 2) / per_run);
    const std::size_t n = copies * per_run;
    // SQLite: the copies as earlier sessions of the probe's memory, which holds the
    // features of its 256 most recent key images in RAM (the store reads the others).
    Latency sqlite;
    {
      const fs::path file = work / ("latency_" + std::to_string(n) + ".vmdb");
      fs::remove(file);
      const auto t0 = Clock::now();
      if (copies > 0) {
        const fs::path vmem = work / "latency_runs.vmem";
        {
          std::ofstream out(vmem, std::ios::binary | std::ios::trunc);
          const std::string bytes = vmap::detail::vmem_file_bytes(vmap::examples::repeated_records(seed, copies), seed.options.images);
          out.write(bytes.data(), static_cast<std::streamsize>(bytes.size()));
        }
        auto runs = vmap::AnyMemory::copy_into_store(vmap::AnyMemory::open(vmem), file);
        runs.close();
        fs::remove(vmem);
        std::fprintf(stderr, "bench_fleet: SQLite, %zu key images written in %.1f s\n", n, ms_since(t0) / 1000.0);
        auto m = vmap::AnyMemory::open(file, {.write = true, .new_session = true, .working_memory = 256});
        sqlite = run_robot(m, frames, probe_first, probe_last);
      } else {
        auto m = vmap::AnyMemory::create(file, stack, {}, vocabulary, {});
        sqlite = run_robot(m, frames, probe_first, probe_last);
      }
      fs::remove(file);
    }
    // The fleet: a seed robot that mapped frames 0-299, and a filler robot holding the
    // other copies' rows.
    const std::string uri = fresh_database(server, "bench_latency_" + std::to_string(n));
    if (copies > 0) {
      auto m = vmap::AnyMemory::create(uri, stack, {}, vocabulary, {.robot = "seed"});
      for (std::size_t i = 0; i < probe_first; ++i) (void)m.push(frames[i]);
      m.close();
      if (copies > 1) {
        const auto t0 = Clock::now();
        fill(uri, "seed", n - per_run);
        std::fprintf(stderr, "bench_fleet: fleet, %zu key images written in %.1f s\n", n, ms_since(t0) / 1000.0);
      }
    }
    auto m = vmap::AnyMemory::create(uri, stack, {}, vocabulary, {.robot = "probe"});
    const Latency l = run_robot(m, frames, probe_first, probe_last);
    // The two server-side parts of a loop query, alone: the ranking in the inverted file,
    // and reading one candidate's features.
    std::vector<double> rank_ms, fetch_ms;
    if (copies > 0) {
      vmap::FleetIndex fleet(uri, "probe");
      vmap::detail::StoreDb db(vmap::pg::Connection(uri, "bench"));
      auto q = db.prepare("SELECT vocabulary FROM vmap.postings p JOIN vmap.robots r ON r.id = p.robot "
                          "WHERE r.name = 'probe' LIMIT 1", "read the vocabulary");
      const std::int64_t crc = q.step() ? q.integer(0) : 0;
      for (const vmap::BowVector& bow : m.records().bows) {
        const auto t = Clock::now();
        const auto ranked = fleet.candidates(bow, crc);
        rank_ms.push_back(ms_since(t));
        if (ranked.empty()) continue;
        const auto tf = Clock::now();
        (void)fleet.features(ranked[0]);
        fetch_ms.push_back(ms_since(tf));
      }
    }
    const double s50 = percentile(sqlite.key_ms, 0.5), s99 = percentile(sqlite.key_ms, 0.99);
    const double p50 = percentile(l.key_ms, 0.5), p99 = percentile(l.key_ms, 0.99);
    std::printf("| %zu | %.1f | %.1f | %.1f | %.1f | %.2f | %.2f | %zu, %zu | %.1f | %.2f |\n", n, s50, s99, p50, p99,
                p50 / s50, p99 / s99, l.between_runs, sqlite.between_runs, percentile(rank_ms, 0.5),
                percentile(fetch_ms, 0.5));
    std::fflush(stdout);
  }
}

constexpr std::size_t scale_frames = 80;  ///< frames each robot of the scale section pushes

/// One robot process (`--robot-run`): robot `name` pushes frames [first, last) of `input`
/// (without the held-out ones when `hold`) into `uri`, with the vocabulary file
/// `vocabulary`; prints the time of each push that made a key image, one per line.
int robot_process(const std::string& uri, const fs::path& input, const std::string& name, std::size_t first,
                  std::size_t last, bool hold, const std::string& vocabulary) {
  // Only its own frames are read (decoding the whole sequence in every process would
  // count in the rate).
  auto src = vmap::FrameSource::open(input, {.start = first, .end = last, .grey = true});
  std::vector<vmap::Frame> frames;
  while (auto f = src.next())
    if (!hold || !held_out(f->index)) frames.push_back(std::move(*f));
  auto m = vmap::AnyMemory::create(uri, vmap::PolicyStack{}, {}, vmap::AnyVocabulary::load(vocabulary), {.robot = name});
  const Latency l = run_robot(m, frames, 0, frames.size());
  for (const double ms : l.key_ms) std::printf("%.3f\n", ms);
  return 0;
}

void scale_section(const std::string& server, const fs::path& shared, const fs::path& work, const std::string& self) {
  std::printf("\n## 3. Robot processes mapping at the same time on one machine (%u cores)\n\n",
              std::thread::hardware_concurrency());
  const fs::path input = shared / "data/tum_fr1_rpy/rgb.txt";
  const auto frames = read_grey(input);
  const fs::path vocabulary = work / "scale_vocabulary.bin";
  fs::remove(vocabulary);
  learn_vocabulary(frames).save(vocabulary);
  std::printf("| robots | key images | seconds | key images / s (all robots) | p50 ms | p99 ms | loops between robots "
              "|\n|---|---|---|---|---|---|---|\n");
  for (const std::size_t n : {1, 2, 4, 8}) {
    const std::string uri = fresh_database(server, "bench_scale_" + std::to_string(n));
    std::vector<Part> parts;
    for (std::size_t r = 0; r < n; ++r) {
      const std::size_t first = (r * 83) % (frames.size() - scale_frames);
      parts.push_back({first, first + scale_frames});
    }
    const auto t0 = Clock::now();
    const std::vector<double> all = run_robot_processes(self, uri, input, parts, false, vocabulary);
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
  std::string robot_run, robot_uri, vocabulary_file, input;
  std::size_t first = 0, last = 0;
  bool hold = false;
  app.add_option("--robot-run", robot_run, "(internal) map as this robot, then print each key image's time");
  app.add_option("--robot-uri", robot_uri, "(internal) the fleet the robot maps into");
  app.add_option("--input", input, "(internal) the robot's sequence");
  app.add_option("--first", first, "(internal) the robot's first frame");
  app.add_option("--last", last, "(internal) one past the robot's last frame");
  app.add_flag("--hold", hold, "(internal) skip the held-out frames");
  app.add_option("--vocabulary-file", vocabulary_file, "(internal) the fleet's vocabulary");
  CLI11_PARSE(app, argc, argv);
  try {
    if (!robot_run.empty()) return robot_process(robot_uri, input, robot_run, first, last, hold, vocabulary_file);
    fs::create_directories(work);
    std::printf("# bench_fleet (%s, vocabulary of 10^%d words)\n", vmap::pg::redacted(uri).c_str(), vocabulary_depth);
    const std::string self = fs::canonical("/proc/self/exe").string();
    if (part == "same" || part == "all") same_section(uri, shared, work, self);
    if (part == "latency" || part == "all") latency_section(uri, shared, work, sizes);
    if (part == "scale" || part == "all") scale_section(uri, shared, work, self);
  } catch (const std::exception& e) {
    std::fprintf(stderr, "bench_fleet: %s\n", e.what());
    return 1;
  }
  return 0;
}
