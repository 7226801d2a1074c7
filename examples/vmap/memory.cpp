// `vmap memory build|localize|info`: a visual memory (include/vmap/memory) kept in one
// file. `build INPUT --memory M` streams a sequence into a new memory, or with --resume
// continues the memory in M after the last frame it saw; `localize M IMAGE...` answers
// the key image each query matches (verified F-matrix, inliers, pose when known);
// `info M` lists the key images and loop edges. --json prints the answers as JSON.
// `vmap build --memory`, `vmap localize --memory` and `vmap loops --memory` do the same
// within the main subcommands; both share common/memory_cli.hpp.
#include "common/cli_support.hpp"
#include "common/keyframe_cli.hpp"
#include "common/memory_cli.hpp"
#include "common/memory_export.hpp"
#include "vmap/cli.hpp"

#include <vmap/memory/visual_memory.hpp>

#include <nlohmann/json.hpp>

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
  std::string input, out, memory, vocabulary;
  std::vector<std::string> images;
  bool resume = false, force = false, json = false, edges = false;
  std::string session;  // build: "new" adds the run as a new session
  std::string convert_in, convert_out;
  std::string merge_a, merge_b;
  std::string export_out;
  double tau = 0.3;
  double time_offset = 0.0;  // build: added to the frame times the key images keep
  std::optional<double> min_confidence;  // localize: the query's threshold; build: of loop edges
  std::string storage = "none";
  std::size_t start = 0, end = 0, stride = 1, save_every = 0;
  std::size_t working_memory = ex::default_working_memory;
  // build: the memory's policy stack (recorded in it; common/memory_cli.hpp)
  std::string features = "orb", model, refine_model, estimator = "magsac", camera;
  int nfeatures = 1000;
};

int build(const MemoryArgs& a, const CLI::App& app) {
  namespace fs = std::filesystem;
  ex::current_inputs() = {a.input};
  const fs::path file = ex::memory_file(a.out);
  const auto continuation = ex::continuation_of(a.resume, !a.session.empty(), a.force);
  const bool continued = continuation.has_value();
  const auto how = continuation.value_or(ex::Continuation::resume);
  vmap::FrameSourceOptions so{.start = a.start, .stride = a.stride, .grey = true, .time_offset = a.time_offset};
  if (a.end > 0) so.end = a.end;
  ex::MemoryStack stack;
  if (!continued) stack = ex::stack_of_args({a.features, a.nfeatures, a.model, a.refine_model}, a.estimator, a.camera, a.input);
  ex::prepare_memory_output(file, "--memory", {a.input}, continued, a.force);
  std::optional<vmap::MemoryStore> kept;
  if (continued) {
    kept.emplace(ex::store_to_continue(file, app, {"--threshold", "--images", "--vocabulary", "--min-confidence"}, how));
    stack = ex::recorded_stack(*kept);
  }
  return ex::with_stack(stack, [&](auto descriptor, auto matcher, auto estimator) -> int {
    using Memory = ex::MemoryOf<decltype(descriptor), decltype(matcher), decltype(estimator)>;
    std::optional<ex::MemoryWriter<Memory>> writer;
    std::optional<Memory> fresh;
    if (continued) {
      writer.emplace(ex::memory_to_continue(std::move(*kept), a.working_memory, how, std::move(descriptor),
                                            std::move(matcher), std::move(estimator)));
      if (a.resume) so = ex::resume_range(writer->memory, so, file.string());
    } else {
      ex::NewMemory n{.tau = a.tau, .images = a.storage, .vocabulary = a.vocabulary};
      if (a.min_confidence) n.min_confidence = *a.min_confidence;
      fresh.emplace(ex::new_memory(n, std::move(descriptor), std::move(matcher), std::move(estimator)));
    }
    auto src = ex::open_frames(a.input, so);
    const std::string fingerprint = ex::input_fingerprint(a.input, src, so.stride);
    if (continued) {
      ex::record_input(*writer, how, fingerprint);
      if (a.resume) ex::check_frames_left(writer->memory, src, so, file.string());
    } else {
      writer.emplace(ex::create_memory(file, a.force, std::move(*fresh), stack));
      writer->store.set_note("input", fingerprint);
    }
    ex::NewMemoryGuard guard(writer, !continued);
    const auto r = ex::stream_into(*writer, src, a.save_every, a.working_memory, std::nullopt, [](const Memory&) {});
    if (r.pushed == 0) vmap::detail::fail("'" + a.input + "' gave no frame in the requested range");
    guard.keep();
    writer->store.checkpoint();
    const auto* mem = &writer->memory;
    const double ms = r.pushed ? 1000.0 * r.seconds / static_cast<double>(r.pushed) : 0.0;
    if (a.json) {
      nlohmann::json loops = nlohmann::json::array();
      for (const auto& e : r.loops) loops.push_back(ex::loop_json(*mem, e));
      ex::print_json({{"memory", ex::path_string(file)}, {"stack", ex::stack_json(stack)},
                      {"session", mem->sessions().size() - 1}, {"pushed", r.pushed}, {"frames", mem->frames()},
                      {"key_images", mem->key_images()}, {"loops", mem->loops().size()}, {"new_loops", loops},
                      {"last_frame_index", mem->last_frame_index().value_or(0)}, {"bytes", fs::file_size(file)},
                      {"seconds", r.seconds}});
    } else {
      std::printf("session %zu: %s %zu frames (%zu in all): %zu key images, %zu loop edges (%zu new), %.1f ms per frame\n",
                  mem->sessions().size(), a.resume ? "resumed with" : "pushed", r.pushed, mem->frames(), mem->key_images(), mem->loops().size(),
                  r.loops.size(), ms);
      std::printf("wrote '%s' (%s; %ju bytes, %zu syncs in %.2f s); last frame %zu\n", file.c_str(),
                  ex::stack_text(stack).c_str(), static_cast<std::uintmax_t>(fs::file_size(file)), r.saves,
                  r.save_seconds, mem->last_frame_index().value_or(0));
    }
    return 0;
  });
}

