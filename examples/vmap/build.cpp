// `vmap build INPUT`: key images of a video (García-Pintos et al. 2023, Algorithm 1 /
// eq. 6), the map's quality (eq. 7), and with --out the map file, a contact sheet of the
// key images and the verified matches of the first and of the weakest key-image pair.
// With --memory DIR|FILE the frames go into a visual memory (include/vmap/memory: key
// images, place database, loop edges) kept in the memory store FILE or DIR/memory.vmdb,
// written at every key image; --resume continues that memory after its last frame.
#include "common/cli_support.hpp"
#include "common/draw.hpp"
#include "common/keyframe_cli.hpp"
#include "common/memory_cli.hpp"
#include "common/policies.hpp"
#include "vmap/cli.hpp"

#include <vmap/io/atomic_file.hpp>
#include <vmap/io/frame_source.hpp>
#include <vmap/keyframe/map_io.hpp>
#include <vmap/keyframe/pipeline.hpp>
#include <vmap/keyframe/selector.hpp>
#include <vmap/matching/brute_force.hpp>
#include <vmap/runtime/exports.hpp>
#include <vmap/runtime/memory.hpp>
#include <vmap/runtime/option_names.hpp>
#include <vmap/runtime/policies.hpp>
#include <vmap/runtime/recorder.hpp>
#include <vmap/runtime/selector.hpp>
#include <vmap/runtime/stack_choice.hpp>

#include <nlohmann/json.hpp>

#include <opencv2/imgcodecs.hpp>

#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <filesystem>
#include <functional>
#include <map>
#include <optional>
#include <string>
#include <vector>

