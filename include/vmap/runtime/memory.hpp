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
// Threading: as VisualMemory (memory/visual_memory.hpp): one thread at a time calls
// push(), localize() and the other members; separate AnyMemory objects share nothing.

#include <vmap/core/error.hpp>
#include <vmap/hooks/detection.hpp>
#include <vmap/io/files.hpp>
#include <vmap/io/frame.hpp>
#include <vmap/keyframe/map_io.hpp>
#include <vmap/memory/records.hpp>
#include <vmap/memory/replace.hpp>
#include <vmap/memory/store.hpp>
#include <vmap/memory/visual_memory.hpp>
#include <vmap/memory/vmem.hpp>
#include <vmap/runtime/policies.hpp>
#include <vmap/runtime/stack.hpp>

#include <opencv2/core.hpp>

#include <chrono>
#include <cstddef>
#include <cstdint>
#include <filesystem>
#include <memory>
#include <optional>
#include <string>
#include <string_view>
#include <typeinfo>
#include <utility>
#include <vector>

namespace vmap {

/// The memory type of a policy stack (eq. 5's inlier ratio as the similarity).
template <class D, class M, class E>
using MemoryOf = VisualMemory<D, M, E, InlierRatio>;

/// The file name a folder given as a memory holds.
inline constexpr const char* memory_file_name = "memory.vmdb";

/// A memory path as a user gives it: an existing folder, or a path ending in '/', means
/// the folder's memory.vmdb; anything else is the memory file itself.
[[nodiscard]] inline std::filesystem::path memory_path(std::string_view given) {
  std::error_code ec;
  const std::filesystem::path p(given);
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
  std::size_t working_memory = 0;  ///< as MemoryOpenOptions::working_memory
  SyncPolicy sync{};
  /// Replace an existing memory at the path (a store or a .vmem file; any other file is
  /// refused): the new store is built under another name and renamed over it by close(),
  /// holding the old one's writer lock meanwhile (refused while another program writes
  /// it). false: an existing file is refused. A path with no file gets a new store there
  /// either way, written in place so that readers can follow it.
  bool replace = false;
  /// A new store where no file is appears there only when closed, whole: it is built under
  /// another name as a replacement is (a killed run leaves no partial memory there; a file
  /// another program made there meanwhile is not replaced). false: written in place.
  bool whole_at_close = false;
};

namespace detail {

/// The interface every held memory answers (AnyMemory's type erasure).
class MemoryConcept {
 public:
  MemoryConcept() = default;
  MemoryConcept(const MemoryConcept&) = delete;
  MemoryConcept& operator=(const MemoryConcept&) = delete;
  virtual ~MemoryConcept() = default;

  virtual MemoryStep push(const Frame& frame, const OdometryPose& pose, const std::vector<Detection>* detections) = 0;
  virtual MemoryLocalization localize(const cv::Mat& image, const PlaceDecisionOptions* decision) = 0;
  virtual void start_session() = 0;
  virtual GcsTrainStats train_gcs(const MemoryGcsOptions& options) = 0;
  virtual void merge(MemoryConcept& other, const std::string& name, const std::string& other_name) = 0;
  virtual void sync() = 0;
  virtual void bound(std::size_t working_memory) = 0;
  [[nodiscard]] virtual MemoryStore* store() noexcept = 0;
  virtual void drop_store() = 0;
  virtual void attach(MemoryStore store) = 0;
  [[nodiscard]] virtual std::string serialize(std::optional<ImageStorage> images) const = 0;
  [[nodiscard]] virtual MemoryRecords records() const = 0;
  [[nodiscard]] virtual const std::type_info& memory_type() const noexcept = 0;

