#pragma once

// What the subcommands that read or write a visual memory file share (`vmap build
// --memory`, `vmap localize --memory`, `vmap loops --memory`, `vmap memory ...`): the
// policy stack a memory records and every reader instantiates again, the --memory path
// rule, loading with errors that name the option, streaming frames into a memory store
// (memory/store.hpp) synced at every key image, and the JSON / text of key images,
// localization answers and loop edges.

#include "common/bag_options.hpp"
#include "common/cli_support.hpp"
#include "common/policies.hpp"

#include <vmap/core/error.hpp>
#include <vmap/geometry/calibrated.hpp>
#include <vmap/io/frame_source.hpp>
#include <vmap/io/poses.hpp>
#include <vmap/memory/store.hpp>
#include <vmap/memory/visual_memory.hpp>
#include <vmap/som/pose_io.hpp>

#include <nlohmann/json.hpp>
#include <opencv2/core/affine.hpp>
#include <opencv2/imgcodecs.hpp>

#include <algorithm>
#include <cctype>
#include <cmath>
#include <chrono>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <optional>
#include <string>
#include <string_view>
#include <variant>
#include <vector>

namespace vmap::examples {

/// What a memory the command line writes is built with: the descriptor (--features,
/// --nfeatures, --model, --refine-model), the F-matrix method (--estimator) and the
/// camera (--camera). A memory holds its options but not its policies, so the store
/// records this (the note `stack_note`) and every command that reads the memory
/// instantiates the same stack from it. A memory without the note (a .vmem file, a store
/// written by the library or by an earlier vmap) is ORB 1000 + MAGSAC++ on raw pixels,
/// the stack the command line used before it had a choice.
struct MemoryStack {
  DescriptorChoice descriptor;
  std::string estimator = "magsac";
  std::optional<CameraOption> camera;  ///< the calibration, kept in the note, not read again
};

/// The store's note that records a MemoryStack (JSON, examples/memory.md).
inline constexpr const char* stack_note = "stack";

inline nlohmann::json stack_json(const MemoryStack& s) {
  nlohmann::json j{{"features", s.descriptor.name},
                   {"nfeatures", s.descriptor.features},
                   {"model", s.descriptor.model},
                   {"refine_model", s.descriptor.refine_model},
                   {"estimator", s.estimator},
                   {"camera", nullptr}};
  if (s.camera) {
    const Camera& c = s.camera->camera;
    j["camera"] = {{"file", path_string(s.camera->file)},
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

/// A MemoryStack from the command line: model paths made absolute, so that a reader in
/// another folder finds them.
inline MemoryStack stack_of_args(DescriptorChoice d, std::string estimator, const std::string& camera_file,
                                  const std::string& input = {}) {
  std::error_code ec;
  for (std::string* path : {&d.model, &d.refine_model})
    if (!path->empty()) {
      const auto abs = std::filesystem::weakly_canonical(*path, ec);
      if (!ec) *path = abs.string();
    }
  (void)parse_method(estimator);  // an unknown method is refused before the memory is made
  return {std::move(d), std::move(estimator), camera_option(camera_file, input)};
}

/// The stack a memory store records; the default stack when it records none. A note
/// that is not a stack is a vmap::Error naming the memory.
inline MemoryStack recorded_stack(MemoryStore& store) {
  const auto note = store.note(stack_note);
  if (!note) return {};
  const std::string who = "memory '" + store.path().string() + "': its recorded stack";
  try {
    const auto j = nlohmann::json::parse(*note);
    MemoryStack s;
    s.descriptor.name = j.at("features").get<std::string>();
    s.descriptor.features = j.at("nfeatures").get<int>();
    s.descriptor.model = j.at("model").get<std::string>();
    s.descriptor.refine_model = j.at("refine_model").get<std::string>();
    s.estimator = j.at("estimator").get<std::string>();
    if (const auto& c = j.at("camera"); !c.is_null()) {
      Camera cam;
      const auto lens = c.at("lens").get<std::string>();
      if (lens != "pinhole" && lens != "fisheye") vmap::detail::fail(who + ": unknown lens '" + lens + "'");
      cam.lens = lens == "pinhole" ? LensModel::pinhole : LensModel::fisheye;
      cam.fx = c.at("fx").get<double>();
      cam.fy = c.at("fy").get<double>();
      cam.cx = c.at("cx").get<double>();
      cam.cy = c.at("cy").get<double>();
      cam.distortion = c.at("distortion").get<std::vector<double>>();
      cam.image_size = {c.at("width").get<int>(), c.at("height").get<int>()};
      cam.validate(who + "'s camera");
      s.camera = CameraOption{c.at("file").get<std::string>(), cam};
    }
    return s;
  } catch (const nlohmann::json::exception& e) {
    vmap::detail::fail(who + " is not valid: " + e.what());
  }
}

/// The stack's F-matrix verification: MAGSAC++ (or --estimator's method) at 1 px, on the
/// camera's undistorted keypoints when the stack has one (Calibrated, which then also
/// gives the relative pose of a localized query).
inline Calibrated<FundamentalEstimator> memory_estimator(const MemoryStack& s) {
  return {s.camera ? std::optional<Camera>(s.camera->camera) : std::nullopt,
          FundamentalEstimator({.method = parse_method(s.estimator)}),
          s.camera ? "the memory's camera (from " + s.camera->file.string() + ")" : std::string("camera")};
}

/// Calls f(descriptor, matcher, estimator) with the stack's policies (one instantiation
/// of f per descriptor type, as with_descriptor); f builds or loads a memory of
/// MemoryOf<decltype(descriptor), ...>.
template <class F>
int with_stack(const MemoryStack& s, F&& f) {
  const auto estimator = memory_estimator(s);
  return with_descriptor(s.descriptor, [&](auto descriptor) -> int {
    auto matcher = matcher_for(descriptor);
    auto verifier = estimator_for(descriptor, s.descriptor, estimator);
    return f(std::move(descriptor), std::move(matcher), std::move(verifier));
  });
}

/// The memory type of a policy stack (eq. 5's inlier ratio as the similarity).
template <class D, class M, class E>
using MemoryOf = VisualMemory<D, M, E, InlierRatio>;

/// "ORB 1000, MAGSAC++" / "XFeat* (model ...), camera tum.yaml": for summaries.
inline std::string stack_text(const MemoryStack& s) {
  std::string out = s.descriptor.name;
  if (s.descriptor.name == "orb" || s.descriptor.name == "sift" || s.descriptor.name == "xfeat")
    out += " " + std::to_string(s.descriptor.features);
  out += ", " + s.estimator;
  out += s.camera ? ", camera " + s.camera->file.string() : ", raw pixels";
  return out;
}

/// --working-memory's default: key images whose features a memory the command line
/// writes keeps in RAM (examples/memory.md, "Bounded memory": reading a released key
/// image's features from the store costs a fraction of its verification).
inline constexpr std::size_t default_working_memory = 200;

/// The file name used when --memory names a folder.
inline constexpr const char* memory_file_name = "memory.vmdb";

/// --memory DIR|FILE: an existing folder, or a path ending in '/', means DIR/memory.vmdb;
/// anything else is the memory file itself.
inline std::filesystem::path memory_file(const std::string& arg) {
  std::error_code ec;
  if (!arg.empty() && (arg.back() == '/' || std::filesystem::is_directory(arg, ec)))
    return std::filesystem::path(arg) / memory_file_name;
  return arg;
}

/// What a file given as a memory is, by its first bytes: a memory store (an SQLite file;
/// memory/store.hpp), a memory file of the library's single-file format (.vmem, "VMAPMEMO"),
/// or something else.
enum class MemoryFileKind : std::uint8_t { store, file, other };

inline MemoryFileKind memory_file_kind(const std::filesystem::path& file) {
  // An empty file is a store whose creation was interrupted (the file is made before
  // its tables): a memory, so that --force may replace it.
  std::error_code ec;
  if (std::filesystem::is_regular_file(file, ec) && std::filesystem::file_size(file, ec) == 0 && !ec)
    return MemoryFileKind::store;
  std::ifstream f(file, std::ios::binary);
  char head[16] = {};
  f.read(head, sizeof head);
  const std::string_view h(head, static_cast<std::size_t>(std::max<std::streamsize>(f.gcount(), 0)));
  if (h == std::string_view("SQLite format 3\0", 16)) return MemoryFileKind::store;
  if (h.size() >= 8 && h.substr(0, 8) == std::string_view(vmap::detail::memory_magic, 8)) return MemoryFileKind::file;
  return MemoryFileKind::other;
}

/// Checks the memory file a command will write (not an input, not a link or folder, its
/// folder created and writable) before any frame is read. An existing file is kept: it
/// is continued (`resume`), replaced only with `force` and only when it is a memory (a
/// mistyped path never overwrites another file), and refused otherwise.
inline void prepare_memory_output(const std::filesystem::path& file, const std::string& option,
                                  const std::vector<std::filesystem::path>& inputs, bool resume = false,
                                  bool force = false) {
  const std::filesystem::path dir = file.has_parent_path() ? file.parent_path() : std::filesystem::path(".");
  std::error_code ec;
  // An --out folder is replaced as a whole by the next --out run: a memory kept there
  // would be deleted with it.
  if (std::filesystem::exists(dir / vmap::detail::output_marker, ec))
    usage_error(option + ": '" + dir.string() +
                "' is an --out folder of vmap, which the next --out run replaces as a whole; keep the memory in "
                "another folder");
  prepare_output_dir(dir, option, inputs, {file.filename().string()});
  if (resume || !std::filesystem::exists(file, ec)) return;
  if (memory_file_kind(file) == MemoryFileKind::other)
    usage_error(option + ": '" + file.string() + "' exists and is not a vmap memory; refusing to replace it");
  if (!force)
    usage_error(option + ": the memory '" + file.string() + "' exists: " +
                (option == "--memory" ? "give --resume to continue it, --session new to add a run to it, or --force "
                                        "to replace it"
                                      : "give --force to replace it"));
}

/// Reads a memory file: a missing path, a folder or a device is a usage error naming
/// `option`; anything that is not a valid memory file is a vmap::Error naming the file
/// and the section (exit 1).
/// A file given as a memory that is neither kind: a vmap::Error naming it (exit 1).
inline void check_memory_file(const std::filesystem::path& file) {
  if (memory_file_kind(file) == MemoryFileKind::other)
    vmap::detail::fail("'" + file.string() + "' is not a vmap memory (neither a memory store nor a .vmem memory file)");
}

/// The stack a memory file records (the default stack for a .vmem file, which has no
/// notes).
inline MemoryStack memory_stack(const std::filesystem::path& file, const std::string& option) {
  check_input_file(file, option);
  check_memory_file(file);
  if (memory_file_kind(file) != MemoryFileKind::store) return {};
  auto store = MemoryStore::open(file, sqlite::Access::read);
  return recorded_stack(store);
}

/// Reads a memory file with the given policies (its recorded stack's, from with_stack).
/// `pixels`: decode the key images' pixels (false for the commands that never show them:
/// info, export, loops, localize; the memory then cannot be written with pixels).
template <class D, class M, class E>
MemoryOf<D, M, E> load_memory_with(const std::filesystem::path& file, const std::string& option, bool pixels,
                                   D descriptor, M matcher, E estimator) {
  check_input_file(file, option);
  check_memory_file(file);
  MapLoadOptions limits;
  limits.decode_images = pixels;
  if (memory_file_kind(file) == MemoryFileKind::store) {
    auto store = MemoryStore::open(file, sqlite::Access::read);
    return store.load<MemoryOf<D, M, E>>(std::move(descriptor), std::move(matcher), std::move(estimator), InlierRatio{},
                                         limits);
  }
  return MemoryOf<D, M, E>::load(file, std::move(descriptor), std::move(matcher), std::move(estimator), InlierRatio{}, limits);
}

/// Loads the memory file with its recorded stack and calls f(memory, stack).
template <class F>
int with_memory(const std::filesystem::path& file, const std::string& option, bool pixels, F&& f) {
  const MemoryStack stack = memory_stack(file, option);
  return with_stack(stack, [&](auto descriptor, auto matcher, auto estimator) -> int {
      auto mem = load_memory_with(file, option, pixels, std::move(descriptor), std::move(matcher), std::move(estimator));
      return f(mem, stack);
  });
}

/// A memory store a run writes into, and the memory it holds.
template <class Memory>
struct MemoryWriter {
  MemoryStore store;
  Memory memory;
};

/// What a memory records of its input (the "input" note): the input's path, its first
/// frame's name (lists and folders) and the stride. --resume reads the same input.
inline std::string input_fingerprint(const std::string& input, const FrameSource& src, std::size_t stride) {
  std::error_code ec;
  const auto canonical = std::filesystem::weakly_canonical(input, ec);
  const auto paths = src.paths();
  nlohmann::json j{{"input", ec ? input : canonical.string()},
                   {"first_frame", paths.empty() ? std::string() : paths.front().filename().string()},
                   {"stride", stride}};
  if (const auto topic = src.bag_topic()) j["topic"] = topic->name;  // a bag: the topic read
  return j.dump();
}

/// The note that records session s's input ("input" for the first, "input 1", ...).
inline std::string session_note(std::size_t session) {
  return session == 0 ? std::string("input") : "input " + std::to_string(session);
}

/// --resume of a store whose last session was built from another input (path, first
/// frame or stride) is refused with both named; a store without the note (written by the
/// library, or converted) takes this run's.
template <class Memory>
void check_same_input(MemoryWriter<Memory>& w, const std::string& fingerprint) {
  const std::string name = session_note(w.memory.sessions().size() - 1);
  const auto recorded = w.store.note(name);
  if (!recorded) {
    w.store.set_note(name, fingerprint);
    return;
  }
  if (*recorded == fingerprint) return;
  const auto describe = [](const std::string& f) {
    const auto j = nlohmann::json::parse(f, nullptr, false);
    if (j.is_discarded() || !j.is_object()) return f;
    return "'" + j.value("input", std::string()) + "' (first frame '" + j.value("first_frame", std::string()) +
           "', stride " + std::to_string(j.value("stride", std::size_t{0})) + ")";
  };
  usage_error("--resume: the memory '" + w.store.path().string() + "' was built from " + describe(*recorded) +
              "; this run reads " + describe(fingerprint) +
              ". Give the same input and --stride, --session new to add this run as a new session, or start another "
              "memory");
}

/// A new memory store at `file` (an existing memory removed first when `force`; the
/// caller checked it with prepare_memory_output), recording the memory's `stack`.
template <class Memory>
MemoryWriter<Memory> create_memory(const std::filesystem::path& file, bool force, Memory memory,
                                   const MemoryStack& stack) {
  if (force) {
    std::error_code ec;
    for (const char* suffix : {"", "-wal", "-shm"}) std::filesystem::remove(file.string() + suffix, ec);
  }
  MemoryWriter<Memory> w{MemoryStore::create(file), std::move(memory)};
  w.store.set_note(stack_note, stack_json(stack).dump());
  return w;
}

/// Removes the store a run created when the run ends (an error, no frame) before
/// keep(): no empty memory is left behind. A resumed memory is never removed.
template <class Memory>
class NewMemoryGuard {
 public:
  NewMemoryGuard(std::optional<MemoryWriter<Memory>>& w, bool created) : w_(&w), armed_(created) {}
  NewMemoryGuard(const NewMemoryGuard&) = delete;
  NewMemoryGuard& operator=(const NewMemoryGuard&) = delete;
  void keep() noexcept { armed_ = false; }
  ~NewMemoryGuard() {
    if (!armed_ || !*w_) return;
    const std::filesystem::path file = (*w_)->store.path();
    w_->reset();
    std::error_code ec;
    for (const char* suffix : {"", "-wal", "-shm"}) std::filesystem::remove(file.string() + suffix, ec);
  }

 private:
  std::optional<MemoryWriter<Memory>>* w_;
  bool armed_;
};

/// How a run continues an existing memory: its last session after its last frame
/// (--resume), or a new session from the input's first frame (--session new).
enum class Continuation : std::uint8_t { resume, new_session };

/// How a run of `build --memory` / `memory build` treats its memory, from --resume,
/// --session new and --force (conflicting pairs are usage errors): nullopt for a new
/// memory (replacing an existing one with --force).
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

/// The store of the memory a run continues: a missing file is a usage error that says
/// how to start one; options that would change the memory's own (`options_kept` and
/// stack_options(), given on the command line) conflict.
inline MemoryStore store_to_continue(const std::filesystem::path& file, const CLI::App& app,
                                     const std::vector<std::string>& options_kept, Continuation how) {
  const std::string flag = how == Continuation::resume ? "--resume" : "--session new";
  for (const auto& list : {options_kept, stack_options()})
    for (const auto& o : list)
      if (app.get_option(o)->count() > 0)
        usage_error(flag + " and " + o + " conflict (a continued memory keeps the options it was started with)");
  std::error_code ec;
  if (!std::filesystem::exists(file, ec))
    usage_error(flag + ": no memory file '" + file.string() + "' to continue (run without " + flag + " to start one)");
  check_input_file(file, "--memory");
  check_memory_file(file);
  if (memory_file_kind(file) == MemoryFileKind::file)
    usage_error(flag + ": '" + file.string() + "' is a single-file memory (.vmem); convert it to a memory store "
                "first: vmap memory convert " + file.string() + " NEW.vmdb");
  auto store = MemoryStore::open(file, sqlite::Access::write);
  if (!store.synced())
    usage_error(flag + ": the memory '" + file.string() + "' holds nothing yet (its first run stopped before its "
                "first key image was written): start it again with --force");
  return store;
}

/// The memory a run continues, from its store (store_to_continue) with its recorded
/// policies. With a `working_memory` (> 0) the memory is loaded holding only that many
/// key images' features (MemoryStore::load_bounded). With Continuation::new_session a new
/// session is started.
template <class D, class M, class E>
MemoryWriter<MemoryOf<D, M, E>> memory_to_continue(MemoryStore store, std::size_t working_memory, Continuation how,
                                                   D descriptor, M matcher, E estimator) {
  using Memory = MemoryOf<D, M, E>;
  auto memory = working_memory > 0
                    ? store.load_bounded<Memory>(working_memory, std::move(descriptor), std::move(matcher),
                                                 std::move(estimator), InlierRatio{})
                    : store.load<Memory>(std::move(descriptor), std::move(matcher), std::move(estimator), InlierRatio{});
  if (how == Continuation::new_session) memory.start_session();
  return MemoryWriter<Memory>{std::move(store), std::move(memory)};
}

/// Records `fingerprint` as the input of the memory's last session: a new session's, or
/// (checked) the resumed one's.
template <class Memory>
void record_input(MemoryWriter<Memory>& w, Continuation how, const std::string& fingerprint) {
  if (how == Continuation::resume)
    check_same_input(w, fingerprint);
  else
    w.store.set_note(session_note(w.memory.sessions().size() - 1), fingerprint);
}

/// What `vmap build --memory` and `vmap memory build` start a memory with.
struct NewMemory {
  double tau = 0.3;
  KeyRule rule = KeyRule::previous_frame;
  std::string images = "none";  ///< none, png or jpeg
  std::string vocabulary;       ///< a vocabulary file (vmap vocabulary); empty: learned online
  std::size_t vocabulary_after = MemoryOptions{}.vocabulary_after;
  /// The place decision's threshold for loop edges (lcd/place_decision.hpp).
  double min_confidence = PlaceDecisionOptions{}.min_confidence;
};

template <class D, class M, class E>
MemoryOf<D, M, E> new_memory(const NewMemory& n, D descriptor, M matcher, E estimator) {
  MemoryOptions o;
  o.selector.tau = n.tau;
  o.selector.rule = n.rule;
  o.vocabulary_after = n.vocabulary_after;
  o.loops.decision.min_confidence = n.min_confidence;
  if (n.images == "png")
    o.images = ImageStorage::png;
  else if (n.images == "jpeg")
    o.images = ImageStorage::jpeg;
  else if (n.images == "none")
    o.images = ImageStorage::none;
  else
    usage_error("--images: unknown storage '" + n.images + "' (choose none, png or jpeg)");
  AnyVocabulary voc;
  if (!n.vocabulary.empty()) {
    check_input_file(n.vocabulary, "--vocabulary");
    voc = AnyVocabulary::load(n.vocabulary);
  }
  return MemoryOf<D, M, E>(std::move(descriptor), std::move(matcher), std::move(estimator), InlierRatio{}, o, std::move(voc));
}

/// The frame range a resumed memory reads: the frames after the last one it holds, in
/// the sequence's index space (the same --stride as the first run gives the same frames
/// an uninterrupted run would have read). Nothing left to read is a usage error.
template <class Memory>
FrameSourceOptions resume_range(const Memory& mem, FrameSourceOptions so, const std::string& file) {
  if (const auto last = mem.last_frame_index()) so.start = std::max(so.start, *last + so.stride);
  if (so.start >= so.end)
    usage_error("--resume: the memory '" + file + "' already holds every frame up to --end (its last frame is " +
                std::to_string(mem.last_frame_index().value_or(0)) + ")");
  return so;
}

/// --resume of a memory that already holds the last frame of a folder or list (whose
/// length is exact; a video's stated frame count is not trusted): a usage error that
/// says so, as resume_range says it for --end, instead of a run that reads no frame.
template <class Memory>
void check_frames_left(const Memory& mem, const FrameSource& src, const FrameSourceOptions& so,
                              const std::string& file) {
  const auto total = src.total();
  if (src.kind() != SourceKind::video && total && so.start >= *total)
    usage_error("--resume: the memory '" + file + "' already holds every frame of its input (its last frame is " +
                std::to_string(mem.last_frame_index().value_or(0)) + ")");
}

/// What stream_into did.
struct StreamResult {
  std::size_t pushed = 0;       ///< frames pushed in this run
  std::size_t saves = 0;        ///< syncs into the store (one transaction each)
  double seconds = 0.0;         ///< pushing (without the syncs)
  /// The pushing thread's time in the syncs: collecting the rows and waiting for the
  /// previous commit (the commit itself runs in the store's writer thread).
  double save_seconds = 0.0;
  std::vector<LoopEdge> loops;  ///< loop edges found in this run
};

/// The odometry pose of each frame from a camera pose file (TUM or KITTI, as
/// load_camera_poses reads it): by order when the file has one pose per frame of the
/// sequence, else the pose nearest in time within 50 ms (TUM fr1's ground truth has gaps
/// of up to 49 ms). A frame without one is an Error naming the file and the frame.
/// `floor`: the SE(2) floor pose (som/pose_io.hpp: TUM's z-up floor, KITTI's y-down)
/// instead of the SE(3) camera pose, as the GCS localizer learns them.
class FramePoses {
 public:
  FramePoses(const std::filesystem::path& file, const FrameSource& src, bool floor = false)
      : name_(file.string()), poses_(load_camera_poses(file)), floor_(floor) {
    if (floor_) format_ = guess_camera_pose_format(read_text_file(file, "pose file"), name_);
    const auto times = src.timestamps();  // empty for a video
    by_order_ = poses_.size() == (times.empty() ? src.total().value_or(0) : times.size());
  }

  [[nodiscard]] OdometryPose operator()(const Frame& f) const {
    std::optional<std::size_t> k;
    if (by_order_)
      k = f.index;
    else
      k = associate_by_timestamp(poses_, std::vector<double>{f.timestamp}, 0.05).front();
    if (!k || *k >= poses_.size())
      vmap::detail::fail(name_ + ": no pose for frame " + std::to_string(f.index) + " (" + f.name + ", time " +
                         std::to_string(f.timestamp) + ")");
    if (floor_)
      return format_ == CameraPoseFormat::kitti ? floor_pose_y_down(poses_[*k]) : floor_pose_z_up(poses_[*k]);
    return cv::Affine3d(poses_[*k].rotation, poses_[*k].position);
  }

 private:
  std::string name_;
  std::vector<CameraPose> poses_;
  bool floor_ = false;
  CameraPoseFormat format_ = CameraPoseFormat::tum;
  bool by_order_ = false;
};

/// Pushes every frame of `src` into the writer's memory, with its pose when `poses` is
/// given, and syncs the store after each frame that made a key image or a loop edge,
/// every `save_every` pushed frames besides (0: no others) and after the last frame: a
/// run killed half way resumes from the last sync. The memory holds the features of its
/// `working_memory` most recent key images in RAM (0: all) and reads the others from the
/// store. `on_frame(mem)` is called after each push.
template <class Memory, class OnFrame>
StreamResult stream_into(MemoryWriter<Memory>& w, FrameSource& src, std::size_t save_every, std::size_t working_memory,
                         const std::optional<FramePoses>& poses, OnFrame&& on_frame) {
  using clock = std::chrono::steady_clock;
  if (working_memory > 0) w.store.bound(w.memory, working_memory);
  StreamResult r;
  const auto sync = [&] {
    const auto t0 = clock::now();
    w.store.sync(w.memory);
    r.save_seconds += std::chrono::duration<double>(clock::now() - t0).count();
    ++r.saves;
  };
  bool unsynced = false;
  while (auto f = src.next()) {
    const OdometryPose pose = poses ? (*poses)(*f) : OdometryPose{};
    const auto t0 = clock::now();
    auto step = w.memory.push(*f, pose);
    r.seconds += std::chrono::duration<double>(clock::now() - t0).count();
    ++r.pushed;
    r.loops.insert(r.loops.end(), step.loops.begin(), step.loops.end());
    on_frame(w.memory);
    unsynced = true;
    if (step.new_key || !step.loops.empty() || (save_every > 0 && r.pushed % save_every == 0)) {
      sync();
      unsynced = false;
    }
  }
  if (unsynced) sync();
  return r;
}

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

/// A verified key image of a localization answer.
template <class Memory>
nlohmann::json link_json(const Memory& mem, const PlaceLink& l) {
  const auto& k = mem.map().keys[l.key];
  nlohmann::json f = nlohmann::json::array();
  for (double e : l.fundamental.val) f.push_back(e);
  return {{"key", l.key},
          {"frame_index", k.frame_index},
          {"name", k.name},
          {"inliers", l.inliers},
          {"matches", l.matches},
          {"bow_score", l.bow_score},
          {"similarity", l.similarity},
          {"confidence", l.confidence},
          {"fundamental", f},
          {"pose", pose_json(mem.poses()[l.key])}};
}

/// A loop edge: key images (from, to) and their frames (query, match), as `vmap loops`
/// names the frames of a loop.
template <class Memory>
nlohmann::json loop_json(const Memory& mem, const LoopEdge& e) {
  return {{"from", e.from},
          {"to", e.link.key},
          {"from_session", mem.session_of(e.from)},
          {"to_session", mem.session_of(e.link.key)},
          {"query", mem.map().keys[e.from].frame_index},
          {"match", mem.map().keys[e.link.key].frame_index},
          {"query_name", mem.map().keys[e.from].name},
          {"match_name", mem.map().keys[e.link.key].name},
          {"query_time", mem.map().keys[e.from].timestamp},
          {"match_time", mem.map().keys[e.link.key].timestamp},
          {"inliers", e.link.inliers},
          {"matches", e.link.matches},
          {"bow_score", e.link.bow_score},
          {"similarity", e.link.similarity},
          {"confidence", e.link.confidence}};
}

/// One query image's answer.
struct MemoryQuery {
  std::string image;
  MemoryLocalization answer;
  double ms = 0.0;
};

/// Localizes each image (read in grey, as the memory's frames were), and each frame of a
/// bag given among them (named "BAG:topic@stamp"); an unreadable image is a vmap::Error
/// naming it.
template <class Memory>
std::vector<MemoryQuery> localize_images(Memory& mem, const std::vector<std::string>& images,
                                         const PlaceDecisionOptions& decision) {
  std::vector<MemoryQuery> out;
  for (const auto& path : images) {
    current_inputs() = {path};
    if (is_bag(path)) {
      auto frames = open_frames(path, {.grey = true});
      while (auto f = frames.next()) {
        const auto t0 = std::chrono::steady_clock::now();
        MemoryQuery q{path + ":" + f->name, mem.localize(f->image, &decision), 0.0};
        q.ms = std::chrono::duration<double, std::milli>(std::chrono::steady_clock::now() - t0).count();
        out.push_back(std::move(q));
      }
      continue;
    }
    // Bounded like frame sources: a regular file, its pixels checked before decoding.
    cv::Mat img;
    try {
      img = vmap::read_image(path, {.flags = cv::IMREAD_GRAYSCALE});
    } catch (const vmap::Error& e) {
      vmap::detail::fail("query " + std::string(e.what()));  // "query image 'x': reason"
    }
    const auto t0 = std::chrono::steady_clock::now();
    MemoryQuery q{path, mem.localize(img, &decision), 0.0};
    q.ms = std::chrono::duration<double, std::milli>(std::chrono::steady_clock::now() - t0).count();
    out.push_back(std::move(q));
  }
  return out;
}

/// The evidence of a place decision (lcd/place_decision.hpp).
inline nlohmann::json evidence_json(const PlaceEvidence& e) {
  return {{"matches", e.matches},         {"inliers", e.inliers},       {"inlier_ratio", e.inlier_ratio},
          {"significance", e.significance}, {"spread", e.spread},       {"bow_score", e.bow_score},
          {"model", std::string(to_string(e.model))}};
}

/// The rotation angle of R in degrees (from its trace).
inline double rotation_degrees(const cv::Matx33d& R) {
  const double c = std::clamp((cv::trace(R) - 1.0) / 2.0, -1.0, 1.0);
  return std::acos(c) * 180.0 / CV_PI;
}

/// A relative pose (core/verification.hpp): R by rows, the unit t, the inliers in front
/// of both cameras; null when the memory has no camera or the decomposition failed.
inline nlohmann::json relative_pose_json(const std::optional<RelativePose>& p) {
  if (!p) return nullptr;
  nlohmann::json r = nlohmann::json::array();
  for (int i = 0; i < 9; ++i) r.push_back(p->rotation.val[i]);
  return {{"rotation", r},
          {"rotation_degrees", rotation_degrees(p->rotation)},
          {"translation", {p->translation[0], p->translation[1], p->translation[2]}},
          {"points_in_front", p->points_in_front}};
}

/// Every answer: per query its decision (status, reason, confidence, evidence), time and
/// every verified key image (most confident first).
template <class Memory>
nlohmann::json localizations_json(const Memory& mem, const std::vector<MemoryQuery>& queries) {
  nlohmann::json out = nlohmann::json::array();
  for (const auto& q : queries) {
    nlohmann::json j{{"image", path_string(q.image)},
                     {"status", std::string(to_string(q.answer.status))},
                     {"reason", q.answer.reason},
                     {"confidence", q.answer.confidence},
                     {"localized", q.answer.ok()},
                     {"evidence", evidence_json(q.answer.evidence)},
                     {"verified_candidates", q.answer.verified_candidates},
                     {"ms", q.ms},
                     {"matches", nlohmann::json::array()}};
    j["key"] = q.answer.best() ? nlohmann::json(q.answer.best()->key) : nlohmann::json(nullptr);
    // The GCS position (Algorithm 5), present when the memory holds a trained GCS
    // (VisualMemory::train_gcs); null otherwise.
    j["position"] = q.answer.position ? pose_json(q.answer.position->pose) : nlohmann::json(nullptr);
    // The query's camera relative to the best key image's (X_key = R X_query + t, |t| = 1),
    // present when the memory has a camera (--camera) and the F-matrix was verified.
    j["relative_pose"] = relative_pose_json(q.answer.relative_pose);
    for (const auto& l : q.answer.matches) j["matches"].push_back(link_json(mem, l));
    out.push_back(std::move(j));
  }
  return out;
}

/// One line per query: the accepted key image (index, frame, name), confidence, inliers,
/// BoW score, pose; or the decision and its reason ("unknown place (confidence 0.12 <
/// 0.50)").
template <class Memory>
void print_localizations(const Memory& mem, const std::vector<MemoryQuery>& queries) {
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
    if (q.answer.best() && q.answer.relative_pose) {
      const RelativePose& p = *q.answer.relative_pose;
      std::printf("  relative to the key image: rotation %.2f deg, translation direction (%.3f, %.3f, %.3f)\n",
                  rotation_degrees(p.rotation), p.translation[0], p.translation[1], p.translation[2]);
    }
    if (q.answer.position) {
      const Pose2& p = q.answer.position->pose;
      std::printf("  GCS position (%.3f, %.3f, %.3f rad)\n", p.x(), p.y(), p.theta());
    }
  }
}

/// `vmap localize --memory M IMAGE...` and `vmap memory localize M IMAGE...`: the answers
/// as lines, or with `json` one object whose `queries` list every answer.
inline int localize_from_memory(const std::filesystem::path& file, const std::string& option,
                                const std::vector<std::string>& images, bool json,
                                std::optional<double> min_confidence = std::nullopt) {
  current_inputs() = {file.string()};
  return with_memory(file, option, false, [&](auto& mem, const MemoryStack& stack) -> int {
    PlaceDecisionOptions decision = mem.options().loops.decision;
    if (min_confidence) decision.min_confidence = *min_confidence;
    const auto queries = localize_images(mem, images, decision);
    if (!json) {
      print_localizations(mem, queries);
      return 0;
    }
    std::size_t localized = 0;
    for (const auto& q : queries) localized += q.answer.ok() ? 1 : 0;
    print_json({{"command", "localize"},
                {"memory", path_string(file)},
                {"stack", stack_json(stack)},
                {"frames", mem.frames()},
                {"key_images", mem.key_images()},
                {"min_confidence", decision.min_confidence},
                {"queries", localizations_json(mem, queries)},
                {"localized", localized}});
    return 0;
  });
}

/// The loop edges: with `all`, one line per edge in the style of `vmap loops` (frame
/// names and times); otherwise a summary (how many, key images involved, confidence) and
/// the five most confident edges, so a long memory does not flood the terminal.
template <class Memory>
void print_loop_edges(const Memory& mem, bool all = false) {
  const auto& keys = mem.map().keys;
  const bool sessions = mem.sessions().size() > 1;
  const auto session = [&](std::uint32_t k) {
    return sessions ? "session " + std::to_string(mem.session_of(k) + 1) + ", " : std::string();
  };
  const auto line = [&](const LoopEdge& e) {
    std::printf("  key %4u (%sframe %4zu, %s, %.6f s) -> key %4u (%sframe %4zu, %s, %.6f s)  confidence %.2f  inliers %4d  "
                "bow score %.3f\n",
                e.from, session(e.from).c_str(), keys[e.from].frame_index, keys[e.from].name.c_str(),
                keys[e.from].timestamp, e.link.key, session(e.link.key).c_str(), keys[e.link.key].frame_index,
                keys[e.link.key].name.c_str(), keys[e.link.key].timestamp, e.link.confidence, e.link.inliers,
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