/// One session of a memory as `memory info` shows it.
struct SessionInfo {
  std::size_t first_key = 0, key_images = 0, frames = 0;
  std::size_t loops_within = 0, loops_across = 0;  ///< edges from its key images: into it, into an earlier session
  std::optional<std::string> input;                ///< the input recorded by the command line (stores)
  std::optional<std::uintmax_t> bytes;             ///< its key images' rows (stores)
};

template <class Memory>
std::vector<SessionInfo> session_infos(const Memory& mem, const std::filesystem::path& file) {
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
  if (ex::memory_file_kind(file) != ex::MemoryFileKind::store) return out;
  auto store = vmap::MemoryStore::open(file, vmap::sqlite::Access::read);
  const auto bytes = store.key_image_bytes();
  for (std::size_t s = 0; s < out.size(); ++s) {
    if (auto note = store.note(ex::session_note(s))) {
      const auto j = nlohmann::json::parse(*note, nullptr, false);
      out[s].input = j.is_object() ? j.value("input", *note) : *note;
    }
    std::uintmax_t b = 0;
    for (std::size_t k = out[s].first_key; k < out[s].first_key + out[s].key_images && k < bytes.size(); ++k) b += bytes[k];
    out[s].bytes = b;
  }
  return out;
}

int info(const MemoryArgs& a) {
  const auto file = ex::memory_file(a.memory);
  ex::current_inputs() = {file.string()};
  return ex::with_memory(file, "memory", false, [&](const auto& mem, const ex::MemoryStack& stack) -> int {
    const auto sessions = session_infos(mem, file);
    nlohmann::json keys = nlohmann::json::array(), loops = nlohmann::json::array(), sess = nlohmann::json::array();
    for (std::size_t k = 0; k < mem.key_images(); ++k)
      keys.push_back({{"key", k},
                      {"session", mem.session_of(k)},
                      {"frame_index", mem.map().keys[k].frame_index},
                      {"name", mem.map().keys[k].name},
                      {"pose", ex::pose_json(mem.poses()[k])}});
    for (const auto& e : mem.loops()) loops.push_back(ex::loop_json(mem, e));
    for (const auto& s : sessions)
      sess.push_back({{"first_key", s.first_key},
                      {"key_images", s.key_images},
                      {"frames", s.frames},
                      {"loops_within", s.loops_within},
                      {"loops_across", s.loops_across},
                      {"input", s.input ? nlohmann::json(*s.input) : nlohmann::json(nullptr)},
                      {"bytes", s.bytes ? nlohmann::json(*s.bytes) : nlohmann::json(nullptr)}});
    const auto file_bytes = std::filesystem::file_size(file);
    if (a.json) {
      ex::print_json({{"stack", ex::stack_json(stack)},
                      {"frames", mem.frames()},
                      {"last_frame_index", mem.last_frame_index() ? nlohmann::json(*mem.last_frame_index()) : nlohmann::json(nullptr)},
                      {"bytes", file_bytes},
                      {"sessions", sess},
                      {"key_images", keys},
                      {"stationary", mem.stationary()},
                      {"loops", loops}});
      return 0;
    }
    std::printf("%zu frames, %zu key images, %zu loop edges, vocabulary of %zu words, last frame %zu (%s)\n",
                mem.frames(), mem.key_images(), mem.loops().size(), mem.vocabulary().size(),
                mem.last_frame_index().value_or(0), ex::stack_text(stack).c_str());
    if (sessions.size() > 1) {
      std::printf("%zu sessions (%ju bytes in all):\n", sessions.size(), static_cast<std::uintmax_t>(file_bytes));
      for (std::size_t s = 0; s < sessions.size(); ++s) {
        const auto& i = sessions[s];
        std::printf("  session %zu: %zu frames, %zu key images (from key %zu), %zu loop edges within, %zu to earlier "
                    "sessions",
                    s + 1, i.frames, i.key_images, i.first_key, i.loops_within, i.loops_across);
        if (i.bytes) std::printf(", %ju bytes of key images", *i.bytes);
        if (i.input) std::printf(", from %s", i.input->c_str());
        std::printf("\n");
      }
    }
    if (mem.stationary()) std::printf("the camera never left its place: no key image is a revisit\n");
    ex::print_loop_edges(mem, a.edges);
    return 0;
  });
}