  [[nodiscard]] virtual const VisualMap& map() const noexcept = 0;
  [[nodiscard]] virtual const std::vector<LoopEdge>& loops() const noexcept = 0;
  [[nodiscard]] virtual const std::vector<OdometryPose>& poses() const noexcept = 0;
  [[nodiscard]] virtual const std::vector<MemorySession>& sessions() const noexcept = 0;
  [[nodiscard]] virtual const MemoryOptions& options() const noexcept = 0;
  [[nodiscard]] virtual const AnyVocabulary& vocabulary() const noexcept = 0;
  [[nodiscard]] virtual const std::vector<std::vector<Detection>>& key_detections() const noexcept = 0;
  [[nodiscard]] virtual const std::array<std::string, 4>& policy_records() const noexcept = 0;
  [[nodiscard]] virtual std::size_t session_of(std::size_t key) const = 0;
  [[nodiscard]] virtual std::optional<std::size_t> last_frame_index() const noexcept = 0;
  [[nodiscard]] virtual bool stationary() const = 0;
  [[nodiscard]] virtual bool labelled() const noexcept = 0;
  [[nodiscard]] virtual bool has_gcs() const noexcept = 0;
  [[nodiscard]] virtual std::vector<std::uint32_t> gcs_keys() const = 0;
  [[nodiscard]] virtual std::size_t checked_key_images() const noexcept = 0;
  [[nodiscard]] virtual bool holds_features(std::size_t key) const noexcept = 0;
  [[nodiscard]] virtual std::size_t working_memory() const noexcept = 0;
  [[nodiscard]] virtual Features key_features(std::uint32_t key) const = 0;
  [[nodiscard]] virtual std::vector<GraphNeighbour> neighbours(std::uint32_t key) const = 0;
};

template <class Memory>
class MemoryModel final : public MemoryConcept {
 public:
  MemoryModel(Memory memory, std::optional<MemoryStore> store) : memory_(std::move(memory)), store_(std::move(store)) {}

  MemoryStep push(const Frame& frame, const OdometryPose& pose, const std::vector<Detection>* detections) override {
    return detections ? memory_.push(frame, pose, *detections) : memory_.push(frame, pose);
  }
  MemoryLocalization localize(const cv::Mat& image, const PlaceDecisionOptions* decision) override {
    return memory_.localize(image, decision);
  }
  void start_session() override { memory_.start_session(); }
  GcsTrainStats train_gcs(const MemoryGcsOptions& options) override { return memory_.train_gcs(options); }
  void merge(MemoryConcept& other, const std::string& name, const std::string& other_name) override {
    auto* same = dynamic_cast<MemoryModel*>(&other);
    if (!same) fail(ErrorKind::policy_mismatch, "cannot merge " + other_name + " into " + name + ": they were made with other policies");
    memory_.merge(std::move(same->memory_), name, other_name);
  }
  void sync() override {
    if (store_) store_->sync(memory_);
  }
  void bound(std::size_t working_memory) override {
    if (store_ && working_memory > 0) store_->bound(memory_, working_memory);
  }
  MemoryStore* store() noexcept override { return store_ ? &*store_ : nullptr; }
  void drop_store() override { store_.reset(); }
  void attach(MemoryStore store) override { store_.emplace(std::move(store)); }
  std::string serialize(std::optional<ImageStorage> images) const override { return memory_.serialize(images); }
  MemoryRecords records() const override { return memory_.records(); }
  const std::type_info& memory_type() const noexcept override { return typeid(Memory); }

  const VisualMap& map() const noexcept override { return memory_.map(); }
  const std::vector<LoopEdge>& loops() const noexcept override { return memory_.loops(); }
  const std::vector<OdometryPose>& poses() const noexcept override { return memory_.poses(); }
  const std::vector<MemorySession>& sessions() const noexcept override { return memory_.sessions(); }
  const MemoryOptions& options() const noexcept override { return memory_.options(); }
  const AnyVocabulary& vocabulary() const noexcept override { return memory_.vocabulary(); }
  const std::vector<std::vector<Detection>>& key_detections() const noexcept override { return memory_.key_detections(); }
  const std::array<std::string, 4>& policy_records() const noexcept override { return memory_.policy_records(); }
  std::size_t session_of(std::size_t key) const override { return memory_.session_of(key); }
  std::optional<std::size_t> last_frame_index() const noexcept override { return memory_.last_frame_index(); }
  bool stationary() const override { return memory_.stationary(); }
  bool labelled() const noexcept override { return memory_.labelled(); }
  bool has_gcs() const noexcept override { return memory_.has_gcs(); }
  std::vector<std::uint32_t> gcs_keys() const override { return memory_.gcs_keys(); }
  std::size_t checked_key_images() const noexcept override { return memory_.database().size(); }
  bool holds_features(std::size_t key) const noexcept override { return memory_.holds_features(key); }
  std::size_t working_memory() const noexcept override { return memory_.working_memory(); }
  Features key_features(std::uint32_t key) const override { return memory_.key_features(key); }
  std::vector<GraphNeighbour> neighbours(std::uint32_t key) const override { return memory_.neighbours(key); }

