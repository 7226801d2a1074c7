#pragma once

// What the subcommands that read or write a visual memory share on the command line
// (`vmap build --memory`, `vmap localize --memory`, `vmap loops --memory`, `vmap memory
// ...`): the policy stack from the options, the checks of a memory given as an input or
// an output (usage errors, before any work), and the JSON and text of key images,
// localization answers and loop edges. The memory itself is the library's run-time layer
// (include/vmap/runtime: AnyMemory, record, export_memory).

#include "common/bag_options.hpp"
#include "common/cli_support.hpp"
#include "common/policies.hpp"

#include <vmap/core/error.hpp>
#include <vmap/io/atomic_file.hpp>
#include <vmap/io/exports.hpp>
#include <vmap/io/frame_source.hpp>
#include <vmap/io/image.hpp>
#include <vmap/io/postgres.hpp>
#include <vmap/memory/replace.hpp>
#include <vmap/memory/sequence.hpp>
#include <vmap/memory/store.hpp>
#include <vmap/runtime/fleet.hpp>
#include <vmap/runtime/memory.hpp>
#include <vmap/runtime/recorder.hpp>
#include <vmap/runtime/stack.hpp>

#include <nlohmann/json.hpp>
#include <opencv2/core/affine.hpp>
#include <opencv2/imgcodecs.hpp>

#include <algorithm>
#include <cctype>
#include <charconv>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <filesystem>
#include <functional>
#include <optional>
#include <string>
#include <variant>
#include <vector>

