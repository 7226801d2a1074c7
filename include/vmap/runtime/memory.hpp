#pragma once

// One visual memory whatever its policy stack and wherever it is kept, for programs that
// choose at run time (a command line, a configuration file, the Python module):
//
//   auto memory = vmap::AnyMemory::open("run.vmdb", {.write = true, .new_session = true});
//   while (auto frame = frames.next()) memory.push(*frame);   // synced at key images
//   memory.close();
//
//   auto query = vmap::AnyMemory::open("run.vmdb");            // read-only, while it maps
//   vmap::MemoryLocalization answer = query.localize(image);
//
// AnyMemory holds a VisualMemory of one of the shipped stacks (runtime/stack.hpp; the
// stack is read back from the memory's own policy records) and, for a memory store, the
// store it is synced into. Every call goes to the concrete memory: nothing per feature
// crosses this interface. A memory is opened from a memory store (SQLite,
// memory/store.hpp) or a single file (.vmem, memory/vmem.hpp), told apart by their first
// bytes; a store is opened to read (a snapshot, also while another program writes it) or
// to write (one writer at a time: pushing syncs it, SyncPolicy). A new store replaces an
// existing memory only when asked (MemoryCreateOptions::replace), atomically: it is built
// beside the old one while readers keep reading that, and renamed over it by close();
// a run that fails, or a memory destroyed before close(), leaves the old one as it was
// (memory/replace.hpp).
//
// Compiling it: this header declares AnyMemory and the types of its answers only. Its
// definitions (runtime/detail/memory_impl.hpp: the stores, the memories of every shipped
// stack) are included at the end of this file in a header-only program, and compiled
// once in vmap::stacks for a program that links it (core/compiled.hpp), whose files then
// parse no VisualMemory. A caller of store() or records() includes memory/store.hpp or
// memory/records.hpp; one that passes a vocabulary, runtime/vocabulary.hpp; one that
// asks what a file is (memory_kind), memory/replace.hpp.
//
// Threading: as VisualMemory (memory/visual_memory.hpp): one thread at a time calls
// push(), localize() and the other members; separate AnyMemory objects share nothing.

#include <vmap/core/compiled.hpp>
#include <vmap/core/error.hpp>
#include <vmap/core/features.hpp>
#include <vmap/hooks/detection.hpp>
#include <vmap/io/frame.hpp>
#include <vmap/memory/options.hpp>
#include <vmap/memory/types.hpp>
#include <vmap/runtime/policy_stack.hpp>

#include <opencv2/core.hpp>

#include <array>
#include <cstddef>
#include <cstdint>
#include <filesystem>
#include <memory>
#include <optional>
#include <string>
#include <string_view>
#include <system_error>
#include <vector>