/// `memory convert IN OUT`: a memory of either kind (a .vmem file of any version, or a
/// store) written into a new memory store.
int convert(const MemoryArgs& a) {
  namespace fs = std::filesystem;
  ex::current_inputs() = {a.convert_in};
  ex::check_input_file(a.convert_in, "INPUT");
  ex::check_memory_file(a.convert_in);
  const fs::path out = a.convert_out;
  ex::prepare_memory_output(out, "OUTPUT", {a.convert_in}, false, a.force);
  const auto t0 = std::chrono::steady_clock::now();
  return ex::with_memory(a.convert_in, "INPUT", true, [&](auto& mem, const ex::MemoryStack& stack) -> int {
    std::optional<ex::MemoryWriter<std::remove_cvref_t<decltype(mem)>>> writer;
    writer.emplace(ex::create_memory(out, a.force, std::move(mem), stack));
    ex::NewMemoryGuard guard(writer, true);
    writer->store.sync(writer->memory);
    writer->store.checkpoint();
    guard.keep();
    const double seconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
    const auto& m = writer->memory;
    if (a.json) {
      ex::print_json({{"input", ex::path_string(a.convert_in)}, {"memory", ex::path_string(out)}, {"frames", m.frames()},
                      {"key_images", m.key_images()}, {"loops", m.loops().size()}, {"bytes", fs::file_size(out)},
                      {"seconds", seconds}});
      return 0;
    }
    std::printf("%s: %zu frames, %zu key images, %zu loop edges (memory store, %ju bytes) from %s in %.2f s\n",
                out.c_str(), m.frames(), m.key_images(), m.loops().size(), static_cast<std::uintmax_t>(fs::file_size(out)),
                a.convert_in.c_str(), seconds);
    return 0;
  });
}