namespace vmap::examples {

/// --working-memory's default: key images whose features a memory the command line
/// writes keeps in RAM (examples/memory.md, "Bounded memory").
inline constexpr std::size_t default_working_memory = 200;

/// The stack of --features, --nfeatures, --model, --refine-model, --estimator and
/// --camera (or the CameraInfo of the bag `input`); a bad name or combination is a usage
/// error naming the option. The memory records its model paths absolute (AnyMemory).
inline PolicyStack stack_of_args(const std::string& features, int nfeatures, const std::string& model,
                                 const std::string& refine_model, const std::string& estimator,
                                 const std::string& camera_file, const std::string& input = {}) {
  return stack_of({features, nfeatures, model, refine_model}, estimator, camera_option(camera_file, input));
}

/// The stack as JSON: what the memory is built with.
inline nlohmann::json stack_json(const PolicyStack& s) {
  nlohmann::json j{{"features", std::string(to_string(s.descriptor))},
                   {"nfeatures", s.features},
                   {"model", s.model},
                   {"refine_model", s.refine_model},
                   {"estimator", std::string(to_string(s.method))},
                   {"camera", nullptr},
                   {"text", to_string(s)}};
  if (s.camera) {
    const Camera& c = *s.camera;
    j["camera"] = {{"file", s.camera_source},
                   {"lens", c.lens == LensModel::pinhole ? "pinhole" : "fisheye"},
                   {"fx", c.fx},
                   {"fy", c.fy},
                   {"cx", c.cx},
                   {"cy", c.cy},
                   {"distortion", c.distortion},
                   {"width", c.image_size.width},
                   {"height", c.image_size.height}};
  }
  return j;
}

/// Checks the memory file a command will write (not an input, not a link, folder, FIFO
/// or device, its folder created and writable) before any frame is read. An existing
/// file is kept: it is continued (`resume`), replaced only with `force` and only when it
/// is a memory (a mistyped path never overwrites another file), and refused otherwise.
/// The replacement itself is the library's (MemoryCreateOptions::replace), which checks
/// the same again under the memory's writer lock.
///
/// A fleet's memory (a postgresql:// URI) is written as robot `robot` (--robot): a robot
/// the fleet has is continued only with --resume or --session new, and never replaced;
/// one that holds nothing (a first run killed before its first key image) is started
/// again with --force.
inline void prepare_memory_output(const std::filesystem::path& file, const std::string& option,
                                  const std::vector<std::filesystem::path>& inputs, bool resume = false,
                                  bool force = false, const std::string& robot = {}) {
  if (pg::is_uri(file.native())) {
    if (robot.empty())
      usage_error(option + ": a fleet's memory (a PostgreSQL URI) holds one memory per robot: give --robot NAME");
    const auto robots = MemoryStore::robots(file.native());
    const bool exists = std::find(robots.begin(), robots.end(), robot) != robots.end();
    if (force) {
      if (!exists || MemoryStore::remove_unsynced_robot(file.native(), robot)) return;
      usage_error("--force: robot '" + robot + "' holds a memory, and a fleet's robot is not replaced (name another "
                  "robot with --robot, or continue it with --resume or --session new)");
    }
    if (exists && !resume)
      usage_error(option + ": robot '" + robot + "' of memory '" + pg::redacted(file.native()) + "' exists: " +
                  (option == "--memory" ? "give --resume to continue it or --session new to add a run to it"
                                        : "name another robot with --robot"));
    return;
  }
  const std::filesystem::path dir = file.has_parent_path() ? file.parent_path() : std::filesystem::path(".");
  std::error_code ec;
  // An --out folder is replaced as a whole by the next --out run: a memory kept there
  // would be deleted with it.
  if (std::filesystem::exists(dir / vmap::detail::output_marker, ec))
    usage_error(option + ": '" + dir.string() +
                "' is an --out folder of vmap, which the next --out run replaces as a whole; keep the memory in "
                "another folder");
  prepare_output_dir(dir, option, inputs, {file.filename().string()});
  if (std::filesystem::exists(file, ec) && !std::filesystem::is_regular_file(file, ec))
    usage_error(option + ": '" + file.string() + "' is not a regular file (a FIFO, a device or a socket); refusing to "
                "write a memory there");
  if (resume || !std::filesystem::exists(file, ec)) return;
  if (memory_kind(file) == MemoryKind::other)
    usage_error(option + ": '" + file.string() + "' exists and is not a vmap memory; refusing to replace it");
  if (!force)
    usage_error(option + ": the memory '" + file.string() + "' exists: " +
                (option == "--memory" ? "give --resume to continue it, --session new to add a run to it, or --force "
                                        "to replace it"
                                      : "give --force to replace it"));
}

/// A memory given as an input (`option` names it): a missing path, a folder or a device
/// is a usage error; a file that is no memory is an Error naming it (corrupt: exit 4).
inline void check_memory_input(const std::filesystem::path& file, const std::string& option) {
  if (pg::is_uri(file.native())) return;  // a fleet's memory: the server says (AnyMemory::open)
  check_input_file(file, option);
  if (memory_kind(file) == MemoryKind::other)
    vmap::detail::fail(vmap::ErrorKind::corrupt, "'" + file.string() + "' is not a vmap memory (neither a memory store nor a .vmem memory file)");
}

/// Opens a memory given as an input to read (a snapshot; `pixels` to decode its key
/// images' pixels, which only the commands that write them again need); `robot` is the
/// robot of a fleet's memory (--robot).
inline AnyMemory open_memory_input(const std::filesystem::path& file, const std::string& option, bool pixels = false,
                                   const std::string& robot = {}) {
  check_memory_input(file, option);
  if (pg::is_uri(file.native()) && robot.empty())
    usage_error(option + ": a fleet's memory (a PostgreSQL URI) holds one memory per robot: give --robot NAME");
  return AnyMemory::open(file, {.robot = robot, .pixels = pixels});
}

/// The bytes of a memory file; none for a fleet's memory (on a server).
inline std::optional<std::uintmax_t> memory_bytes(const std::filesystem::path& file) {
  if (pg::is_uri(file.native())) return std::nullopt;
  return std::filesystem::file_size(file);
}

/// `--robot NAME`: the robot of a fleet's memory (a PostgreSQL URI given as the memory).
inline void add_robot_option(CLI::App& app, std::string& robot) {
  app.add_option("--robot", robot,
                 "The robot whose memory it is, when the memory is a fleet's (a postgresql:// URI)");
}

/// How a run continues an existing memory: its last session after its last frame
/// (--resume), or a new session from the input's first frame (--session new).
enum class Continuation : std::uint8_t { resume, new_session };

/// How a run of `build --memory` treats its memory, from --resume, --session new and
/// --force (conflicting pairs are usage errors): nullopt for a new memory (replacing an
/// existing one with --force).
inline std::optional<Continuation> continuation_of(bool resume, bool new_session, bool force) {
  if (resume && force) usage_error("--resume and --force conflict (continue the memory, or replace it)");
  if (new_session && resume)
    usage_error("--session new and --resume conflict (a new session reads its input from the start; --resume "
                "continues the last session)");
  if (new_session && force) usage_error("--session new and --force conflict (add a session, or replace the memory)");
  if (resume) return Continuation::resume;
  if (new_session) return Continuation::new_session;
  return std::nullopt;
}

/// The options that make a memory's policy stack: a continued memory keeps its own.
inline const std::vector<std::string>& stack_options() {
  static const std::vector<std::string> names{"--features", "--model", "--refine-model", "--nfeatures",
                                              "--estimator", "--camera"};
  return names;
}

/// The checks before a run continues the memory `file`: options that would change the
/// memory's own (`options_kept` and stack_options(), given on the command line) conflict;
/// a missing file, a .vmem file and a store that holds nothing yet are usage errors that
/// say what to do.
inline void check_continuable(const std::filesystem::path& file, const CLI::App& app,
                              const std::vector<std::string>& options_kept, Continuation how,
                              const std::string& robot = {}) {
  const std::string flag = how == Continuation::resume ? "--resume" : "--session new";
  for (const auto& list : {options_kept, stack_options()})
    for (const auto& o : list)
      if (app.get_option(o)->count() > 0)
        usage_error(flag + " and " + o + " conflict (a continued memory keeps the options it was started with)");
  std::error_code ec;
  if (pg::is_uri(file.native())) {
    const auto robots = MemoryStore::robots(file.native());
    if (std::find(robots.begin(), robots.end(), robot) == robots.end())
      usage_error(flag + ": memory '" + pg::redacted(file.native()) + "' has no robot '" + robot +
                  "' to continue (run without " + flag + " to start it)");
    auto store = MemoryStore::open(file, sqlite::Access::read, robot);
    if (!store.synced())
      usage_error(flag + ": robot '" + robot + "' holds nothing yet (its first run stopped before its first key image "
                  "was written): start it again with --force");
    return;
  }
  if (!std::filesystem::exists(file, ec))
    usage_error(flag + ": no memory file '" + file.string() + "' to continue (run without " + flag + " to start one)");
  check_memory_input(file, "--memory");
  if (memory_kind(file) == MemoryKind::file)
    usage_error(flag + ": '" + file.string() + "' is a single-file memory (.vmem); convert it to a memory store "
                "first: vmap memory convert " + file.string() + " NEW.vmdb");
  auto store = MemoryStore::open(file, sqlite::Access::read);
  if (!store.synced())
    usage_error(flag + ": the memory '" + file.string() + "' holds nothing yet (its first run stopped before its "
                "first key image was written): start it again with --force");
}

/// --resume of a memory whose last session was built from another input (path, first
/// frame or stride), or from a list or folder whose frames changed since, is refused
/// with both named; a store without the record (written by
/// the library, or converted) takes this run's.
inline void check_same_input(AnyMemory& memory, const RecordedInput& input, const FrameSource& src) {
  if (const auto why = changed_input(memory, src))
    usage_error("--resume: the input '" + input.input + "' changed since the memory '" + memory.path().string() +
                "' read it: " + *why + ". Give --session new to add this run as a new session, or start another "
                "memory");
  const auto recorded = session_input(memory, memory.sessions().size() - 1);
  if (!recorded) {
    set_session_input(memory, input);
    return;
  }
  if (*recorded == input) return;
  usage_error("--resume: the memory '" + memory.path().string() + "' was built from " + recorded->text() +
              "; this run reads " + input.text() +
              ". Give the same input and --stride, --session new to add this run as a new session, or start another "
              "memory");
}

/// The frame range a resumed memory reads: the frames after the last one it holds, in
/// the sequence's index space (the same --stride as the first run gives the same frames
/// an uninterrupted run would have read). Nothing left to read is a usage error.
inline FrameSourceOptions resume_range(const AnyMemory& memory, FrameSourceOptions so) {
  if (const auto last = memory.last_frame_index()) so.start = std::max(so.start, *last + so.stride);
  if (so.start >= so.end)
    usage_error("--resume: the memory '" + memory.path().string() +
                "' already holds every frame up to --end (its last frame is " +
                std::to_string(memory.last_frame_index().value_or(0)) + ")");
  return so;
}

/// --resume of a memory that already holds the last frame of a folder or list (whose
/// length is exact; a video's stated frame count is not trusted): a usage error that
/// says so, as resume_range says it for --end, instead of a run that reads no frame.
inline void check_frames_left(const AnyMemory& memory, const FrameSource& src, const FrameSourceOptions& so) {
  const auto total = src.total();
  if (src.kind() != SourceKind::video && total && so.start >= *total)
    usage_error("--resume: the memory '" + memory.path().string() +
                "' already holds every frame of its input (its last frame is " +
                std::to_string(memory.last_frame_index().value_or(0)) + ")");
}

/// Removes the memory store a run created when the run ends (an error, no frame) before
/// keep() while it holds nothing: no empty memory is left behind. One that holds key
/// images a sync committed (a reader may have seen them; the run failed later, e.g. on a
/// full disk) is kept, and the guard says so: `--resume` continues it. A continued memory
/// is never removed, nor one that replaces another (AnyMemory::replaces(): destroyed
/// unclosed, it leaves the memory it was to replace as it was).
class NewMemoryGuard {
 public:
  /// `location` is the memory as given: for a fleet's memory, the URI of its server.
  NewMemoryGuard(std::optional<AnyMemory>& memory, bool created, std::string location = {})
      : memory_(&memory), armed_(created), location_(std::move(location)) {}
  NewMemoryGuard(const NewMemoryGuard&) = delete;
  NewMemoryGuard& operator=(const NewMemoryGuard&) = delete;
  void keep() noexcept { armed_ = false; }
  ~NewMemoryGuard() {
    if (!armed_ || !*memory_ || (*memory_)->replaces()) return;
    const std::filesystem::path file = (*memory_)->path();
    const std::string robot = (*memory_)->robot();
    memory_->reset();  // waits for the sync in flight
    if (!robot.empty()) {
      // A fleet's robot that holds nothing is removed, so that the name can start again.
      try {
        if (!MemoryStore::remove_unsynced_robot(location_, robot))
          std::fprintf(stderr, "robot '%s' of memory '%s' keeps what was committed before the error (--resume continues "
                       "it)\n", robot.c_str(), file.c_str());
      } catch (const std::exception& e) {
        std::fprintf(stderr, "robot '%s' is kept as the error left it (%s)\n", robot.c_str(), e.what());
      }
      return;
    }
    // Removed only when it is known to hold nothing: a store that cannot be read back
    // now (the error may still be there) is kept as it is.
    try {
      auto store = MemoryStore::open(file, sqlite::Access::read);
      if (store.synced()) {
        std::fprintf(stderr, "the memory '%s' keeps the %zu key images committed before the error (--resume "
                     "continues it)\n", file.c_str(), store.key_images());
        return;
      }
    } catch (const std::exception& e) {
      std::fprintf(stderr, "the memory '%s' is kept as the error left it (reading it back: %s)\n", file.c_str(), e.what());
      return;
    }
    std::error_code ec;
    for (const char* suffix : {"", "-wal", "-shm"}) std::filesystem::remove(file.string() + suffix, ec);
  }