 private:
  Memory memory_;
  std::optional<MemoryStore> store_;
};

/// The memories of one descriptor type D, with the stack's matcher and estimator for a
/// memory (runtime/policies.hpp). Defined apart from the class so that a program linking
/// vmap::stacks, which compiles them once for the shipped descriptors, instantiates
/// nothing of a VisualMemory itself (see the end of this file).
template <class D>
struct MemoryFactory {
  /// A new memory in RAM.
  static std::unique_ptr<MemoryConcept> create(D descriptor, const PolicyStack& stack, const MemoryOptions& options,
                                               AnyVocabulary vocabulary, const std::string& camera_name);
  /// The memory of `records`, synced into `store` when given.
  static std::unique_ptr<MemoryConcept> load(D descriptor, const PolicyStack& stack, MemoryRecords records,
                                             const std::string& who, bool pixels_unread,
                                             std::optional<MemoryStore> store, const std::string& camera_name);
};

template <class D>
std::unique_ptr<MemoryConcept> MemoryFactory<D>::create(D descriptor, const PolicyStack& stack,
                                                        const MemoryOptions& options, AnyVocabulary vocabulary,
                                                        const std::string& camera_name) {
  auto matcher = matcher_for(descriptor);
  auto estimator = estimator_for<D>(stack, StackUse::memory, camera_name);
  using Memory = MemoryOf<D, decltype(matcher), decltype(estimator)>;
  return std::make_unique<MemoryModel<Memory>>(
      Memory(std::move(descriptor), std::move(matcher), std::move(estimator), InlierRatio{}, options,
             std::move(vocabulary)),
      std::nullopt);
}

template <class D>
std::unique_ptr<MemoryConcept> MemoryFactory<D>::load(D descriptor, const PolicyStack& stack, MemoryRecords records,
                                                      const std::string& who, bool pixels_unread,
                                                      std::optional<MemoryStore> store,
                                                      const std::string& camera_name) {
  auto matcher = matcher_for(descriptor);
  auto estimator = estimator_for<D>(stack, StackUse::memory, camera_name);
  using Memory = MemoryOf<D, decltype(matcher), decltype(estimator)>;
  return std::make_unique<MemoryModel<Memory>>(
      Memory::from_records(std::move(records), who, std::move(descriptor), std::move(matcher), std::move(estimator),
                           InlierRatio{}, pixels_unread),
      std::move(store));
}

/// The stack of a memory whose policies recorded `records`; a memory whose descriptor
/// recorded nothing (a format-1 file, a memory of policies that do not describe
/// themselves) is taken as the default stack, and loading it then checks what it holds.
[[nodiscard]] inline PolicyStack stack_of_records(const std::array<std::string, 4>& records, const std::string& who) {
  if (records[0].empty() && records[2].empty()) return PolicyStack{};
  return stack_of_policies(records, who);
}

}  // namespace detail

/// One visual memory of a shipped stack (see the top of this file). Move-only.
class AnyMemory {
 public:
  /// Opens the memory at `path` (a memory store or a .vmem file; see memory_path for a
  /// folder), with the stack its policies recorded. A .vmem file is read whole and cannot
  /// be written (convert it into a store). An Error names the file and what is wrong: it
  /// does not exist or is not a memory, another program writes it (write), it is
  /// damaged, or its policies are not one of the shipped stacks.
  [[nodiscard]] static AnyMemory open(const std::filesystem::path& path, const MemoryOpenOptions& options = {}) {
    check_input(path);
    MapLoadOptions limits;
    // A memory pushed into writes pixels again (I_{j-1}'s, when it keeps them).
    limits.decode_images = options.pixels || options.write;
    bool skipped = false;
    AnyMemory out;
    out.path_ = path;
    out.sync_ = options.sync;
    if (memory_kind(path) == MemoryKind::file) {
      // Read whole; pushed into (write) in RAM, kept by save().
      const std::string bytes = read_file(path, limits.max_file_bytes, "memory file");
      MemoryRecords records = detail::read_vmem(bytes, path.string(), limits, &skipped);
      out.stack_ = detail::stack_of_records(records.policies, "memory file '" + path.string() + "'");
      out.kind_ = MemoryKind::file;
      out.writes_ = options.write;
      out.impl_ = build(out.stack_, std::move(records), "memory file '" + path.string() + "'", skipped, std::nullopt);
      return out;
    }
    MemoryStore store = MemoryStore::open(path, options.write ? sqlite::Access::write : sqlite::Access::read);
    const std::string who = "memory '" + path.string() + "'";
    if (!store.synced())
      detail::fail(who + " holds nothing yet (its first run stopped before its first key image was written)");
    out.stack_ = stack_of_store(store, who);
    out.kind_ = MemoryKind::store;
    out.writes_ = options.write;
    const std::size_t bound = options.write ? options.working_memory : 0;
    MemoryRecords records = store.records(bound, limits, &skipped);
    out.impl_ = build(out.stack_, std::move(records), who, skipped, std::move(store));
    out.impl_->bound(bound);
    if (options.new_session) out.start_session();
    return out;
  }