/// `memory merge A B --out C`: B's sessions appended to A's, loops searched from B's key
/// images into every key image before them (VisualMemory::merge: C equals the memory
/// built from A's runs and then B's as new sessions). C is written under a temporary
/// name and renamed when complete, so an existing C (with --force) is never half replaced.
int merge(const MemoryArgs& a) {
  namespace fs = std::filesystem;
  ex::current_inputs() = {a.merge_a, a.merge_b};
  for (const auto& [in, option] : {std::pair{a.merge_a, "A"}, std::pair{a.merge_b, "B"}}) {
    ex::check_input_file(in, option);
    ex::check_memory_file(in);
  }
  const fs::path out = ex::memory_file(a.out);
  ex::prepare_memory_output(out, "--out", {a.merge_a, a.merge_b}, false, a.force);
  const auto t0 = std::chrono::steady_clock::now();
  // Both memories must have been built with one policy stack (the camera compared by its
  // parameters, not by the name of its file).
  const ex::MemoryStack stack = ex::memory_stack(a.merge_a, "A"), stack_b = ex::memory_stack(a.merge_b, "B");
  const auto comparable = [](const ex::MemoryStack& s) {
    auto j = ex::stack_json(s);
    if (j["camera"].is_object()) j["camera"].erase("file");
    return j;
  };
  if (comparable(stack) != comparable(stack_b))
    vmap::detail::fail("cannot merge memory '" + a.merge_b + "' (" + ex::stack_text(stack_b) + ") into memory '" +
                       a.merge_a + "' (" + ex::stack_text(stack) + "): they were built with different policies");
  return ex::with_stack(stack, [&](auto descriptor, auto matcher, auto estimator) -> int {
    auto mem = ex::load_memory_with(a.merge_a, "A", true, descriptor, matcher, estimator);
    auto other = ex::load_memory_with(a.merge_b, "B", true, std::move(descriptor), std::move(matcher), std::move(estimator));
    const std::size_t sessions_a = mem.sessions().size(), sessions_b = other.sessions().size();
    const std::size_t keys_a = mem.key_images(), loops_a = mem.loops().size();
    mem.merge(std::move(other), "memory '" + a.merge_a + "'", "memory '" + a.merge_b + "'");
    // The inputs each session was built from (a store's notes), renumbered.
    std::vector<std::optional<std::string>> inputs;
    for (const auto& [in, n] : {std::pair{a.merge_a, sessions_a}, std::pair{a.merge_b, sessions_b}}) {
      std::optional<vmap::MemoryStore> store;
      if (ex::memory_file_kind(in) == ex::MemoryFileKind::store) store.emplace(vmap::MemoryStore::open(in, vmap::sqlite::Access::read));
      for (std::size_t s = 0; s < n; ++s) inputs.push_back(store ? store->note(ex::session_note(s)) : std::nullopt);
    }
    const fs::path tmp = out.string() + ".merging";
    std::optional<ex::MemoryWriter<decltype(mem)>> writer;
    writer.emplace(ex::create_memory(tmp, true, std::move(mem), stack));
    {
      ex::NewMemoryGuard guard(writer, true);
      writer->store.sync(writer->memory);
      for (std::size_t s = 0; s < inputs.size(); ++s)
        if (inputs[s]) writer->store.set_note(ex::session_note(s), *inputs[s]);
      writer->store.checkpoint();
      guard.keep();
    }
    const auto& m = writer->memory;
    const std::size_t frames = m.frames(), key_images = m.key_images(), loops = m.loops().size(), sessions = m.sessions().size();
    std::size_t across = 0;
    for (const auto& e : m.loops()) across += m.session_of(e.from) != m.session_of(e.link.key) ? 1 : 0;
    writer.reset();  // closes the store (its write-ahead log is empty after the checkpoint)
    std::error_code ec;
    for (const char* suffix : {"-wal", "-shm"}) {
      fs::remove(tmp.string() + suffix, ec);
      fs::remove(out.string() + suffix, ec);
    }
    fs::rename(tmp, out);
    vmap::detail::sync_folder(vmap::detail::folder_of(out));
    const double seconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
    if (a.json) {
      ex::print_json({{"a", ex::path_string(a.merge_a)}, {"b", ex::path_string(a.merge_b)}, {"memory", ex::path_string(out)},
                      {"sessions", sessions}, {"frames", frames}, {"key_images", key_images}, {"loops", loops},
                      {"new_loops", loops - loops_a}, {"loops_across_sessions", across}, {"bytes", fs::file_size(out)},
                      {"seconds", seconds}});
      return 0;
    }
    std::printf("%s: %zu sessions, %zu frames, %zu key images (%zu from A), %zu loop edges (%zu found for B's key "
                "images, %zu across sessions), %ju bytes, in %.2f s\n",
                out.c_str(), sessions, frames, key_images, keys_a, loops, loops - loops_a, across,
                static_cast<std::uintmax_t>(fs::file_size(out)), seconds);
    return 0;
  });
}