 private:
  std::optional<AnyMemory>* memory_;
  bool armed_;
  std::string location_;
};

// ---------------------------------------------------------------------------------------
// JSON and text.

/// An odometry pose: {x, y, theta} (SE(2)), {se3: the 12 numbers of [R | t] by rows}, or null.
inline nlohmann::json pose_json(const OdometryPose& p) {
  if (const auto* p2 = std::get_if<Pose2>(&p)) return {{"x", p2->x()}, {"y", p2->y()}, {"theta", p2->theta()}};
  if (const auto* p3 = std::get_if<cv::Affine3d>(&p)) {
    nlohmann::json m = nlohmann::json::array();
    for (int i = 0; i < 12; ++i) m.push_back(p3->matrix.val[i]);
    return {{"se3", m}};
  }
  return nullptr;
}

/// ", pose (x, y, theta)" / ", position (x, y, z)" or "" when the key image has none.
inline std::string pose_text(const OdometryPose& p) {
  char buf[160];
  if (const auto* p2 = std::get_if<Pose2>(&p)) {
    std::snprintf(buf, sizeof buf, ", pose (%.3f, %.3f, %.3f rad)", p2->x(), p2->y(), p2->theta());
    return buf;
  }
  if (const auto* p3 = std::get_if<cv::Affine3d>(&p)) {
    const cv::Vec3d t = p3->translation();
    std::snprintf(buf, sizeof buf, ", position (%.3f, %.3f, %.3f)", t[0], t[1], t[2]);
    return buf;
  }
  return {};
}

/// A key image: its index, session, frame, name, times (seconds and nanoseconds) and pose.
inline nlohmann::json key_json(const AnyMemory& mem, std::size_t k) {
  const KeyImage& key = mem.map().keys[k];
  return {{"key", k},
          {"session", mem.session_of(k)},
          {"frame_index", key.frame_index},
          {"name", key.name},
          {"time", key.timestamp},
          {"time_ns", key.time_ns},
          {"pose", pose_json(mem.poses()[k])}};
}

/// A verified key image of a localization answer.
inline nlohmann::json link_json(const AnyMemory& mem, const PlaceLink& l) {
  const auto& k = mem.map().keys[l.key];
  nlohmann::json f = nlohmann::json::array();
  for (double e : l.model.val) f.push_back(e);
  return {{"key", l.key},
          {"frame_index", k.frame_index},
          {"name", k.name},
          {"inliers", l.inliers},
          {"matches", l.matches},
          {"bow_score", l.bow_score},
          {"similarity", l.similarity},
          {"confidence", l.confidence},
          {"model", f},
          {"model_kind", std::string(to_string(l.model_kind))},
          {"pose", pose_json(mem.poses()[l.key])}};
}

/// A loop edge: key images (from, to) and their frames (query, match), as `vmap loops`
/// names the frames of a loop.
inline nlohmann::json loop_json(const AnyMemory& mem, const LoopEdge& e) {
  const auto& keys = mem.map().keys;
  return {{"from", e.from},
          {"to", e.link.key},
          {"from_session", mem.session_of(e.from)},
          {"to_session", mem.session_of(e.link.key)},
          {"query", keys[e.from].frame_index},
          {"match", keys[e.link.key].frame_index},
          {"query_name", keys[e.from].name},
          {"match_name", keys[e.link.key].name},
          {"query_time", keys[e.from].timestamp},
          {"match_time", keys[e.link.key].timestamp},
          {"inliers", e.link.inliers},
          {"matches", e.link.matches},
          {"bow_score", e.link.bow_score},
          {"similarity", e.link.similarity},
          {"confidence", e.link.confidence}};
}

/// One query image's answer.
/// --sequence and --max-speed of `localize --memory` and `memory localize`.
struct SequenceArgs {
  std::size_t window = 1;  ///< 1: each image alone
  std::optional<double> max_speed;  ///< default: SequenceLine's
};

/// Adds --sequence and --max-speed to a subcommand that localizes in a memory.
inline void add_sequence_options(CLI::App& app, SequenceArgs& a) {
  app.add_option("--sequence", a.window,
                 "Answer each query with the evidence of the N queries around it, in the order given (a robot's "
                 "consecutive frames; 1: each image alone)")
      ->check(count_in(1, static_cast<long long>(max_sequence_window)));
  app.add_option("--max-speed", a.max_speed,
                 "With --sequence: the fastest the queries move along the memory's key images, in key images per query "
                 "(default 5)")
      ->check(real_in(0.0, 1000.0));
}

struct MemoryQuery {
  std::string image;
  MemoryLocalization answer;
  double ms = 0.0;
  std::size_t robot = 0;  ///< a fleet's: the robot whose memory answered (FleetMemory::robots)
  /// The query's time: a frame's (Frame::timestamp, time_ns), an image named by its time
  /// in seconds (TUM's 1305031230.697932.png) that time, any other image its position
  /// among the queries.
  double time = 0.0;
  std::int64_t time_ns = 0;
};

/// The time of a query image given alone: its name's, when the name (without extension)
/// is a decimal number of seconds, else `index`.
inline std::pair<double, std::int64_t> query_image_time(const std::string& path, std::size_t index) {
  const std::string stem = std::filesystem::path(path).stem().string();
  double v = 0.0;
  const auto [ptr, ec] = std::from_chars(stem.data(), stem.data() + stem.size(), v, std::chars_format::fixed);
  if (!stem.empty() && ec == std::errc() && ptr == stem.data() + stem.size() && std::isfinite(v) && v >= 0)
    return {v, nanoseconds_from_decimal(stem).value_or(nanoseconds_from_seconds(v))};
  return {static_cast<double>(index), nanoseconds_from_seconds(static_cast<double>(index))};
}

/// The query images of `inputs`: each an image file, or a sequence (a folder, a list, a
/// video, a bag: named "BAG:topic@stamp") whose frames are queries in order. Read in
/// grey, as the memory's frames were;
/// an unreadable image given alone is an Error naming it, a sequence's unreadable frames
/// are skipped and reported.
/// `localize` answers one image (a memory's, or a fleet's with the robot that answered).
inline std::vector<MemoryQuery> localize_queries(const std::function<MemoryQuery(const cv::Mat&)>& localize,
                                                 const std::vector<std::string>& inputs) {
  std::vector<MemoryQuery> out;
  const auto answer = [&](const std::string& name, const cv::Mat& img, std::pair<double, std::int64_t> time) {
    const auto t0 = std::chrono::steady_clock::now();
    MemoryQuery q = localize(img);
    q.image = name;
    q.ms = std::chrono::duration<double, std::milli>(std::chrono::steady_clock::now() - t0).count();
    q.time = time.first;
    q.time_ns = time.second;
    out.push_back(std::move(q));
  };
  for (const auto& input : inputs) {
    current_inputs() = {input};
    // A folder, or a regular file that is not an image (a list, a video), is a sequence;
    // anything else is one image, read with every check (a FIFO or a device is refused
    // unread).
    std::error_code ec;
    const bool sequence = std::filesystem::is_directory(input, ec) ||
                          (std::filesystem::is_regular_file(input, ec) && !vmap::detail::is_image_file(input));
    if (!sequence) {
      // Bounded like frame sources: a regular file, its pixels checked before decoding.
      cv::Mat img;
      try {
        img = vmap::read_image(input, {.flags = cv::IMREAD_GRAYSCALE});
      } catch (const vmap::Error& e) {
        vmap::detail::fail(e.kind(), "query " + std::string(e.what()));  // "query image 'x': reason"
      }
      answer(input, img, query_image_time(input, out.size()));
      continue;
    }
    FrameSourceOptions so;
    so.grey = true;
    so.on_skip = [](const SkippedFrame& s) {
      std::fprintf(stderr, "vmap: skipping query %zu (%s): %s\n", s.index, s.name.c_str(), s.reason.c_str());
    };
    auto src = open_frames(input, so);
    const std::string prefix = is_bag(input) ? input + ":" : std::string();
    while (auto f = src.next()) answer(prefix + f->name, f->image, {f->timestamp, f->time_ns});
  }
  return out;
}

/// The evidence of a place decision (lcd/place_decision.hpp).
inline nlohmann::json evidence_json(const PlaceEvidence& e) {
  return {{"matches", e.matches},         {"inliers", e.inliers},       {"inlier_ratio", e.inlier_ratio},
          {"significance", e.significance}, {"spread", e.spread},       {"bow_score", e.bow_score},
          {"model", std::string(to_string(e.model))}};
}

/// A relative pose (core/verification.hpp): R by rows, the unit t, the inliers in front
/// of both cameras; null when the memory has no camera or the decomposition failed.
inline nlohmann::json relative_pose_json(const std::optional<RelativePose>& p) {
  if (!p) return nullptr;
  nlohmann::json r = nlohmann::json::array();
  for (int i = 0; i < 9; ++i) r.push_back(p->rotation.val[i]);
  return {{"rotation", r},
          {"rotation_degrees", p->rotation_degrees()},
          {"translation", {p->translation[0], p->translation[1], p->translation[2]}},
          {"points_in_front", p->points_in_front}};
}

/// A query's metric pose (geometry/metric_pose.hpp): camera-to-world in the memory's
/// frame, the quaternion in TUM's order (qx, qy, qz, qw); null without one.
inline nlohmann::json metric_pose_json(const std::optional<MetricPose>& p) {
  if (!p) return nullptr;
  const cv::Vec3d t = p->position();
  const auto q = quaternion_from_rotation(p->rotation());
  const cv::Vec3d sigma = p->position_sigma();
  nlohmann::json cov = nlohmann::json::array();
  for (int i = 0; i < 6; ++i) {
    nlohmann::json row = nlohmann::json::array();
    for (int j = 0; j < 6; ++j) row.push_back(p->covariance(i, j));
    cov.push_back(std::move(row));
  }
  return {{"position", {t[0], t[1], t[2]}},
          {"quaternion", {q[0], q[1], q[2], q[3]}},
          {"key", p->key},
          {"points", p->points},
          {"inliers", p->inliers},
          {"reprojection_px", p->reprojection_px},
          {"position_sigma", {sigma[0], sigma[1], sigma[2]}},
          {"rotation_sigma_deg", p->rotation_sigma_deg()},
          {"covariance", cov},
          {"rotation_disagreement_deg", p->rotation_disagreement_deg ? nlohmann::json(*p->rotation_disagreement_deg)
                                                                      : nlohmann::json(nullptr)}};
}

/// Every answer: per query its decision (status, reason, confidence, evidence), time and
/// every verified key image (the decision's first, then by confidence).
inline nlohmann::json localizations_json(const AnyMemory& mem, const std::vector<MemoryQuery>& queries) {
  nlohmann::json out = nlohmann::json::array();
  for (const auto& q : queries) {
    nlohmann::json j{{"image", path_string(q.image)},
                     {"status", std::string(to_string(q.answer.status))},
                     {"reason", q.answer.reason},
                     {"reason_code", std::string(to_string(q.answer.reason_code))},
                     {"confidence", q.answer.confidence},
                     {"localized", q.answer.ok()},
                     {"evidence", evidence_json(q.answer.evidence)},
                     {"verified_candidates", q.answer.verified_candidates},
                     {"ms", q.ms},
                     {"time", q.time},
                     {"time_ns", q.time_ns},
                     {"matches", nlohmann::json::array()}};
    j["key"] = q.answer.best() ? nlohmann::json(q.answer.best()->key) : nlohmann::json(nullptr);
    // The GCS position (Algorithm 5), present when the memory holds a trained GCS; null otherwise.
    j["position"] = q.answer.position ? pose_json(q.answer.position->pose) : nlohmann::json(nullptr);
    // The query's camera relative to the best key image's (X_key = R X_query + t, |t| = 1),
    // present when the memory has a camera (--camera) and the F-matrix was verified.
    j["relative_pose"] = relative_pose_json(q.answer.relative_pose);
    // The query's camera-to-world pose in the memory's frame (a memory with SE(3) poses
    // and a camera), or null and why not.
    j["pose"] = metric_pose_json(q.answer.pose);
    j["pose_reason"] = q.answer.pose_reason;
    j["pose_reason_code"] = std::string(to_string(q.answer.pose_reason_code));
    // What the neighbours in the sequence added (--sequence N > 1); null for images alone.
    j["sequence"] = nullptr;
    if (const auto& s = q.answer.sequence)
      j["sequence"] = {{"window", s->window},
                       {"weighed", s->weighed},
                       {"on_line", s->on_line},
                       {"significance", s->significance},
                       {"single_confidence", s->single_confidence},
                       {"single_key", s->single_key ? nlohmann::json(*s->single_key) : nlohmann::json(nullptr)}};
    for (const auto& l : q.answer.matches) j["matches"].push_back(link_json(mem, l));
    out.push_back(std::move(j));
  }
  return out;
}

/// One line per query: the accepted key image (index, frame, name), confidence, inliers,
/// BoW score, pose; or the decision and its reason ("unknown place (confidence 0.12 <
/// 0.50)").
inline void print_localizations(const AnyMemory& mem, const std::vector<MemoryQuery>& queries) {
  for (const auto& q : queries) {
    if (const auto* b = q.answer.best()) {
      const auto& k = mem.map().keys[b->key];
      std::printf("%s: key %u (frame %zu, %s), confidence %.2f, %d inliers of %d matches, BoW %.3f%s, %.1f ms\n",
                  q.image.c_str(), b->key, k.frame_index, k.name.c_str(), q.answer.confidence, b->inliers, b->matches,
                  b->bow_score, pose_text(mem.poses()[b->key]).c_str(), q.ms);
    } else {
      std::printf("%s: %s (%s), %.1f ms\n", q.image.c_str(), std::string(to_string(q.answer.status)).c_str(),
                  q.answer.reason.c_str(), q.ms);
    }
    if (const auto& s = q.answer.sequence)
      std::printf("  sequence: %zu of %zu images that see a place on the line (window %zu); alone: confidence %.2f\n",
                  s->on_line, s->weighed, s->window, s->single_confidence);
    if (q.answer.best() && q.answer.relative_pose) {
      const RelativePose& p = *q.answer.relative_pose;
      std::printf("  relative to the key image: rotation %.2f deg, translation direction (%.3f, %.3f, %.3f)\n",
                  p.rotation_degrees(), p.translation[0], p.translation[1], p.translation[2]);
    }
    if (const auto& p = q.answer.pose) {
      const cv::Vec3d t = p->position();
      const auto r = quaternion_from_rotation(p->rotation());
      std::printf("  pose: position (%.3f, %.3f, %.3f), quaternion (%.4f, %.4f, %.4f, %.4f), %d of %d points, %.2f px, "
                  "sigma %.2g in position, %.2f deg in rotation\n",
                  t[0], t[1], t[2], r[0], r[1], r[2], r[3], p->inliers, p->points, p->reprojection_px,
                  p->position_sigma_max(), p->rotation_sigma_deg());
    } else if (q.answer.best() && std::holds_alternative<cv::Affine3d>(mem.poses()[q.answer.best()->key]) &&
               q.answer.pose_reason_code != PoseReason::no_camera) {
      std::printf("  no pose: %s (%s)\n", std::string(to_string(q.answer.pose_reason_code)).c_str(),
                  q.answer.pose_reason.c_str());
    }
    if (q.answer.position) {
      const Pose2& p = q.answer.position->pose;
      std::printf("  GCS position (%.3f, %.3f, %.3f rad)\n", p.x(), p.y(), p.theta());
    }
  }
}

/// `localize --memory URI QUERY...` without --robot: each query among every robot's key
/// images of a fleet's memory (FleetMemory), answered by the robot whose memory is the
/// most confident; the answers as localize_from_memory gives them, with the robot.
inline int localize_in_fleet(const std::string& uri, const std::vector<std::string>& queries, bool json,
                             std::optional<double> min_confidence, const SequenceArgs& sequence,
                             const std::string& trajectory) {
  if (sequence.window > 1 || sequence.max_speed)
    usage_error("--sequence: a sequence is placed along one robot's key images: give --robot NAME");
  if (!trajectory.empty())
    usage_error("--trajectory: each robot's poses are in its own frame, so a trajectory is one robot's: give --robot NAME");
  auto fleet = FleetMemory::open(uri);
  auto answers = localize_queries(
      [&](const cv::Mat& img) {
        FleetLocalization where = fleet.localize(img, min_confidence);
        return MemoryQuery{{}, std::move(where.answer), 0.0, where.index};
      },
      queries);
  const std::string shown = pg::redacted(uri);
  if (!json) {
    for (const auto& q : answers) {
      std::printf("robot '%s': ", fleet.robots()[q.robot].c_str());
      print_localizations(fleet.memory(q.robot), {q});
    }
    return 0;
  }
  nlohmann::json out = nlohmann::json::array();
  std::size_t localized = 0;
  for (const auto& q : answers) {
    nlohmann::json j = localizations_json(fleet.memory(q.robot), {q})[0];
    j["robot"] = fleet.robots()[q.robot];
    out.push_back(std::move(j));
    localized += q.answer.ok() ? 1 : 0;
  }
  print_json({{"command", "localize"}, {"memory", shown}, {"robots", fleet.robots()}, {"queries", out},
              {"localized", localized}});
  return 0;
}

/// The answered metric poses of `answers` as a TUM trajectory (the queries' times), written
/// atomically to `file`; how many.
inline std::size_t write_trajectory(const std::filesystem::path& file, const std::vector<MemoryQuery>& answers) {
  std::vector<CameraPose> poses;
  std::vector<std::int64_t> times;
  for (const auto& q : answers)
    if (const auto& p = q.answer.pose) {
      poses.push_back({q.time, p->position(), p->rotation()});
      times.push_back(q.time_ns);
    }
  write_file_atomically(file, tum_trajectory_text(poses, &times));
  return poses.size();
}

/// `vmap localize --memory M QUERY...` and `vmap memory localize M QUERY...`: the answers
/// as lines, or with `json` one object whose `queries` list every answer. A QUERY is an
/// image, or a folder, list or video of query images. `trajectory`: a file for the
/// answered metric poses (TUM format), or empty.
inline int localize_from_memory(const std::filesystem::path& file, const std::string& option,
                                const std::vector<std::string>& queries, bool json,
                                std::optional<double> min_confidence = std::nullopt, const SequenceArgs& sequence = {},
                                const std::string& robot = {}, const std::string& trajectory = {}) {
  current_inputs() = {file.string()};
  if (!trajectory.empty()) {
    std::vector<std::filesystem::path> inputs{file};
    for (const auto& q : queries) inputs.emplace_back(q);
    check_output_file(trajectory, "--trajectory", inputs);
  }
  if (pg::is_uri(file.native()) && robot.empty())
    return localize_in_fleet(file.native(), queries, json, min_confidence, sequence, trajectory);
  auto mem = open_memory_input(file, option, false, robot);
  // Said once: a memory with SE(3) poses but no camera answers no metric pose.
  if (!mem.stack().camera && std::any_of(mem.poses().begin(), mem.poses().end(), [](const OdometryPose& p) {
        return std::holds_alternative<cv::Affine3d>(p);
      }))
    std::fprintf(stderr, "vmap: the memory '%s' has poses but no camera: a query's metric pose needs the camera's "
                 "calibration; build the memory with --camera FILE as well as --poses FILE\n",
                 path_string(file).c_str());
  PlaceDecisionOptions decision = mem.options().loops.decision;
  if (min_confidence) decision.min_confidence = *min_confidence;
  auto answers = localize_queries([&](const cv::Mat& img) { return MemoryQuery{{}, mem.localize(img, &decision)}; },
                                  queries);
  if (sequence.max_speed && sequence.window == 1) usage_error("--max-speed needs --sequence N with N > 1");
  if (sequence.window > 1) {
    std::vector<MemoryLocalization> singles;
    for (const auto& q : answers) singles.push_back(q.answer);
    singles = with_sequence_evidence(std::move(singles), mem.sessions(),
                                     {.window = sequence.window, .line = {.max_speed = sequence.max_speed.value_or(SequenceLine{}.max_speed)}},
                                     decision);
    for (std::size_t i = 0; i < answers.size(); ++i) answers[i].answer = std::move(singles[i]);
  }
  std::optional<std::size_t> written;
  if (!trajectory.empty()) written = write_trajectory(trajectory, answers);
  if (!json) {
    print_localizations(mem, answers);
    if (written) std::printf("trajectory: %zu poses written to %s\n", *written, trajectory.c_str());
    return 0;
  }
  std::size_t localized = 0, posed = 0;
  for (const auto& q : answers) {
    localized += q.answer.ok() ? 1 : 0;
    posed += q.answer.pose ? 1 : 0;
  }
  print_json({{"command", "localize"},
              {"memory", path_string(file)},
              {"stack", stack_json(mem.stack())},
              {"frames", mem.frames()},
              {"key_images", mem.key_images()},
              {"min_confidence", decision.min_confidence},
              {"chance_inlier_rate", decision.chance_inlier_rate},
              {"sequence", sequence.window},
              {"queries", localizations_json(mem, answers)},
              {"localized", localized},
              {"posed", posed},
              {"trajectory", written ? nlohmann::json{{"file", path_string(trajectory)}, {"poses", *written}}
                                     : nlohmann::json(nullptr)}});
  return 0;
}

/// The loop edges: with `all`, one line per edge in the style of `vmap loops` (frame
/// names and times); otherwise a summary (how many, key images involved, confidence) and
/// the five most confident edges, so a long memory does not flood the terminal.
inline void print_loop_edges(const AnyMemory& mem, bool all = false) {
  const auto& keys = mem.map().keys;
  const bool sessions = mem.sessions().size() > 1;
  const auto session = [&](std::uint32_t k) {
    return sessions ? "session " + std::to_string(mem.session_of(k)) + ", " : std::string();
  };
  const auto line = [&](const LoopEdge& e) {
    std::printf("  key %4u (%sframe %4zu, %s, %s s) -> key %4u (%sframe %4zu, %s, %s s)  confidence %.2f  inliers %4d  "
                "bow score %.3f\n",
                e.from, session(e.from).c_str(), keys[e.from].frame_index, keys[e.from].name.c_str(),
                vmap::seconds_text(keys[e.from].time_ns).c_str(), e.link.key, session(e.link.key).c_str(),
                keys[e.link.key].frame_index, keys[e.link.key].name.c_str(),
                vmap::seconds_text(keys[e.link.key].time_ns).c_str(), e.link.confidence, e.link.inliers,
                e.link.bow_score);
  };
  std::vector<LoopEdge> edges = mem.loops();
  if (all || edges.size() <= 5) {
    for (const auto& e : edges) line(e);
    return;
  }
  std::vector<std::uint32_t> queries;
  for (const auto& e : edges) queries.push_back(e.from);
  std::sort(queries.begin(), queries.end());
  queries.erase(std::unique(queries.begin(), queries.end()), queries.end());
  std::sort(edges.begin(), edges.end(),
            [](const LoopEdge& a, const LoopEdge& b) { return a.link.confidence > b.link.confidence; });
  std::printf("  %zu edges from %zu key images, confidence %.2f .. %.2f; the 5 most confident (--edges lists all):\n",
              edges.size(), queries.size(), edges.back().link.confidence, edges.front().link.confidence);
  for (std::size_t k = 0; k < 5; ++k) line(edges[k]);
}

/// Refuses every option of `app` given on the command line (or in --config) that is not
/// in `allowed`: the options of another mode of the subcommand.
inline void refuse_other_options(const CLI::App& app, const std::vector<std::string>& allowed, const std::string& mode) {
  for (const CLI::Option* opt : app.get_options()) {
    if (opt->count() == 0) continue;
    std::string name = opt->get_lnames().empty() ? opt->get_name() : "--" + opt->get_lnames().front();
    if (opt->get_lnames().empty())  // a positional argument, named as the usage line names it
      std::transform(name.begin(), name.end(), name.begin(), [](unsigned char c) { return static_cast<char>(std::toupper(c)); });
    if (name == "--help" || name == "--config") continue;
    if (std::find(allowed.begin(), allowed.end(), name) == allowed.end())
      usage_error(mode + " and " + name + " conflict");
  }
}

}  // namespace vmap::examples