namespace vmap {

class AnyVocabulary;
class FleetIndex;
class MemoryReplacement;
class MemoryStore;
struct MemoryRecords;
struct MetricPoseOptions;
struct VisualMap;

/// The file name a folder given as a memory holds.
inline constexpr const char* memory_file_name = "memory.vmdb";

/// A memory path as a user gives it: an existing folder, or a path ending in '/', means
/// the folder's memory.vmdb; a PostgreSQL URI (postgresql://..., a fleet's memory) is
/// kept as it is; anything else is the memory file itself.
[[nodiscard]] inline std::filesystem::path memory_path(std::string_view given) {
  std::error_code ec;
  const std::filesystem::path p(given);
  if (given.starts_with("postgresql://") || given.starts_with("postgres://")) return p;
  if (!given.empty() && (given.back() == '/' || std::filesystem::is_directory(p, ec))) return p / memory_file_name;
  return p;
}

/// When pushing syncs a memory store: after every frame that made a key image or a loop
/// edge (so a program killed after it resumes from there), and every `every` frames
/// besides (0: no others).
struct SyncPolicy {
  std::size_t every = 0;
};

/// How AnyMemory::open opens a memory.
struct MemoryOpenOptions {
  /// A fleet's memory (a postgresql:// URI): the robot whose memory to open. Unused for
  /// a file.
  std::string robot = {};
  /// Open a store to push into it (one writer at a time; an older schema is brought to
  /// the current one). false: read it as it was last synced.
  bool write = false;
  /// (write) start a new session: the next frame starts another run of the robot.
  bool new_session = false;
  /// Decode the key images' pixels (needed to write them into another file or store;
  /// always with `write`).
  bool pixels = false;
  /// (write) key images whose features stay in RAM; the older ones are read from the
  /// store when a candidate needs them (0: all).
  std::size_t working_memory = 0;
  SyncPolicy sync{};
};

/// How AnyMemory::create (and copy_into_store) makes a memory store.
struct MemoryCreateOptions {
  /// A fleet's memory (a postgresql:// URI): the new robot whose memory it is (refused
  /// when the fleet has it). Unused for a file.
  std::string robot = {};
  std::size_t working_memory = 0;  ///< as MemoryOpenOptions::working_memory
  SyncPolicy sync{};
  /// Replace an existing memory at the path (a store or a .vmem file, known by their own
  /// records: memory_kind; any other file, an SQLite database of another program
  /// included, is refused): the new store is built under another name and renamed over it
  /// by close(), holding the old one's writer lock meanwhile (refused while another
  /// program writes it). false: an existing file is refused. A path with no file gets a
  /// new store there either way: an empty store made whole (MemoryStore::create), then
  /// written in place so that readers can follow it.
  bool replace = false;
  /// A new store where no file is appears there only when closed, whole: it is built under
  /// another name as a replacement is (a killed run leaves no memory there; a file
  /// another program made there meanwhile is not replaced). false: written in place.
  bool whole_at_close = false;
};


namespace detail {
class MemoryConcept;
}  // namespace detail

/// One visual memory of a shipped stack (see the top of this file). Move-only.
class AnyMemory {
 public:
  /// Opens the memory at `path` (a memory store or a .vmem file; see memory_path for a
  /// folder), with the stack its policies recorded. A .vmem file is read whole and cannot
  /// be written (convert it into a store). An Error names the file and what is wrong: it
  /// does not exist or is not a memory, another program writes it (write), it is
  /// damaged, or its policies are not one of the shipped stacks.
  [[nodiscard]] static AnyMemory open(const std::filesystem::path& path, const MemoryOpenOptions& options = {});

  /// A new memory store at `path` (its folder made when missing) of `stack`, with these
  /// options and vocabulary (empty: learned from the first key images). An existing file
  /// is refused, or with `how.replace` replaced by close() when it is a memory. The
  /// stack's camera source is kept as the store's note "camera source".
  [[nodiscard]] static AnyMemory create(const std::filesystem::path& path, const PolicyStack& given,
                                        const MemoryOptions& options = {}, const MemoryCreateOptions& how = {});
  /// The same with a vocabulary given (an empty one: learned, as above).
  [[nodiscard]] static AnyMemory create(const std::filesystem::path& path, const PolicyStack& given,
                                        const MemoryOptions& options, AnyVocabulary vocabulary,
                                        const MemoryCreateOptions& how);

  /// A memory in RAM (not kept anywhere until saved) of `stack`.
  [[nodiscard]] static AnyMemory in_ram(const PolicyStack& given, const MemoryOptions& options = {});
  /// The same with a vocabulary given.
  [[nodiscard]] static AnyMemory in_ram(const PolicyStack& given, const MemoryOptions& options,
                                        AnyVocabulary vocabulary);

  /// A memory store at `path` holding `source`'s memory (its records written whole into
  /// a new store): a .vmem file made a store, a store copied. An existing file is refused,
  /// or with `how.replace` replaced by close() when it is a memory; with
  /// `how.whole_at_close` a new one appears at close() only (`how.robot` names a fleet's
  /// robot; the other fields are not used). The memory must have been opened with its
  /// pixels when it keeps them.
  [[nodiscard]] static AnyMemory copy_into_store(AnyMemory&& source, const std::filesystem::path& path,
                                                 const MemoryCreateOptions& how = {});

  AnyMemory(AnyMemory&&) noexcept;
  AnyMemory& operator=(AnyMemory&&) noexcept;
  AnyMemory(const AnyMemory&) = delete;
  AnyMemory& operator=(const AnyMemory&) = delete;
  /// Waits for a sync in flight (a failure of it is dropped: close() or flush() first).
  /// A memory replacing another (MemoryCreateOptions::replace) that was not closed is
  /// discarded: the memory it was to replace stays.
  ~AnyMemory();

