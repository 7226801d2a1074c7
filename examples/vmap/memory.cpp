// `vmap memory localize|info|export|convert|merge`: a visual memory (include/vmap/memory)
// kept in a memory store or a .vmem file, read and written through the library's
// run-time layer (include/vmap/runtime). `localize M QUERY...` answers the key image each
// query matches; `info M` lists the sessions, key images (--keys) and loop edges;
// `export` writes them for other tools; `convert` writes any memory into a new store;
// `merge A B` joins two. `vmap memory build` is `vmap build --memory` (main.cpp).
#include "common/cli_support.hpp"
#include "common/memory_cli.hpp"
#include "vmap/cli.hpp"

#include <vmap/memory/fleet.hpp>
#include <vmap/runtime/exports.hpp>
#include <vmap/runtime/memory.hpp>
#include <vmap/runtime/recorder.hpp>

#include <nlohmann/json.hpp>

#include <algorithm>
#include <chrono>
#include <cstdio>
#include <filesystem>
#include <functional>
#include <memory>
#include <optional>
#include <string>
#include <vector>

namespace {

namespace ex = vmap::examples;

struct MemoryArgs {
  std::string memory, out;
  std::vector<std::string> queries;
  bool force = false, json = false, edges = false, keys = false;
  std::string convert_in, convert_out;
  std::string merge_a, merge_b;
  std::string export_out;
  std::string robot;                     // --robot NAME: the robot of a fleet's memory (a postgresql:// URI)
  std::optional<double> min_confidence;  // localize: the query's threshold
  ex::SequenceArgs sequence;             // localize: --sequence, --max-speed
};

/// One session of a memory as `memory info` shows it.
struct SessionInfo {
  std::size_t first_key = 0, key_images = 0, frames = 0;
  std::size_t loops_within = 0, loops_across = 0;  ///< edges from its key images: into it, into an earlier session
  std::optional<std::string> input;                ///< the input its run recorded (stores)
  std::optional<std::uintmax_t> bytes;             ///< its key images' rows (stores)
};

std::vector<SessionInfo> session_infos(vmap::AnyMemory& mem) {
  const auto& sessions = mem.sessions();
  std::vector<SessionInfo> out(sessions.size());
  for (std::size_t s = 0; s < sessions.size(); ++s) {
    const bool last = s + 1 == sessions.size();
    out[s].first_key = sessions[s].first_key;
    out[s].key_images = (last ? mem.key_images() : sessions[s + 1].first_key) - sessions[s].first_key;
    out[s].frames = (last ? mem.frames() : sessions[s + 1].first_frame) - sessions[s].first_frame;
  }
  for (const auto& e : mem.loops()) {
    const std::size_t from = mem.session_of(e.from);
    ++(from == mem.session_of(e.link.key) ? out[from].loops_within : out[from].loops_across);
  }
  if (mem.kind() != vmap::MemoryKind::store || !mem.store()) return out;
  vmap::MemoryStore& store = *mem.store();
  const auto bytes = store.key_image_bytes();
  for (std::size_t s = 0; s < out.size(); ++s) {
    if (auto input = vmap::session_input_of(store, s)) out[s].input = input->input;
    std::uintmax_t b = 0;
    for (std::size_t k = out[s].first_key; k < out[s].first_key + out[s].key_images && k < bytes.size(); ++k) b += bytes[k];
    out[s].bytes = b;
  }
  return out;
}

/// `memory info URI` without --robot: each robot of a fleet's memory, and the loops
/// between robots.
int fleet_info(const MemoryArgs& a) {
  const auto robots = vmap::fleet_summary(a.memory);
  const auto loops = vmap::fleet_loops(a.memory);
  const std::string shown = vmap::pg::redacted(a.memory);
  if (robots.empty()) vmap::detail::fail(vmap::ErrorKind::not_found, "memory '" + shown + "' holds no robot's memory");
  if (a.json) {
    nlohmann::json rs = nlohmann::json::array(), ls = nlohmann::json::array();
    for (const auto& r : robots)
      rs.push_back({{"robot", r.robot}, {"frames", r.frames}, {"key_images", r.key_images}, {"sessions", r.sessions},
                    {"loops", r.loops}, {"fleet_loops", r.fleet_loops}, {"linked", r.linked}});
    for (const auto& l : loops)
      ls.push_back({{"from_robot", l.from_robot}, {"from", l.from_key}, {"to_robot", l.to_robot}, {"to", l.to_key},
                    {"inliers", l.link.inliers}, {"confidence", l.link.confidence}});
    ex::print_json({{"memory", shown}, {"robots", rs}, {"fleet_loops", ls}});
    return 0;
  }
  std::printf("%s: %zu robots, %zu loop edges between robots\n", shown.c_str(), robots.size(), loops.size());
  std::printf("  %-20s  %7s  %10s  %8s  %10s  %16s\n", "robot", "frames", "key images", "sessions", "loop edges",
              "to other robots");
  for (const auto& r : robots)
    std::printf("  %-20s  %7zu  %10zu  %8zu  %10zu  %16zu\n", r.robot.c_str(), r.frames, r.key_images, r.sessions, r.loops,
                r.fleet_loops);
  const std::size_t shown_loops = a.edges ? loops.size() : std::min<std::size_t>(loops.size(), 5);
  if (shown_loops > 0) std::printf("%s:\n", a.edges ? "loop edges between robots" : "the first loop edges between robots");
  for (std::size_t i = 0; i < shown_loops; ++i) {
    const auto& l = loops[i];
    std::printf("  %s key %u -> %s key %u: %d inliers, confidence %.3f\n", l.from_robot.c_str(), l.from_key,
                l.to_robot.c_str(), l.to_key, l.link.inliers, l.link.confidence);
  }
  return 0;
}

int info(const MemoryArgs& a) {
  if (vmap::pg::is_uri(a.memory) && a.robot.empty()) return fleet_info(a);
  const auto file = vmap::memory_path(a.memory);
  ex::current_inputs() = {file.string()};
  auto mem = ex::open_memory_input(file, "memory", false, a.robot);
  const auto sessions = session_infos(mem);
  const auto file_bytes = ex::memory_bytes(file);
  if (a.json) {
    nlohmann::json keys = nlohmann::json::array(), loops = nlohmann::json::array(), sess = nlohmann::json::array();
    for (std::size_t k = 0; k < mem.key_images(); ++k) keys.push_back(ex::key_json(mem, k));
    for (const auto& e : mem.loops()) loops.push_back(ex::loop_json(mem, e));
    for (const auto& s : sessions)
      sess.push_back({{"first_key", s.first_key},
                      {"key_images", s.key_images},
                      {"frames", s.frames},
                      {"loops_within", s.loops_within},
                      {"loops_across", s.loops_across},
                      {"input", s.input ? nlohmann::json(*s.input) : nlohmann::json(nullptr)},
                      {"bytes", s.bytes ? nlohmann::json(*s.bytes) : nlohmann::json(nullptr)}});
    ex::print_json({{"stack", ex::stack_json(mem.stack())},
                    {"frames", mem.frames()},
                    {"last_frame_index", mem.last_frame_index() ? nlohmann::json(*mem.last_frame_index()) : nlohmann::json(nullptr)},
                    {"bytes", file_bytes ? nlohmann::json(*file_bytes) : nlohmann::json(nullptr)},
                    {"robot", a.robot.empty() ? nlohmann::json(nullptr) : nlohmann::json(a.robot)},
                    {"sessions", sess},
                    {"key_images", keys},
                    {"stationary", mem.stationary()},
                    {"loops", loops}});
    return 0;
  }
  std::printf("%zu frames, %zu key images, %zu loop edges, vocabulary of %zu words, last frame %zu (%s)\n", mem.frames(),
              mem.key_images(), mem.loops().size(), mem.vocabulary().size(), mem.last_frame_index().value_or(0),
              vmap::summary(mem.stack()).c_str());
  if (sessions.size() > 1) {
    if (file_bytes)
      std::printf("%zu sessions (%ju bytes in all):\n", sessions.size(), static_cast<std::uintmax_t>(*file_bytes));
    else
      std::printf("%zu sessions:\n", sessions.size());
    for (std::size_t s = 0; s < sessions.size(); ++s) {
      const auto& i = sessions[s];
      std::printf("  session %zu: %zu frames, %zu key images (from key %zu), %zu loop edges within, %zu to earlier "
                  "sessions",
                  s, i.frames, i.key_images, i.first_key, i.loops_within, i.loops_across);
      if (i.bytes) std::printf(", %ju bytes of key images", *i.bytes);
      if (i.input) std::printf(", from %s", i.input->c_str());
      std::printf("\n");
    }
  }
  if (a.keys) {
    std::printf("  %4s  %7s  %6s  %-28s  %s\n", "key", "session", "frame", "name", "time (s, to the ns)");
    for (std::size_t k = 0; k < mem.key_images(); ++k) {
      const vmap::KeyImage& key = mem.map().keys[k];
      std::printf("  %4zu  %7zu  %6zu  %-28s  %s%s\n", k, mem.session_of(k), key.frame_index, key.name.c_str(),
                  vmap::seconds_text(key.time_ns).c_str(), ex::pose_text(mem.poses()[k]).c_str());
    }
  }
  if (mem.stationary()) std::printf("the camera never left its place: no key image is a revisit\n");
  ex::print_loop_edges(mem, a.edges);
  return 0;
}

/// `memory convert IN OUT`: a memory of either kind (a .vmem file of any version, or a
/// store) written into a new memory store.
int convert(const MemoryArgs& a) {
  namespace fs = std::filesystem;
  ex::current_inputs() = {a.convert_in};
  const fs::path out = a.convert_out;
  const bool fleet_in = vmap::pg::is_uri(a.convert_in), fleet_out = vmap::pg::is_uri(a.convert_out);
  if (fleet_in && fleet_out)
    ex::usage_error("INPUT and OUTPUT are both fleets' memories: convert one robot through a file (--robot names one)");
  if (!fleet_in && !fleet_out && !a.robot.empty()) ex::usage_error("--robot needs INPUT or OUTPUT to be a fleet's memory");
  ex::prepare_memory_output(out, "OUTPUT", fleet_in ? std::vector<fs::path>{} : std::vector<fs::path>{a.convert_in}, false,
                            a.force, a.robot);
  const auto t0 = std::chrono::steady_clock::now();
  auto mem = ex::open_memory_input(a.convert_in, "INPUT", true, fleet_in ? a.robot : "");
  std::optional<vmap::AnyMemory> written;
  ex::NewMemoryGuard guard(written, true, out.native());
  // A new OUTPUT appears only complete, when the command ends (as merge's): killed, it
  // leaves no file there.
  written.emplace(vmap::AnyMemory::copy_into_store(
      std::move(mem), out, {.robot = fleet_out ? a.robot : "", .replace = a.force && !fleet_out, .whole_at_close = !fleet_out}));
  written->close();
  guard.keep();
  const double seconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
  const auto& m = *written;
  if (a.json) {
    const auto bytes = ex::memory_bytes(out);
    ex::print_json({{"input", fleet_in ? vmap::pg::redacted(a.convert_in) : ex::path_string(a.convert_in)},
                    {"memory", ex::path_string(m.path())}, {"robot", a.robot.empty() ? nlohmann::json(nullptr) : nlohmann::json(a.robot)},
                    {"frames", m.frames()}, {"key_images", m.key_images()}, {"loops", m.loops().size()},
                    {"bytes", bytes ? nlohmann::json(*bytes) : nlohmann::json(nullptr)}, {"seconds", seconds}});
    return 0;
  }
  const auto bytes = ex::memory_bytes(out);
  std::printf("%s: %zu frames, %zu key images, %zu loop edges (%s) from %s in %.2f s\n", m.name().c_str(), m.frames(),
              m.key_images(), m.loops().size(),
              bytes ? ("memory store, " + std::to_string(*bytes) + " bytes").c_str() : "on the fleet's server",
              fleet_in ? ("robot '" + a.robot + "' of memory '" + vmap::pg::redacted(a.convert_in) + "'").c_str()
                       : a.convert_in.c_str(),
              seconds);
  return 0;
}

/// `memory merge A B --out C`: B's sessions appended to A's, loops searched from B's key
/// images into every key image before them (VisualMemory::merge: C equals the memory
/// built from A's runs and then B's as new sessions). C is written under a unique
/// temporary name beside it and renamed when complete (MemoryCreateOptions: replace,
/// whole_at_close), so C is never half written, an existing C (with --force) is replaced
/// whole or not at all, and a C another run made meanwhile is not overwritten.
int merge(const MemoryArgs& a) {
  namespace fs = std::filesystem;
  ex::current_inputs() = {a.merge_a, a.merge_b};
  for (const auto& [in, option] : {std::pair{a.merge_a, "A"}, std::pair{a.merge_b, "B"}}) {
    if (vmap::pg::is_uri(in))
      ex::usage_error(std::string(option) + ": merge reads memory files; a fleet's robot is written into one with "
                      "vmap memory convert URI FILE --robot NAME");
    ex::check_memory_input(in, option);
  }
  std::error_code ec;
  if (fs::equivalent(a.merge_a, a.merge_b, ec))
    ex::usage_error("A and B are the same memory ('" + a.merge_a + "'): merging it with itself would add each of its "
                    "runs again as a new session");
  const fs::path out = vmap::memory_path(a.out);
  const bool fleet_out = vmap::pg::is_uri(out.native());
  if (!fleet_out && !a.robot.empty()) ex::usage_error("--robot needs --out to be a fleet's memory (a postgresql:// URI)");
  ex::prepare_memory_output(out, "--out", {a.merge_a, a.merge_b}, false, a.force, a.robot);
  const auto t0 = std::chrono::steady_clock::now();
  auto mem = vmap::AnyMemory::open(a.merge_a, {.pixels = true});
  auto other = vmap::AnyMemory::open(a.merge_b, {.pixels = true});
  const std::size_t keys_a = mem.key_images(), loops_a = mem.loops().size();
  // The inputs each session was built from (a store's notes), renumbered.
  std::vector<std::optional<vmap::RecordedInput>> inputs;
  for (auto* m : {&mem, &other})
    for (std::size_t s = 0; s < m->sessions().size(); ++s) inputs.push_back(vmap::session_input(*m, s));
  auto written =
      vmap::AnyMemory::copy_into_store(std::move(mem), out,
                                       {.robot = a.robot, .replace = a.force && !fleet_out, .whole_at_close = true});
  written.merge(std::move(other), "memory '" + a.merge_a + "'", "memory '" + a.merge_b + "'");
  for (std::size_t s = 0; s < inputs.size(); ++s)
    if (inputs[s]) vmap::set_session_input_of(*written.store(), s, *inputs[s]);
  written.close();
  const auto& m = written;
  const std::size_t frames = m.frames(), key_images = m.key_images(), loops = m.loops().size(), sessions = m.sessions().size();
  std::size_t across = 0;
  for (const auto& e : m.loops()) across += m.session_of(e.from) != m.session_of(e.link.key) ? 1 : 0;
  const double seconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
  const auto bytes = ex::memory_bytes(out);
  if (a.json) {
    ex::print_json({{"a", ex::path_string(a.merge_a)}, {"b", ex::path_string(a.merge_b)}, {"memory", ex::path_string(m.path())},
                    {"robot", a.robot.empty() ? nlohmann::json(nullptr) : nlohmann::json(a.robot)},
                    {"sessions", sessions}, {"frames", frames}, {"key_images", key_images}, {"loops", loops},
                    {"new_loops", loops - loops_a}, {"loops_across_sessions", across},
                    {"bytes", bytes ? nlohmann::json(*bytes) : nlohmann::json(nullptr)}, {"seconds", seconds}});
    return 0;
  }
  std::printf("%s: %zu sessions, %zu frames, %zu key images (%zu from A), %zu loop edges (%zu found for B's key "
              "images, %zu across sessions)%s, in %.2f s\n",
              m.name().c_str(), sessions, frames, key_images, keys_a, loops, loops - loops_a, across,
              bytes ? (", " + std::to_string(*bytes) + " bytes").c_str() : "", seconds);
  return 0;
}

/// `memory export M --out DIR`: key images, trajectory and loop edges for other tools.
int export_files(const MemoryArgs& a) {
  const auto file = vmap::memory_path(a.memory);
  ex::current_inputs() = {file.string()};
  ex::OutputFolder out(a.export_out, "--out", vmap::pg::is_uri(file.native()) ? std::vector<std::filesystem::path>{}
                                                                                : std::vector<std::filesystem::path>{file},
                       vmap::memory_export_files());
  auto mem = ex::open_memory_input(file, "memory", false, a.robot);
  vmap::G2oExportCounts g2o;
  const auto written = vmap::export_memory(mem, out.path(), true, {}, &g2o);
  out.commit();
  const bool graph = std::find(written.begin(), written.end(), "loops.g2o") != written.end();
  if (a.json) {
    ex::print_json({{"memory", ex::path_string(file)}, {"out", a.export_out}, {"files", written},
                    {"key_images", mem.key_images()}, {"loops", mem.loops().size()},
                    {"g2o", graph ? nlohmann::json{{"vertices", g2o.vertices},
                                                   {"odometry_edges", g2o.odometry_edges},
                                                   {"loop_edges", g2o.loop_edges},
                                                   {"loops_without_metric_pose", g2o.loops_unmeasured}}
                                  : nlohmann::json(nullptr)}});
    return 0;
  }
  std::printf("%zu key images, %zu loop edges: wrote %s\n", mem.key_images(), mem.loops().size(),
              ex::written_files(a.export_out, written).c_str());
  if (graph)
    std::printf("loops.g2o: %zu vertices, %zu odometry edges, %zu loop edges with a metric pose (%zu without one: "
                "no camera, or the geometry did not hold)\n",
                g2o.vertices, g2o.odometry_edges, g2o.loop_edges, g2o.loops_unmeasured);
  return 0;
}

std::function<int()> setup(CLI::App& app) {
  auto a = std::make_shared<MemoryArgs>();
  app.require_subcommand(1);
  auto* l = app.add_subcommand("localize", "The key image(s) each query image matches");
  l->add_option("memory", a->memory, "Memory store or .vmem file (a folder: DIR/memory.vmdb)")->required();
  l->add_option("queries", a->queries, "Query images, or folders, lists, videos or bags of query images")->required();
  ex::add_bag_options(*l);
  l->add_flag("--json", a->json, "Print every answer as JSON");
  l->add_option("--min-confidence", a->min_confidence,
                "Accept a key image at this place-decision confidence in [0, 1] (default: the memory's)")
      ->check(ex::real_in(0.0, 1.0));
  ex::add_sequence_options(*l, a->sequence);
  ex::add_robot_option(*l, a->robot);
  auto* i = app.add_subcommand("info", "Sessions, key images and loop edges of a memory");
  i->add_option("memory", a->memory, "Memory store or .vmem file (a folder: DIR/memory.vmdb)")->required();
  i->add_flag("--json", a->json, "Print as JSON (every key image and loop edge)");
  i->add_flag("--keys", a->keys, "List every key image: index, session, frame, name, time to the nanosecond, pose");
  i->add_flag("--edges", a->edges, "List every loop edge (default: a summary and the 5 strongest)");
  ex::add_robot_option(*i, a->robot);
  auto* x = app.add_subcommand("export", "Key images (names, times, TUM trajectory) and loop edges (pairs, g2o) of a memory");
  x->add_option("memory", a->memory, "Memory store or .vmem file")->required();
  x->add_option("--out", a->export_out, "Folder for key_images.txt, key_images.tum, loops.txt, loops.g2o")->required();
  x->add_flag("--json", a->json, "Print the files written as JSON");
  ex::add_robot_option(*x, a->robot);
  auto* c = app.add_subcommand("convert", "Write a memory (a .vmem file of any version, or a store) into a new memory store");
  c->add_option("INPUT", a->convert_in, "Memory file (.vmem) or store")->required();
  c->add_option("OUTPUT", a->convert_out, "Memory store written (refused when it exists, unless --force)")->required();
  c->add_flag("--force", a->force, "Replace an existing memory OUTPUT");
  c->add_flag("--json", a->json, "Print the result as JSON");
  ex::add_robot_option(*c, a->robot);
  auto* g = app.add_subcommand("merge", "Join two memories made with the same options: B's sessions after A's, loops "
                                        "searched from B's key images into A's");
  g->add_option("A", a->merge_a, "Memory (store or .vmem) whose sessions come first")->required();
  g->add_option("B", a->merge_b, "Memory whose sessions are appended")->required();
  g->add_option("--out", a->out, "Memory store written (refused when it exists, unless --force)")->required();
  g->add_flag("--force", a->force, "Replace an existing memory --out");
  g->add_flag("--json", a->json, "Print the result as JSON");
  ex::add_robot_option(*g, a->robot);
  return [a, l, x, c, g]() {
    if (g->parsed()) return merge(*a);
    if (l->parsed())
      return ex::localize_from_memory(vmap::memory_path(a->memory), "memory", a->queries, a->json, a->min_confidence,
                                      a->sequence, a->robot);
    if (x->parsed()) return export_files(*a);
    if (c->parsed()) return convert(*a);
    return info(*a);
  };
}

const bool registered = vmap::cli::add_command(
    {"memory", "A visual memory: localize, info, export, convert, merge (memory build: vmap build --memory)", setup});

}  // namespace