  /// A new memory store at `path` (its folder made when missing) of `stack`, with these
  /// options and vocabulary (empty: learned from the first key images). An existing file
  /// is refused, or with `how.replace` replaced by close() when it is a memory. The
  /// stack's camera source is kept as the store's note "camera source".
  [[nodiscard]] static AnyMemory create(const std::filesystem::path& path, const PolicyStack& given,
                                        const MemoryOptions& options = {}, AnyVocabulary vocabulary = {},
                                        const MemoryCreateOptions& how = {}) {
    const PolicyStack stack = recordable(given);
    AnyMemory out;
    out.stack_ = stack;
    if (path.has_parent_path()) {
      std::error_code ec;
      std::filesystem::create_directories(path.parent_path(), ec);
      if (ec) detail::fail("memory '" + path.string() + "': cannot create its folder: " + ec.message());
    }
    out.replacement_ = replacement_of(path, how);
    out.impl_ = new_memory(stack, options, std::move(vocabulary));
    MemoryStore store = new_store(path, out.replacement_.get());
    if (stack.camera && !stack.camera_source.empty()) store.set_note(camera_source_note, stack.camera_source);
    out.impl_->attach(std::move(store));
    out.path_ = path;
    out.kind_ = MemoryKind::store;
    out.writes_ = true;
    out.sync_ = how.sync;
    out.impl_->bound(how.working_memory);
    return out;
  }

  /// A memory in RAM (not kept anywhere until saved) of `stack`.
  [[nodiscard]] static AnyMemory in_ram(const PolicyStack& given, const MemoryOptions& options = {},
                                        AnyVocabulary vocabulary = {}) {
    const PolicyStack stack = recordable(given);
    AnyMemory out;
    out.stack_ = stack;
    out.kind_ = MemoryKind::other;
    out.writes_ = true;
    out.impl_ = new_memory(stack, options, std::move(vocabulary));
    return out;
  }

  /// A memory store at `path` holding `source`'s memory (its records written whole into
  /// a new store): a .vmem file made a store, a store copied. An existing file is refused,
  /// or with `how.replace` replaced by close() when it is a memory (`how`'s other fields
  /// are not used). The memory must have been opened with its pixels when it keeps them.
  [[nodiscard]] static AnyMemory copy_into_store(AnyMemory&& source, const std::filesystem::path& path,
                                                 const MemoryCreateOptions& how = {}) {
    AnyMemory out = std::move(source);
    if (auto* s = out.impl_->store()) s->flush();
    out.replacement_ = replacement_of(path, how);
    MemoryStore store = new_store(path, out.replacement_.get());
    if (out.stack_.camera && !out.stack_.camera_source.empty()) store.set_note(camera_source_note, out.stack_.camera_source);
    // The memory's records, written whole by the first sync into the new store (a memory
    // bounded by its old store reads its released features through that store's own
    // reader, which stays open).
    out.impl_->attach(std::move(store));
    out.path_ = path;
    out.kind_ = MemoryKind::store;
    out.writes_ = true;
    out.impl_->sync();
    out.flush();
    return out;
  }

  AnyMemory(AnyMemory&&) noexcept = default;
  AnyMemory& operator=(AnyMemory&&) noexcept = default;
  AnyMemory(const AnyMemory&) = delete;
  AnyMemory& operator=(const AnyMemory&) = delete;
  /// Waits for a sync in flight (a failure of it is dropped: close() or flush() first).
  /// A memory replacing another (MemoryCreateOptions::replace) that was not closed is
  /// discarded: the memory it was to replace stays.
  ~AnyMemory() = default;