  // ---- what it is ---------------------------------------------------------------------

  [[nodiscard]] const PolicyStack& stack() const noexcept { return stack_; }
  /// The file it was opened from or created at (a fleet's URI without its password);
  /// empty for a memory in RAM.
  [[nodiscard]] const std::filesystem::path& path() const noexcept { return path_; }
  /// The robot whose memory it is in a fleet's memory; empty otherwise.
  [[nodiscard]] const std::string& robot() const noexcept { return robot_; }
  /// How messages name it: "memory 'run.vmdb'", or "robot 'a' of memory 'postgresql://...'".
  [[nodiscard]] std::string name() const;
  /// store, file, or other for a memory in RAM.
  [[nodiscard]] MemoryKind kind() const noexcept { return kind_; }
  /// Whether push() and the other changes are allowed (a memory in RAM, a store opened
  /// to write); false for a snapshot read or a closed memory.
  [[nodiscard]] bool writes() const noexcept { return writes_ && !closed_; }
  /// Whether it was opened to read only (a snapshot of a store, a file not opened to write).
  [[nodiscard]] bool read_only() const noexcept { return !writes_; }
  /// Whether close() is still to rename the store over the memory it replaces, or into
  /// place (MemoryCreateOptions::replace, whole_at_close): until then path() holds the
  /// old memory, or nothing.
  [[nodiscard]] bool replaces() const noexcept { return replacement_ != nullptr; }
  /// The store it is synced into, or nullptr (a file, a memory in RAM, a closed memory).
  [[nodiscard]] MemoryStore* store() noexcept;

  // ---- changing it -------------------------------------------------------------------

  /// Pushes a frame (with its odometry pose and, for a memory with object labels, its
  /// detections): VisualMemory::push. A memory store is synced as the SyncPolicy says;
  /// the sync's commit runs in the store's writer thread.
  MemoryStep push(const Frame& frame, const OdometryPose& pose = detail::no_odometry_pose,
                  const std::vector<Detection>* detections = nullptr);

  /// Starts a session (VisualMemory::start_session), synced at once into a store.
  void start_session();

  /// Trains the GCS localizer (VisualMemory::train_gcs), synced at once into a store.
  GcsTrainStats train_gcs(const MemoryGcsOptions& options = {});

  /// Appends `other`'s sessions (VisualMemory::merge): both must be of one stack (the
  /// camera by its parameters) and options; `other` must hold all its features and be
  /// opened with its pixels when it keeps them. `name` and `other_name` name them in errors.
  void merge(AnyMemory&& other, const std::string& name, const std::string& other_name);

  /// Hands what the memory made since the last sync to its store (a no-op without one);
  /// the commit runs in the store's writer thread (flush() waits for it).
  void sync();

  /// sync() when frames were pushed since the last one.
  void sync_pending() {
    if (unsynced_ > 0) sync();
  }

  /// Syncs handed to the store so far, and the time the calling thread spent in them
  /// (encoding the rows, waiting for the previous commit).
  [[nodiscard]] std::size_t syncs() const noexcept { return syncs_; }
  [[nodiscard]] double sync_seconds() const noexcept { return sync_seconds_; }

  /// Waits until every sync is committed, throwing a failed one's error.
  void flush();

  /// Syncs, commits and closes the store (its write-ahead log moved into the file); the
  /// memory can still be read, not changed. A store replacing another memory is renamed
  /// over it here (an Error leaves the old one). A no-op for a memory without a store.
  void close();

  /// Ends a memory that replaces another without replacing it, for a run that failed:
  /// what it wrote is removed and the memory it was to replace stays; it is closed (read
  /// only). A no-op for any other memory (close() keeps what it wrote).
  void abandon();

  /// Writes the memory as a .vmem file, atomically (VisualMemory::save).
  void save(const std::filesystem::path& file, std::optional<ImageStorage> images = {}) const;

  // ---- reading it --------------------------------------------------------------------