namespace {

namespace ex = vmap::examples;

struct BuildArgs {
  ex::KeyframeArgs common;
  double threshold = 0.3;
  bool single_thread = false;
  std::string memory;  // --memory DIR|FILE; empty: no memory
  bool resume = false;
  std::string session;  // --session new: add this run to --memory as a new session
  std::string robot;    // --robot NAME: the robot whose memory it is in a fleet's memory (a URI)
  bool force = false;   // --force: replace an existing memory
  std::size_t save_every = 0;
  std::size_t working_memory = ex::default_working_memory;
  std::string images = "none";
  std::string vocabulary;
  std::string poses;  // --poses FILE: odometry kept with the memory's key images
  bool gcs = false;   // --gcs: floor poses, and the GCS localizer trained at the end
  std::size_t vocabulary_after = vmap::MemoryOptions{}.vocabulary_after;
  double min_confidence = vmap::PlaceDecisionOptions{}.min_confidence;  // --min-confidence: of loop edges
  std::optional<double> chance_rate;  // --chance-rate: unset, the rate measured for the stack
};

// The human table goes to stdout, or to stderr when --json owns stdout.
void print_table(std::FILE* out, const vmap::VisualMap& map) {
  const auto& keys = map.keys;
  std::fprintf(out, "  %4s  %6s  %-28s  %8s  %6s\n", "key", "frame", "name", "inliers", "S");
  const std::size_t m = keys.size();
  for (std::size_t k = 0; k < m; ++k) {
    if (m > 16 && k == 10) {
      std::fprintf(out, "  %4s\n", "...");
      k = m - 5;
    }
    const std::string name = keys[k].name.size() > 28 ? "..." + keys[k].name.substr(keys[k].name.size() - 25) : keys[k].name;
    if (k == 0)
      std::fprintf(out, "  %4zu  %6zu  %-28s  %8s  %6s\n", k, keys[k].frame_index, name.c_str(), "-", "-");
    else
      std::fprintf(out, "  %4zu  %6zu  %-28s  %8d  %6.3f\n", k, keys[k].frame_index, name.c_str(),
                  map.pairs[k - 1].inliers, map.pairs[k - 1].similarity);
  }
}

/// The key images in colour. Features come from frames decoded straight to grey
/// (libjpeg's grey decoding differs slightly from converting colour, and the key images
/// must not depend on --out), so image files are read again in colour here; video
/// frames were decoded in colour and converted exactly as the grey mode does.
void reread_key_images(vmap::VisualMap& map, const std::string& input);

void colour_key_images(vmap::VisualMap& map, const vmap::FrameSource& src) {
  if (src.kind() == vmap::SourceKind::video || src.kind() == vmap::SourceKind::live) return;
  if (src.kind() == vmap::SourceKind::bag) return reread_key_images(map, src.input().string());
  const auto paths = src.paths();
  for (auto& k : map.keys) {
    cv::Mat colour = cv::imread(paths.at(k.frame_index).string(), cv::IMREAD_COLOR);
    if (!colour.empty()) k.image = colour;
  }
}

/// The key images' pixels for the pictures of a memory run, whose frames were decoded in
/// grey and whose pixels are kept only with --images png|jpeg: image files are read
/// again in colour, a video is decoded again up to its last key image, and a live stream
/// (which cannot be read again) keeps the memory's own pixels.
/// The key images' frames read again in colour (a video, a bag), up to the last one.
void reread_key_images(vmap::VisualMap& map, const std::string& input) {
  if (map.keys.empty()) return;
  std::map<std::size_t, vmap::KeyImage*> wanted;
  for (auto& k : map.keys) wanted[k.frame_index] = &k;
  vmap::FrameSourceOptions o;
  o.end = map.keys.back().frame_index + 1;
  o.grey = false;
  auto again = ex::open_frames(input, o);
  while (auto f = again.next())
    if (const auto it = wanted.find(f->index); it != wanted.end()) it->second->image = f->image;
}

void key_pixels_for_pictures(vmap::VisualMap& map, const vmap::FrameSource& src, const std::string& input) {
  if (src.kind() == vmap::SourceKind::video) {
    reread_key_images(map, input);
  } else {
    colour_key_images(map, src);
  }
  for (std::size_t k = 0; k < map.keys.size(); ++k)
    if (map.keys[k].image.empty())
      vmap::detail::fail("--out: no pixels of key image " + std::to_string(k) + " (frame " +
                         std::to_string(map.keys[k].frame_index) + ", " + map.keys[k].name + ") for the pictures");
}

/// The lowest-S consecutive pair (the map's weakest link), index into map.pairs.
std::size_t weakest_pair(const vmap::VisualMap& map) {
  std::size_t w = 0;
  for (std::size_t k = 1; k < map.pairs.size(); ++k)
    if (map.pairs[k].similarity < map.pairs[w].similarity) w = k;
  return w;
}

/// Key images i and i+1 with their verified matches and a caption.
template <class Selector>
cv::Mat pair_picture(const vmap::VisualMap& map, std::size_t i, Selector& sel, const std::string& what) {
  // Matches and verification are deterministic, so these are the ones the map records.
  const auto& a = map.keys[i];
  const auto& b = map.keys[i + 1];
  const vmap::VerifiedPair p = vmap::verify_pair(sel, a.features, b.features);
  char caption[256];
  std::snprintf(caption, sizeof caption, "%s: K%zu-K%zu, frames %zu-%zu: %zu matches, %d inliers, S = %.3f",
                what.c_str(), i, i + 1, a.frame_index, b.frame_index, p.matches.size(),
                p.score.verification.inliers, map.pairs[i].similarity);
  return ex::captioned(
      ex::draw_verified_matches(a.image, a.features, b.image, b.features, p.matches, p.score.verification), caption);
}

template <class Selector>
std::vector<std::string> write_outputs(const ex::OutputFolder& dir, const vmap::VisualMap& map, Selector& sel) {
  std::vector<std::string> written;
  vmap::save_map(map, dir / "map.vmap");
  written.push_back("map.vmap");
  vmap::write_file_atomically(dir / "key_images.txt", vmap::key_images_text(map.keys));
  written.push_back("key_images.txt");
  std::vector<cv::Mat> images;
  std::vector<std::string> captions;
  for (std::size_t k = 0; k < map.keys.size(); ++k) {
    images.push_back(map.keys[k].image);
    captions.push_back("K" + std::to_string(k) + "  frame " + std::to_string(map.keys[k].frame_index));
  }
  vmap::write_image_atomically(dir / "contact_sheet.png", ex::contact_sheet(images, captions));
  written.push_back("contact_sheet.png");
  if (map.keys.size() >= 2) {
    std::vector<cv::Mat> panels{pair_picture(map, 0, sel, "first pair")};
    const std::size_t w = weakest_pair(map);
    if (w != 0) panels.push_back(pair_picture(map, w, sel, "weakest link (lowest S)"));
    vmap::write_image_atomically(dir / "matches.png", ex::stack_vertically(panels));
    written.push_back("matches.png");
  }
  return written;
}

/// What a --memory run adds to the report.
struct MemoryRun {
  std::filesystem::path file;
  bool resumed = false;
  std::size_t session = 0;  ///< the session this run pushed into
  vmap::RecordResult record;
  std::size_t loops = 0;  ///< loop edges in the whole memory
  std::optional<std::size_t> last_frame;
  std::optional<std::uintmax_t> bytes;  ///< the memory file's (none on a server)
  std::string robot;                    ///< a fleet's robot
  /// Writes the memory's exports (runtime/exports.hpp) into a folder.
  std::function<std::vector<std::string>(const std::filesystem::path&)> write_exports;
  vmap::PolicyStack stack;  ///< the memory's policies (a resumed memory's own)
};

/// The key images' outputs (--out), the JSON or the table, for a plain or a memory run.
/// `frames_read` is what this run read (a resumed memory holds more).
template <class Selector>
int report(const BuildArgs& args, const CLI::App& app, const vmap::VisualMap& map, Selector& sel,
           const vmap::FrameSource& src, std::size_t frames_read, double seconds,
           std::optional<ex::OutputFolder>& out_dir, const std::optional<ex::CameraOption>& camera,
           const std::optional<MemoryRun>& memory) {
  const auto& a = args.common;
  const std::size_t skipped = src.skipped().size();
  const auto st = map.stats();
  const double fps = seconds > 0 ? static_cast<double>(frames_read) / seconds : 0.0;
  std::vector<std::string> written;
  if (out_dir) {
    vmap::VisualMap coloured = map;
    if (memory)
      key_pixels_for_pictures(coloured, src, a.input);
    else
      colour_key_images(coloured, src);
    written = write_outputs(*out_dir, coloured, sel);
    if (memory && memory->write_exports)
      for (auto& f : memory->write_exports(out_dir->path())) written.push_back(std::move(f));
    out_dir->commit();
  }
  nlohmann::json memory_json = nullptr;
  if (memory) {
    nlohmann::json new_loops = nlohmann::json::array();
    for (const auto& e : memory->record.loops) new_loops.push_back({{"from", e.from}, {"to", e.link.key}});
    memory_json = {{"file", ex::path_string(memory->file)},
                   {"resumed", memory->resumed},
                   {"session", memory->session},
                   {"pushed", memory->record.pushed},
                   {"saves", memory->record.syncs},
                   {"loops", memory->loops},
                   {"new_loops", new_loops},
                   {"last_frame_index", memory->last_frame ? nlohmann::json(*memory->last_frame) : nlohmann::json(nullptr)},
                   {"bytes", memory->bytes ? nlohmann::json(*memory->bytes) : nlohmann::json(nullptr)},
                   {"robot", memory->robot.empty() ? nlohmann::json(nullptr) : nlohmann::json(memory->robot)},
                   {"stack", ex::stack_json(memory->stack)}};
  }
  if (a.json) {
    nlohmann::json j{{"command", "build"},
                     {"input", ex::path_string(a.input)},
                     {"options", ex::options_json(app)},
                     {"frames", st.frames},
                     {"skipped_frames", skipped},
                     {"key_images", st.key_images},
                     {"min_matches", st.min_matches},
                     {"max_matches", st.max_matches},
                     {"mean_matches", ex::finite_or_null(st.mean_matches)},
                     {"quality", ex::finite_or_null(st.quality)},
                     {"threshold", memory ? sel.options().tau : args.threshold},
                     {"seconds", seconds},
                     {"fps", fps},
                     {"key_frames", map.key_indices()},
                     {"out", a.out.empty() ? nlohmann::json(nullptr) : nlohmann::json(ex::path_string(a.out))},
                     {"files", written},
                     {"memory", memory_json}};
    ex::print_json(j);
    return 0;
  }
  std::FILE* out = stdout;
  const bool previous_rule = memory ? sel.options().rule == vmap::KeyRule::previous_frame : a.rule == "previous";
  std::fprintf(out, "vmap build: %s (%s + mutual NN + %s, threshold %.2f, %s rule)%s\n\n", a.input.c_str(),
               (memory ? std::string(vmap::to_string(memory->stack.descriptor)) : a.features).c_str(),
               (memory ? std::string(vmap::to_string(memory->stack.method)) : a.estimator).c_str(),
               memory ? sel.options().tau : args.threshold,
               previous_rule ? "eq. 6 previous-frame" : "Algorithm 1 current-frame",
               camera ? (", camera " + camera->file.string()).c_str() : "");
  print_table(out, map);
  std::fprintf(out, "\n  frames            %zu\n", st.frames);
  if (skipped > 0) std::fprintf(out, "  skipped frames    %zu (unreadable, listed above)\n", skipped);
  std::fprintf(out, "  key images        %zu (%.1f %% of the frames)\n", st.key_images,
               100.0 * static_cast<double>(st.key_images) / static_cast<double>(st.frames));
  if (st.key_images >= 2)
    std::fprintf(out, "  inliers K_i-K_i+1 min %d, max %d, mean %.1f\n", st.min_matches, st.max_matches,
                 st.mean_matches);
  if (std::isfinite(st.quality))
    std::fprintf(out, "  quality (eq. 7)   %.3f\n", st.quality);
  else
    std::fprintf(out, "  quality (eq. 7)   not a finite number\n");
  std::fprintf(out, "  time              %.2f s (%.1f frames/s)\n", seconds, fps);
  if (memory)
    std::fprintf(out, "  memory            %s%s: session %zu %s %zu frames, %zu loop edges (%zu new), last frame %zu%s\n",
                 ex::path_string(memory->file).c_str(), memory->robot.empty() ? "" : (", robot '" + memory->robot + "'").c_str(),
                 memory->session, memory->resumed ? "resumed with" : "pushed", memory->record.pushed, memory->loops,
                 memory->record.loops.size(), memory->last_frame.value_or(0),
                 memory->bytes ? (", " + std::to_string(*memory->bytes) + " bytes").c_str() : "");
  if (out_dir) {
    std::fprintf(out, "\n  wrote %s\n", ex::written_files(a.out, written).c_str());
  }
  return 0;
}

std::optional<std::size_t> expected_frames(const vmap::FrameSource& src, const vmap::FrameSourceOptions& so) {
  const auto total = src.total();
  if (!total) return std::nullopt;
  const std::size_t end = std::min(so.end, *total);
  return end > so.start ? (end - so.start + so.stride - 1) / so.stride : 0;
}

/// The options of a new memory from the command line.
vmap::MemoryOptions memory_options(const BuildArgs& args, const vmap::PolicyStack& stack) {
  vmap::MemoryOptions o;
  o.selector.tau = args.threshold;
  o.selector.rule = ex::parse_rule(args.common.rule);
  o.vocabulary_after = args.vocabulary_after;
  o.loops.decision.min_confidence = args.min_confidence;
  o.loops.decision.chance_inlier_rate = args.chance_rate.value_or(vmap::measured_chance_rate(stack));
  o.images = args.images == "png" ? vmap::ImageStorage::png : args.images == "jpeg" ? vmap::ImageStorage::jpeg
                                                                                    : vmap::ImageStorage::none;
  return o;
}

/// `vmap build INPUT --memory DIR|FILE [--resume] [--save-every N] [--images none|png|jpeg]`
/// (also `vmap memory build`): the frames streamed into a visual memory store
/// (runtime/recorder.hpp), synced at every key image.
int build_memory(const BuildArgs& args, const CLI::App& app) {
  namespace fs = std::filesystem;
  const auto& a = args.common;
  auto given = [&](const char* name) { return app.get_option(name)->count() > 0; };
  if (given("--vocabulary") && given("--vocabulary-after"))
    ex::usage_error("--vocabulary and --vocabulary-after conflict (the second is for a vocabulary learned online)");
  const fs::path file = vmap::memory_path(args.memory);
  const auto continuation = ex::continuation_of(args.resume, !args.session.empty(), args.force);
  const bool continued = continuation.has_value();
  const auto how = continuation.value_or(ex::Continuation::resume);
  std::vector<fs::path> inputs{a.input};
  if (!args.poses.empty()) {
    ex::check_input_file(args.poses, "--poses");
    inputs.emplace_back(args.poses);
  }
  // The policy stack: a new memory's from the command line (its camera read before any
  // folder is made), a continued one's as it recorded it (the stack's options then
  // conflict, check_continuable).
  vmap::PolicyStack stack;
  if (!continued) stack = ex::stack_of_args(a.features, a.nfeatures, a.model, a.refine_model, a.estimator, a.camera, a.input);
  const bool fleet = vmap::pg::is_uri(file.native());
  if (!fleet && !args.robot.empty()) ex::usage_error("--robot needs a fleet's memory: --memory postgresql://...");
  ex::prepare_memory_output(file, "--memory", inputs, continued, args.force, args.robot);
  if (continued)
    ex::check_continuable(file, app, {"--threshold", "--rule", "--images", "--vocabulary", "--vocabulary-after",
                                      "--min-confidence", "--chance-rate"}, how, args.robot);
  if (!args.vocabulary.empty()) ex::check_input_file(args.vocabulary, "--vocabulary");
  const vmap::SyncPolicy sync{args.save_every};
  std::optional<vmap::AnyMemory> mem;
  if (continued)
    mem.emplace(vmap::AnyMemory::open(file, {.robot = args.robot, .write = true,
                                             .new_session = how == ex::Continuation::new_session,
                                             .working_memory = args.working_memory, .sync = sync}));
  if (!fleet) inputs.push_back(file);
  std::optional<ex::OutputFolder> out_dir;
  if (!a.out.empty()) {
    // The --out folder is replaced as a whole when the run ends: a memory inside it would go.
    if (!fleet && ex::cli_detail::inside(ex::cli_detail::resolved(file), ex::cli_detail::resolved(a.out)))
      ex::usage_error("--memory: '" + file.string() + "' is inside the --out folder '" + a.out +
                      "', which is replaced as a whole (keep the memory elsewhere)");
    std::vector<std::string> files{"map.vmap", "key_images.txt", "contact_sheet.png", "matches.png"};
    files.insert(files.end(), vmap::memory_export_files().begin(), vmap::memory_export_files().end());
    out_dir.emplace(a.out, "--out", inputs, files);
  }
  auto so = ex::source_options(a, true);
  if (args.resume) so = ex::resume_range(*mem, so);
  auto src = ex::open_frames(a.input, so);
  const bool no_pixels = continued ? mem->options().images == vmap::ImageStorage::none : args.images == "none";
  if (out_dir && src.kind() == vmap::SourceKind::live && no_pixels)
    ex::usage_error("--out with --memory on a live source needs the memory's pixels (--images png or jpeg): a live "
                    "stream cannot be read again");
  std::optional<vmap::FramePoses> poses;
  if (args.gcs && args.poses.empty()) ex::usage_error("--gcs needs --poses FILE (the GCS learns a pose per neuron)");
  if (!args.poses.empty()) poses.emplace(args.poses, src, args.gcs);
  const vmap::RecordedInput input = vmap::recorded_input(a.input, src, so.stride);
  if (continued) {
    if (args.resume) {
      ex::check_same_input(*mem, input, src);
      ex::check_frames_left(*mem, src, so);
    } else {
      vmap::set_session_input(*mem, input);
    }
  } else {
    vmap::AnyVocabulary vocabulary;
    if (!args.vocabulary.empty()) vocabulary = vmap::AnyVocabulary::load(args.vocabulary);
    // --force: the memory there is replaced when the run closes it; until then readers
    // see it, and a failed run leaves it as it was.
    mem.emplace(vmap::AnyMemory::create(file, stack, memory_options(args, stack), std::move(vocabulary),
                                        {.robot = args.robot, .working_memory = args.working_memory, .sync = sync,
                                         .replace = args.force && !fleet}));
    vmap::set_session_input(*mem, input);
  }
  ex::NewMemoryGuard guard(mem, !continued, file.native());
  ex::Progress progress("vmap build", expected_frames(src, so));
  MemoryRun run{mem->path(), args.resume, mem->sessions().size() - 1, {}, 0, std::nullopt, std::nullopt, args.robot, {},
                mem->stack()};
  vmap::RecordOptions record;
  if (poses) record.poses = [&](const vmap::Frame& f) { return (*poses)(f); };
  record.on_frame = [&](const vmap::AnyMemory& m) {
    progress.update(src.delivered(), std::to_string(m.key_images()) + " key images");
  };
  run.record = vmap::record(*mem, src, record);
  progress.done(std::to_string(mem->key_images()) + " key images, " + std::to_string(src.skipped().size()) + " skipped");
  if (run.record.pushed == 0)
    vmap::detail::fail("'" + a.input + "' gave no frame in the requested range" +
                       (args.resume ? " after the memory's last frame " + std::to_string(mem->last_frame_index().value_or(0)) : ""));
  guard.keep();
  if (args.gcs) {
    // The GCS (Trujillo-Romero 2024, Algorithms 1 and 4) learns from every key image with
    // a floor pose, the resumed ones included, so it is trained again after each run.
    (void)mem->train_gcs();
    ++run.record.syncs;
  }
  mem->close();
  run.loops = mem->loops().size();
  run.last_frame = mem->last_frame_index();
  run.bytes = ex::memory_bytes(file);
  run.write_exports = [&](const fs::path& dir) { return vmap::export_memory(*mem, dir, false); };
  // map.vmap and the pictures need every key image's features: the released ones are
  // read back from the memory.
  std::optional<vmap::VisualMap> whole;
  if (out_dir) {
    whole.emplace(mem->map());
    for (std::size_t k = 0; k < whole->keys.size(); ++k)
      if (!mem->holds_features(k)) whole->keys[k].features = mem->key_features(static_cast<std::uint32_t>(k));
  }
  // The pictures match key image pairs again with the memory's own policies.
  vmap::AnySelector sel(mem->stack(), mem->options().selector, "the memory's camera");
  return report(args, app, whole ? *whole : mem->map(), sel, src, run.record.pushed, run.record.seconds, out_dir,
                run.stack.camera ? std::optional<ex::CameraOption>(ex::CameraOption{run.stack.camera_source, *run.stack.camera})
                                 : std::nullopt,
                run);
}

std::function<int()> setup(CLI::App& app) {
  auto args = std::make_shared<BuildArgs>();
  ex::add_keyframe_options(app, args->common);
  app.add_option("--threshold,--tau", args->threshold, "Similarity threshold tau: a new key image when S < tau")
      ->check(ex::real_in(0.0, 1.0, true));
  app.add_option("--out", args->common.out,
                 "Folder for map.vmap, key_images.txt, contact_sheet.png and matches.png (created if missing)");
  app.add_flag("--single-thread", args->single_thread, "Decode and extract on the matching thread");
  app.add_option("--memory", args->memory,
                 "Keep a visual memory (key images, place database, loop edges) in the memory store FILE, or "
                 "DIR/memory.vmdb when DIR is a folder or ends in '/', written at every key image; --out is then "
                 "optional");
  app.add_flag("--resume", args->resume,
               "Continue the --memory file after its last frame (the same INPUT and --stride, checked)");
  app.add_option("--session", args->session,
                 "With --memory: 'new' adds this run to the existing memory as a new session (its own chain of key "
                 "images; loops are searched across sessions)")
      ->check(CLI::IsMember({"new"}));
  app.add_flag("--force", args->force, "With --memory: replace an existing memory instead of refusing to");
  app.add_option("--robot", args->robot,
                 "With --memory postgresql://...: the robot whose memory this run writes in the fleet's memory (new, "
                 "or continued with --resume or --session new)");
  app.add_option("--save-every", args->save_every,
                 "With --memory: also write it every N frames (0: only at key images, loop edges and the end)")
      ->check(ex::count_in(0, ex::max_frame_index));
  app.add_option("--working-memory", args->working_memory,
                 "With --memory: key images whose features stay in RAM; older ones are read from the memory when a "
                 "loop candidate needs them (0: all)")
      ->check(ex::count_in(0, ex::max_frame_index));
  app.add_option("--images", args->images, "With --memory: key image pixels kept in it: none, png or jpeg")
      ->check(CLI::IsMember({"none", "png", "jpeg"}));
  app.add_option("--vocabulary", args->vocabulary,
                 "With --memory: its place vocabulary (vmap vocabulary); default: learned from the first key images");
  app.add_option("--vocabulary-after", args->vocabulary_after,
                 "With --memory and no --vocabulary: learn it from the first N key images (loops are searched from then on)")
      ->check(ex::count_in(1, 1000000));
  app.add_option("--min-confidence", args->min_confidence,
                 "With --memory: a loop edge needs this place-decision confidence in [0, 1] (0.5: inliers a chance "
                 "alignment gives 1 in 10^12)")
      ->check(ex::real_in(0.0, 1.0));
  app.add_option("--chance-rate", args->chance_rate,
                 "With --memory: the place decision's chance-inlier rate, kept with the memory (default: the rate "
                 "measured for the stack, vmap::measured_chance_rate; your own from vmap::calibrate_chance_rate)")
      ->check(ex::real_in(0.0001, 0.9));
  app.add_option("--poses", args->poses,
                 "With --memory: each frame's odometry pose (TUM or KITTI camera poses; by order when there is one "
                 "per frame, else the nearest in time within 50 ms), kept with its key image");
  app.add_flag("--gcs", args->gcs,
               "With --memory and --poses: keep floor poses (x, y, heading: TUM's z-up floor, KITTI's y-down) and "
               "train the GCS localizer on the key images at the end; localize --memory then answers a position too");
  return [args, &app]() -> int {
    const auto& a = args->common;
    ex::current_inputs() = {a.input};
    ex::check_range(a);
    if (!args->memory.empty()) return build_memory(*args, app);
    for (const char* o : {"--resume", "--session", "--robot", "--save-every", "--working-memory", "--images", "--vocabulary",
                          "--vocabulary-after", "--min-confidence", "--chance-rate", "--poses", "--gcs"})
      if (app.get_option(o)->count() > 0) ex::usage_error(std::string(o) + " needs --memory DIR|FILE");
    const auto camera = ex::camera_option(a.camera, a.input);
    const bool pictures = !a.out.empty();
    // Everything the command line can get wrong is refused before the first frame.
    std::optional<ex::OutputFolder> out_dir;
    if (pictures) out_dir.emplace(a.out, "--out", std::vector<std::filesystem::path>{a.input},
                                  std::vector<std::string>{"map.vmap", "key_images.txt", "contact_sheet.png", "matches.png"});
    const vmap::SelectorOptions so{.tau = args->threshold, .rule = ex::parse_rule(a.rule), .keep_images = pictures};
    const vmap::PolicyStack stack = a.stack(camera);
    const auto source = ex::source_options(a, true);
    auto src = ex::open_frames(a.input, source);
    if (pictures && src.kind() == vmap::SourceKind::video)
      src = ex::open_frames(a.input, ex::source_options(a, false));
    const auto expected = expected_frames(src, source);
    vmap::AnySelector sel(stack, so, vmap::camera_name(stack, vmap::OptionNames::command_line()));
    ex::Progress progress("vmap build", expected);
    sel.run(src, {.pipelined = !args->single_thread}, [&](const vmap::FrameResult&) {
      progress.update(sel.map().frames, std::to_string(sel.map().keys.size()) + " key images");
    });
    const double seconds = progress.seconds();
    progress.done(std::to_string(sel.map().keys.size()) + " key images, " + std::to_string(src.skipped().size()) +
                  " skipped");
    if (sel.map().frames == 0) vmap::detail::fail("'" + a.input + "' gave no frame in the requested range");
    return report(*args, app, sel.map(), sel, src, sel.map().frames, seconds, out_dir, camera, std::nullopt);
  };
}

[[maybe_unused]] const bool registered = vmap::cli::add_command({"build", "Select the key images of a video (visual map)", setup});

}  // namespace