/// `memory export M --out DIR`: key images, trajectory and loop edges for other tools.
int export_files(const MemoryArgs& a) {
  const auto file = ex::memory_file(a.memory);
  ex::current_inputs() = {file.string()};
  ex::OutputFolder out(a.export_out, "--out", {file}, ex::export_file_names());
  return ex::with_memory(file, "memory", false, [&](const auto& mem, const ex::MemoryStack&) -> int {
    const auto written = ex::export_memory(mem, out.path());
    out.commit();
    if (a.json) {
      ex::print_json({{"memory", ex::path_string(file)}, {"out", a.export_out}, {"files", written},
                      {"key_images", mem.key_images()}, {"loops", mem.loops().size()}});
      return 0;
    }
    std::printf("%zu key images, %zu loop edges: wrote %s\n", mem.key_images(), mem.loops().size(),
                ex::written_files(a.export_out, written).c_str());
    return 0;
  });
}

std::function<int()> setup(CLI::App& app) {
  auto a = std::make_shared<MemoryArgs>();
  app.require_subcommand(1);
  auto* b = app.add_subcommand("build", "Stream a sequence into a memory file (or --resume one)");
  b->add_option("input", a->input, "Video, image folder, image list, TUM rgb.txt or a bag")->required();
  ex::add_bag_options(*b);
  b->add_option("--memory", a->out,
                "Memory store written at every key image, or DIR/memory.vmdb for a folder (read first with --resume)")
      ->required();
  b->add_flag("--resume", a->resume,
              "Continue the memory in --memory after the last frame it saw (its options are kept; the same input and "
              "--stride, checked)");
  b->add_option("--session", a->session,
                "'new' adds this run to the existing memory as a new session (its own chain of key images; loops are "
                "searched across sessions)")
      ->check(CLI::IsMember({"new"}));
  b->add_flag("--force", a->force, "Replace an existing memory instead of refusing to");
  b->add_option("--working-memory", a->working_memory,
                 "Key images whose features stay in RAM; older ones are read from the store when needed (0: all)")
      ->check(ex::count_in(0, ex::max_frame_index));
  b->add_option("--save-every", a->save_every, "Also write the memory every N frames (0: only at key images, loop edges and the end)")
      ->check(ex::count_in(0, ex::max_frame_index));
  b->add_option("--threshold,--tau", a->tau, "Similarity threshold tau: a new key image when S < tau (eq. 6)")
      ->check(ex::real_in(0.0, 1.0, true));
  b->add_option("--images", a->storage, "Key image pixels saved")->check(CLI::IsMember({"none", "png", "jpeg"}));
  b->add_option("--vocabulary", a->vocabulary, "Vocabulary file (vmap vocabulary); default: learned online");
  b->add_option("--start", a->start, "First frame index read")->check(ex::count_in(0, ex::max_frame_index));
  b->add_option("--end", a->end, "One past the last frame index read (0: all)")->check(ex::count_in(0, ex::max_frame_index));
  b->add_option("--stride", a->stride, "Read every n-th frame")->check(ex::count_in(1, ex::max_frame_index));
  b->add_flag("--json", a->json, "Print the result as JSON");
  ex::add_time_offset_option(*b, a->time_offset);
  b->add_option("--min-confidence", a->min_confidence, "A loop edge needs this place-decision confidence in [0, 1]")
      ->check(ex::real_in(0.0, 1.0));
  ex::add_feature_options(*b, a->features, a->model, a->nfeatures, a->refine_model);
  b->add_option("--estimator", a->estimator, "F-matrix estimation: magsac, ransac, lmeds or 8point");
  b->add_option("--camera", a->camera,
                "Calibration file (as vmap build --camera): kept in the memory; its F-matrices fit undistorted "
                "keypoints and a localized query gets its pose relative to the key image");
  auto* l = app.add_subcommand("localize", "The key image(s) each query image matches");
  l->add_option("memory", a->memory, "Memory file")->required();
  l->add_option("images", a->images, "Query images (or bags: each frame a query)")->required();
  ex::add_bag_options(*l);
  l->add_flag("--json", a->json, "Print every answer as JSON");
  l->add_option("--min-confidence", a->min_confidence,
                "Accept a key image at this place-decision confidence in [0, 1] (default: the memory's)")
      ->check(ex::real_in(0.0, 1.0));
  auto* i = app.add_subcommand("info", "Key images and loop edges of a memory file");
  i->add_option("memory", a->memory, "Memory file")->required();
  i->add_flag("--json", a->json, "Print as JSON");
  i->add_flag("--edges", a->edges, "List every loop edge (default: a summary and the 5 strongest)");
  auto* x = app.add_subcommand("export", "Key images (names, times, TUM trajectory) and loop edges (pairs, g2o) of a memory");
  x->add_option("memory", a->memory, "Memory file")->required();
  x->add_option("--out", a->export_out, "Folder for key_images.txt, key_images.tum, loops.txt, loops.g2o")->required();
  x->add_flag("--json", a->json, "Print the files written as JSON");
  auto* c = app.add_subcommand("convert", "Write a memory (a .vmem file of any version, or a store) into a new memory store");
  c->add_option("INPUT", a->convert_in, "Memory file (.vmem) or store")->required();
  c->add_option("OUTPUT", a->convert_out, "Memory store written (refused when it exists, unless --force)")->required();
  c->add_flag("--force", a->force, "Replace an existing memory OUTPUT");
  c->add_flag("--json", a->json, "Print the result as JSON");
  auto* g = app.add_subcommand("merge", "Join two memories made with the same options: B's sessions after A's, loops "
                                        "searched from B's key images into A's");
  g->add_option("A", a->merge_a, "Memory (store or .vmem) whose sessions come first")->required();
  g->add_option("B", a->merge_b, "Memory whose sessions are appended")->required();
  g->add_option("--out", a->out, "Memory store written (refused when it exists, unless --force)")->required();
  g->add_flag("--force", a->force, "Replace an existing memory --out");
  g->add_flag("--json", a->json, "Print the result as JSON");
  return [a, b, l, x, c, g]() {
    if (g->parsed()) return merge(*a);
    if (b->parsed()) return build(*a, *b);
    if (l->parsed())
      return ex::localize_from_memory(ex::memory_file(a->memory), "memory", a->images, a->json, a->min_confidence);
    if (x->parsed()) return export_files(*a);
    if (c->parsed()) return convert(*a);
    return info(*a);
  };
}

const bool registered =
    vmap::cli::add_command({"memory", "A visual memory: build, resume, localize, info, export, convert, merge", setup});

}  // namespace