  // ---- what it is ---------------------------------------------------------------------

  [[nodiscard]] const PolicyStack& stack() const noexcept { return stack_; }
  /// The file it was opened from or created at; empty for a memory in RAM.
  [[nodiscard]] const std::filesystem::path& path() const noexcept { return path_; }
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
  [[nodiscard]] MemoryStore* store() noexcept { return closed_ ? nullptr : impl_->store(); }

  // ---- changing it -------------------------------------------------------------------

  /// Pushes a frame (with its odometry pose and, for a memory with object labels, its
  /// detections): VisualMemory::push. A memory store is synced as the SyncPolicy says;
  /// the sync's commit runs in the store's writer thread.
  MemoryStep push(const Frame& frame, const OdometryPose& pose = detail::no_odometry_pose,
                  const std::vector<Detection>* detections = nullptr) {
    writable("push");
    MemoryStep step = impl_->push(frame, pose, detections);
    ++unsynced_;
    if (impl_->store() && (step.new_key || !step.loops.empty() || (sync_.every > 0 && unsynced_ >= sync_.every))) sync();
    return step;
  }

  /// Starts a session (VisualMemory::start_session), synced at once into a store.
  void start_session() {
    writable("start_session");
    impl_->start_session();
    if (impl_->store()) sync();
  }

  /// Trains the GCS localizer (VisualMemory::train_gcs), synced at once into a store.
  GcsTrainStats train_gcs(const MemoryGcsOptions& options = {}) {
    writable("train_gcs");
    GcsTrainStats s = impl_->train_gcs(options);
    if (impl_->store()) sync();
    return s;
  }

  /// Appends `other`'s sessions (VisualMemory::merge): both must be of one stack (the
  /// camera by its parameters) and options; `other` must hold all its features and be
  /// opened with its pixels when it keeps them. `name` and `other_name` name them in errors.
  void merge(AnyMemory&& other, const std::string& name, const std::string& other_name) {
    writable("merge");
    if (!(other.stack_ == stack_))
      detail::fail(ErrorKind::policy_mismatch, "cannot merge " + other_name + " (" + summary(other.stack_) + ") into " + name + " (" + summary(stack_) +
                   "): they were built with different policies");
    impl_->merge(*other.impl_, name, other_name);
    other.closed_ = true;
    if (impl_->store()) sync();
  }

  /// Hands what the memory made since the last sync to its store (a no-op without one);
  /// the commit runs in the store's writer thread (flush() waits for it).
  void sync() {
    if (closed_ || !impl_->store() || !writes_) return;
    const auto t0 = std::chrono::steady_clock::now();
    impl_->sync();
    sync_seconds_ += std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
    ++syncs_;
    unsynced_ = 0;
  }

  /// sync() when frames were pushed since the last one.
  void sync_pending() {
    if (unsynced_ > 0) sync();
  }

  /// Syncs handed to the store so far, and the time the calling thread spent in them
  /// (encoding the rows, waiting for the previous commit).
  [[nodiscard]] std::size_t syncs() const noexcept { return syncs_; }
  [[nodiscard]] double sync_seconds() const noexcept { return sync_seconds_; }

  /// Waits until every sync is committed, throwing a failed one's error.
  void flush() {
    if (auto* s = store()) s->flush();
  }

  /// Syncs, commits and closes the store (its write-ahead log moved into the file); the
  /// memory can still be read, not changed. A store replacing another memory is renamed
  /// over it here (an Error leaves the old one). A no-op for a memory without a store.
  void close() {
    if (closed_) return;
    if (auto* s = impl_->store(); s && writes_) {
      sync();
      s->checkpoint();
    }
    impl_->drop_store();
    closed_ = true;
    if (replacement_) {
      const std::unique_ptr<MemoryReplacement> r = std::move(replacement_);
      r->commit();
    }
  }

  /// Ends a memory that replaces another without replacing it, for a run that failed:
  /// what it wrote is removed and the memory it was to replace stays; it is closed (read
  /// only). A no-op for any other memory (close() keeps what it wrote).
  void abandon() {
    if (!replacement_) return;
    impl_->drop_store();
    closed_ = true;
    replacement_.reset();
  }