  /// Where `image` was taken (VisualMemory::localize): the key image it shows and, for a
  /// memory with SE(3) poses and a camera, its metric pose (MemoryLocalization::pose).
  [[nodiscard]] MemoryLocalization localize(const cv::Mat& image, const PlaceDecisionOptions* decision = nullptr);
  /// The metric pose of a loop edge's newer key image against the one it revisits
  /// (VisualMemory::loop_pose).
  [[nodiscard]] PoseAnswer loop_pose(const LoopEdge& edge) const;
  /// When a query gets a metric pose (memory/metric_pose.hpp, which a caller includes):
  /// a setting of this program, not recorded with the memory.
  void set_pose_options(const MetricPoseOptions& options);
  [[nodiscard]] const MetricPoseOptions& pose_options() const noexcept;
  [[nodiscard]] const VisualMap& map() const noexcept;
  [[nodiscard]] std::size_t frames() const noexcept;
  [[nodiscard]] std::size_t key_images() const noexcept;
  [[nodiscard]] const std::vector<LoopEdge>& loops() const noexcept;
  [[nodiscard]] const std::vector<OdometryPose>& poses() const noexcept;
  [[nodiscard]] const std::vector<MemorySession>& sessions() const noexcept;
  [[nodiscard]] const MemoryOptions& options() const noexcept;
  [[nodiscard]] const AnyVocabulary& vocabulary() const noexcept;
  [[nodiscard]] const std::vector<std::vector<Detection>>& key_detections() const noexcept;
  [[nodiscard]] const std::array<std::string, 4>& policy_records() const noexcept;
  [[nodiscard]] std::size_t session_of(std::size_t key) const;
  [[nodiscard]] std::optional<std::size_t> last_frame_index() const noexcept;
  [[nodiscard]] bool stationary() const;
  [[nodiscard]] bool labelled() const noexcept;
  [[nodiscard]] bool has_gcs() const noexcept;
  [[nodiscard]] std::vector<std::uint32_t> gcs_keys() const;
  /// Key images checked for loops (those in the place database).
  [[nodiscard]] std::size_t checked_key_images() const noexcept;
  [[nodiscard]] bool holds_features(std::size_t key) const noexcept;
  [[nodiscard]] std::size_t working_memory() const noexcept;
  [[nodiscard]] Features key_features(std::uint32_t key) const;
  [[nodiscard]] std::vector<GraphNeighbour> neighbours(std::uint32_t key) const;
  /// The memory's records, whole (memory/records.hpp).
  [[nodiscard]] MemoryRecords records() const;

 private:
  AnyMemory();

  void writable(const char* what) const;
  /// A fleet's robot: looks for the key images checked and committed since the last call
  /// among the other robots' (`all`: after waiting for the sync in flight), keeping the
  /// loops found for push().
  void link_fleet(bool all = false);

  [[nodiscard]] std::string where() const { return path_.empty() ? std::string() : " '" + path_.string() + "'"; }

  /// Declared before impl_: the new store is closed before an unfinished replacement
  /// removes it.
  std::unique_ptr<MemoryReplacement> replacement_;
  std::unique_ptr<detail::MemoryConcept> impl_;  ///< never null but after a move
  PolicyStack stack_;
  std::filesystem::path path_;
  std::string location_;  ///< a server's URI as given (with its password, if any): never shown
  std::string robot_;
  /// A fleet's robot that writes: its key images are looked for among the other robots'
  /// (memory/fleet.hpp) once their sync is committed; those before fleet_linked_ were.
  std::unique_ptr<FleetIndex> fleet_;
  std::size_t fleet_linked_ = 0;
  /// The loops to other robots found by the syncs since the last push() returned.
  std::vector<FleetLoop> fleet_found_;
  MemoryKind kind_ = MemoryKind::other;
  bool writes_ = false;
  bool closed_ = false;
  SyncPolicy sync_{};
  std::size_t unsynced_ = 0;  ///< frames pushed since the last sync
  std::size_t syncs_ = 0;
  double sync_seconds_ = 0.0;
};


}  // namespace vmap

#ifndef VMAP_COMPILED_STACKS
#include <vmap/runtime/detail/memory_impl.hpp>
#endif