  /// Writes the memory as a .vmem file, atomically (VisualMemory::save).
  void save(const std::filesystem::path& file, std::optional<ImageStorage> images = {}) const {
    write_file_atomically(file, impl_->serialize(images));
  }

  // ---- reading it --------------------------------------------------------------------

  [[nodiscard]] MemoryLocalization localize(const cv::Mat& image, const PlaceDecisionOptions* decision = nullptr) {
    return impl_->localize(image, decision);
  }
  [[nodiscard]] const VisualMap& map() const noexcept { return impl_->map(); }
  [[nodiscard]] std::size_t frames() const noexcept { return impl_->map().frames; }
  [[nodiscard]] std::size_t key_images() const noexcept { return impl_->map().keys.size(); }
  [[nodiscard]] const std::vector<LoopEdge>& loops() const noexcept { return impl_->loops(); }
  [[nodiscard]] const std::vector<OdometryPose>& poses() const noexcept { return impl_->poses(); }
  [[nodiscard]] const std::vector<MemorySession>& sessions() const noexcept { return impl_->sessions(); }
  [[nodiscard]] const MemoryOptions& options() const noexcept { return impl_->options(); }
  [[nodiscard]] const AnyVocabulary& vocabulary() const noexcept { return impl_->vocabulary(); }
  [[nodiscard]] const std::vector<std::vector<Detection>>& key_detections() const noexcept {
    return impl_->key_detections();
  }
  [[nodiscard]] const std::array<std::string, 4>& policy_records() const noexcept { return impl_->policy_records(); }
  [[nodiscard]] std::size_t session_of(std::size_t key) const { return impl_->session_of(key); }
  [[nodiscard]] std::optional<std::size_t> last_frame_index() const noexcept { return impl_->last_frame_index(); }
  [[nodiscard]] bool stationary() const { return impl_->stationary(); }
  [[nodiscard]] bool labelled() const noexcept { return impl_->labelled(); }
  [[nodiscard]] bool has_gcs() const noexcept { return impl_->has_gcs(); }
  [[nodiscard]] std::vector<std::uint32_t> gcs_keys() const { return impl_->gcs_keys(); }
  /// Key images checked for loops (those in the place database).
  [[nodiscard]] std::size_t checked_key_images() const noexcept { return impl_->checked_key_images(); }
  [[nodiscard]] bool holds_features(std::size_t key) const noexcept { return impl_->holds_features(key); }
  [[nodiscard]] std::size_t working_memory() const noexcept { return impl_->working_memory(); }
  [[nodiscard]] Features key_features(std::uint32_t key) const { return impl_->key_features(key); }
  [[nodiscard]] std::vector<GraphNeighbour> neighbours(std::uint32_t key) const { return impl_->neighbours(key); }
  /// The memory's records, whole (memory/records.hpp).
  [[nodiscard]] MemoryRecords records() const { return impl_->records(); }

 private:
  AnyMemory() = default;

  /// The store note that keeps where a stack's calibration came from (for messages).
  static constexpr const char* camera_source_note = "camera source";

  /// The replacement of the memory at `path` when `how` asks for one (a file there and
  /// `replace`, or none there and `whole_at_close`); null for a store made in place (or
  /// refused there when a file is).
  static std::unique_ptr<MemoryReplacement> replacement_of(const std::filesystem::path& path,
                                                           const MemoryCreateOptions& how) {
    std::error_code ec;
    const bool exists = std::filesystem::exists(std::filesystem::symlink_status(path, ec));
    if (!(exists ? how.replace : how.whole_at_close)) return nullptr;
    return std::make_unique<MemoryReplacement>(path, !exists);
  }

  /// A new store at `path`, or beside it when it replaces the memory there (named as
  /// that memory in messages).
  static MemoryStore new_store(const std::filesystem::path& path, const MemoryReplacement* replacement) {
    if (!replacement) return MemoryStore::create(path);
    return MemoryStore::create(replacement->path(), "memory '" + path.string() + "'");
  }

  static void check_input(const std::filesystem::path& path) {
    std::error_code ec;
    if (!std::filesystem::exists(path, ec)) detail::fail(ErrorKind::not_found, "memory '" + path.string() + "' does not exist");
    if (!std::filesystem::is_regular_file(path, ec))
      detail::fail("memory '" + path.string() + "' is not a regular file (a folder, a device or a FIFO)");
    if (memory_kind(path) == MemoryKind::other)
      detail::fail(ErrorKind::corrupt, "'" + path.string() + "' is not a vmap memory (neither a memory store nor a .vmem memory file)");
  }

  /// `s` checked, its model files named by absolute paths: the memory records the stack,
  /// and a reader in another folder must find them.
  static PolicyStack recordable(PolicyStack s) {
    s.validate();
    for (std::string* path : {&s.model, &s.refine_model})
      if (!path->empty()) {
        std::error_code ec;
        const auto absolute = std::filesystem::weakly_canonical(*path, ec);
        if (!ec) *path = absolute.string();
      }
    return s;
  }

  static std::string camera_name(const PolicyStack& s) {
    return s.camera_source.empty() ? std::string("the memory's camera") : "the memory's camera (from " + s.camera_source + ")";
  }

  /// The stack a store's memory records: its policies' records, or for a store written
  /// before the XFeat policies described themselves the note "stack" the command line
  /// kept; the calibration's source from the notes.
  static PolicyStack stack_of_store(MemoryStore& store, const std::string& who) {
    const auto records = store.policy_records();
    PolicyStack s;
    const auto legacy = store.note("stack");
    if (records[0].empty() && legacy)
      s = stack_of_legacy_note(*legacy, who + ": its recorded stack");
    else
      s = detail::stack_of_records(records, who);
    if (auto source = store.note(camera_source_note)) {
      s.camera_source = *source;
    } else if (legacy && s.camera && s.camera_source.empty()) {
      try {
        s.camera_source = stack_of_legacy_note(*legacy, who).camera_source;
      } catch (const Error&) {
      }
    }
    return s;
  }

  static std::unique_ptr<detail::MemoryConcept> new_memory(const PolicyStack& stack, const MemoryOptions& options,
                                                           AnyVocabulary vocabulary) {
    return with_descriptor(stack, [&](auto d) {
      return detail::MemoryFactory<decltype(d)>::create(std::move(d), stack, options, std::move(vocabulary),
                                                        camera_name(stack));
    });
  }

  static std::unique_ptr<detail::MemoryConcept> build(const PolicyStack& stack, MemoryRecords records,
                                                      const std::string& who, bool pixels_unread,
                                                      std::optional<MemoryStore> store) {
    return with_descriptor(stack, [&](auto d) {
      return detail::MemoryFactory<decltype(d)>::load(std::move(d), stack, std::move(records), who, pixels_unread,
                                                      std::move(store), camera_name(stack));
    });
  }

  void writable(const char* what) const {
    if (closed_) detail::fail("memory" + where() + ": " + what + ": the memory was closed");
    if (!writes_)
      detail::fail("memory" + where() + ": " + what + ": the memory was opened read-only (open it with write = true)");
  }

  [[nodiscard]] std::string where() const { return path_.empty() ? std::string() : " '" + path_.string() + "'"; }

  /// Declared before impl_: the new store is closed before an unfinished replacement
  /// removes it.
  std::unique_ptr<MemoryReplacement> replacement_;
  std::unique_ptr<detail::MemoryConcept> impl_;
  PolicyStack stack_;
  std::filesystem::path path_;
  MemoryKind kind_ = MemoryKind::other;
  bool writes_ = false;
  bool closed_ = false;
  SyncPolicy sync_{};
  std::size_t unsynced_ = 0;  ///< frames pushed since the last sync
  std::size_t syncs_ = 0;
  double sync_seconds_ = 0.0;
};

}  // namespace vmap

// A program that links vmap::stacks (CMake) compiles the memories of the shipped
// descriptors once, there (runtime/detail/compiled_stacks.hpp): its other translation
// units instantiate none of them.
#ifdef VMAP_COMPILED_STACKS
namespace vmap::detail {
extern template struct MemoryFactory<OrbDescriptor>;
extern template struct MemoryFactory<AkazeDescriptor>;
extern template struct MemoryFactory<SiftDescriptor>;
extern template struct MemoryFactory<XFeatDescriptor>;
extern template struct MemoryFactory<XFeatDenseDescriptor>;
}  // namespace vmap::detail
#endif
