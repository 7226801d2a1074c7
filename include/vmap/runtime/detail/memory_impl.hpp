#pragma once

// AnyMemory's definitions (runtime/memory.hpp declares it). Not included by programs: a
// program includes runtime/memory.hpp, which includes this file unless the program links
// vmap::stacks, whose one translation unit of the run-time layer includes it instead
// (core/compiled.hpp).

#include <vmap/core/compiled.hpp>
#include <vmap/core/error.hpp>
#include <vmap/io/files.hpp>
#include <vmap/keyframe/map_io.hpp>
#include <vmap/memory/fleet.hpp>
#include <vmap/memory/records.hpp>
#include <vmap/memory/replace.hpp>
#include <vmap/memory/store.hpp>
#include <vmap/memory/vmem.hpp>
#include <vmap/runtime/detail/memory_model.hpp>
#include <vmap/runtime/memory.hpp>
#include <vmap/runtime/stack.hpp>

#include <chrono>
#include <filesystem>
#include <memory>
#include <optional>
#include <string>
#include <system_error>
#include <utility>

namespace vmap {

namespace detail {

/// The store note that keeps where a stack's calibration came from (for messages).
inline constexpr const char* camera_source_note = "camera source";

/// The replacement of the memory at `path` when `how` asks for one (a file there and
/// `replace`, or none there and `whole_at_close`); null for a store made in place (or
/// refused there when a file is).
VMAP_INLINE std::unique_ptr<MemoryReplacement> memory_replacement_of(const std::filesystem::path& path,
                                                                   const MemoryCreateOptions& how) {
  if (pg::is_uri(path.native())) {
    // A robot's memory on a server is written in place: its first sync is one transaction.
    if (how.replace)
      fail("robot '" + how.robot + "' of memory '" + pg::redacted(path.native()) +
           "': a fleet's robot is not replaced (name another robot)");
    return nullptr;
  }
  std::error_code ec;
  const bool exists = std::filesystem::exists(std::filesystem::symlink_status(path, ec));
  // A file that is not a memory is never one to replace, nor called a memory.
  if (exists && !how.replace && memory_kind(path) == MemoryKind::other)
    fail("'" + path.string() + "' exists and is not a vmap memory; refusing to replace it");
  if (!(exists ? how.replace : how.whole_at_close)) return nullptr;
  return std::make_unique<MemoryReplacement>(path, !exists);
}

/// A new store at `path`, or beside it when it replaces the memory there (named as
/// that memory in messages).
VMAP_INLINE MemoryStore new_memory_store(const std::filesystem::path& path, const MemoryReplacement* replacement,
                                         const std::string& robot) {
  if (!replacement) return MemoryStore::create(path, {}, robot);
  return MemoryStore::create(*replacement, "memory '" + path.string() + "'");
}

VMAP_INLINE void check_memory_input(const std::filesystem::path& path) {
  if (pg::is_uri(path.native())) return;  // the server says (MemoryStore::open)
  std::error_code ec;
  if (!std::filesystem::exists(path, ec)) fail(ErrorKind::not_found, "memory '" + path.string() + "' does not exist");
  if (!std::filesystem::is_regular_file(path, ec))
    fail("memory '" + path.string() + "' is not a regular file (a folder, a device or a FIFO)");
  if (memory_kind(path) == MemoryKind::other)
    fail(ErrorKind::corrupt, "'" + path.string() + "' is not a vmap memory (neither a memory store nor a .vmem memory file)");
}

/// `s` checked, its model files named by absolute paths: the memory records the stack,
/// and a reader in another folder must find them.
VMAP_INLINE PolicyStack recordable_stack(PolicyStack s) {
  s.validate();
  for (std::string* path : {&s.model, &s.refine_model})
    if (!path->empty()) {
      std::error_code ec;
      const auto absolute = std::filesystem::weakly_canonical(*path, ec);
      if (!ec) *path = absolute.string();
    }
  return s;
}

VMAP_INLINE std::string memory_camera_name(const PolicyStack& s) {
  return s.camera_source.empty() ? std::string("the memory's camera") : "the memory's camera (from " + s.camera_source + ")";
}

/// The stack a store's memory records: its policies' records, or for a store written
/// before the XFeat policies described themselves the note "stack" the command line
/// kept; the calibration's source from the notes.
VMAP_INLINE PolicyStack stack_of_store(MemoryStore& store, const std::string& who) {
  const auto records = store.policy_records();
  PolicyStack s;
  const auto legacy = store.note("stack");
  if (records[0].empty() && legacy)
    s = stack_of_legacy_note(*legacy, who + ": its recorded stack");
  else
    s = stack_of_records(records, who);
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

VMAP_INLINE std::unique_ptr<MemoryConcept> new_any_memory(const PolicyStack& stack, const MemoryOptions& options,
                                                      AnyVocabulary vocabulary) {
  return with_descriptor(stack, [&](auto d) {
    return MemoryFactory<decltype(d)>::create(std::move(d), stack, options, std::move(vocabulary),
                                                      memory_camera_name(stack));
  });
}

VMAP_INLINE std::unique_ptr<MemoryConcept> load_any_memory(const PolicyStack& stack, MemoryRecords records,
                                                       const std::string& who, bool pixels_unread,
                                                       std::optional<MemoryStore> store) {
  return with_descriptor(stack, [&](auto d) {
    return MemoryFactory<decltype(d)>::load(std::move(d), stack, std::move(records), who, pixels_unread,
                                                    std::move(store), memory_camera_name(stack));
  });
}

}  // namespace detail

VMAP_INLINE AnyMemory::AnyMemory() = default;
VMAP_INLINE AnyMemory::AnyMemory(AnyMemory&&) noexcept = default;
VMAP_INLINE AnyMemory& AnyMemory::operator=(AnyMemory&&) noexcept = default;
VMAP_INLINE AnyMemory::~AnyMemory() = default;

VMAP_INLINE AnyMemory AnyMemory::open(const std::filesystem::path& path, const MemoryOpenOptions& options) {
  detail::check_memory_input(path);
  MapLoadOptions limits;
  // A memory pushed into writes pixels again (I_{j-1}'s, when it keeps them).
  limits.decode_images = options.pixels || options.write;
  bool skipped = false;
  AnyMemory out;
  out.path_ = path;
  out.sync_ = options.sync;
  const bool server = pg::is_uri(path.native());
  if (!server && memory_kind(path) == MemoryKind::file) {
    // Read whole; pushed into (write) in RAM, kept by save().
    const std::string bytes = read_file(path, limits.max_file_bytes, "memory file");
    MemoryRecords records = detail::read_vmem(bytes, path.string(), limits, &skipped);
    out.stack_ = detail::stack_of_records(records.policies, "memory file '" + path.string() + "'");
    out.kind_ = MemoryKind::file;
    out.writes_ = options.write;
    out.impl_ = detail::load_any_memory(out.stack_, std::move(records), "memory file '" + path.string() + "'", skipped,
                                        std::nullopt);
    return out;
  }
  MemoryStore store =
      MemoryStore::open(path, options.write ? sqlite::Access::write : sqlite::Access::read, server ? options.robot : "");
  if (server) {
    out.location_ = path.native();
    out.path_ = store.path();
    out.robot_ = options.robot;
  }
  const std::string who = out.name();
  if (!store.synced())
    detail::fail(who + " holds nothing yet (its first run stopped before its first key image was written)");
  out.stack_ = detail::stack_of_store(store, who);
  out.kind_ = MemoryKind::store;
  out.writes_ = options.write;
  const std::size_t bound = options.write ? options.working_memory : 0;
  MemoryRecords records = store.records(bound, limits, &skipped);
  out.impl_ = detail::load_any_memory(out.stack_, std::move(records), who, skipped, std::move(store));
  out.impl_->bound(bound);
  if (server && options.write) {
    out.fleet_ = std::make_unique<FleetIndex>(out.location_, out.robot_);
    out.fleet_linked_ = std::min(out.fleet_->linked(), out.impl_->checked_key_images());
  }
  if (options.new_session) out.start_session();
  return out;
}

VMAP_INLINE AnyMemory AnyMemory::create(const std::filesystem::path& path, const PolicyStack& given,
                                         const MemoryOptions& options, const MemoryCreateOptions& how) {
  return create(path, given, options, AnyVocabulary{}, how);
}

VMAP_INLINE AnyMemory AnyMemory::create(const std::filesystem::path& path, const PolicyStack& given,
                                         const MemoryOptions& options, AnyVocabulary vocabulary,
                                         const MemoryCreateOptions& how) {
  const PolicyStack stack = detail::recordable_stack(given);
  AnyMemory out;
  out.stack_ = stack;
  const bool server = pg::is_uri(path.native());
  if (!server && path.has_parent_path()) {
    std::error_code ec;
    std::filesystem::create_directories(path.parent_path(), ec);
    if (ec) detail::fail(ErrorKind::io, "memory '" + path.string() + "': cannot create its folder: " + ec.message());
  }
  out.replacement_ = detail::memory_replacement_of(path, how);
  out.impl_ = detail::new_any_memory(stack, options, std::move(vocabulary));
  MemoryStore store = detail::new_memory_store(path, out.replacement_.get(), server ? how.robot : "");
  if (stack.camera && !stack.camera_source.empty()) store.set_note(detail::camera_source_note, stack.camera_source);
  out.path_ = server ? store.path() : path;
  if (server) {
    out.location_ = path.native();
    out.robot_ = how.robot;
  }
  out.impl_->attach(std::move(store));
  if (server) out.fleet_ = std::make_unique<FleetIndex>(out.location_, out.robot_);
  out.kind_ = MemoryKind::store;
  out.writes_ = true;
  out.sync_ = how.sync;
  out.impl_->bound(how.working_memory);
  return out;
}

VMAP_INLINE AnyMemory AnyMemory::in_ram(const PolicyStack& given, const MemoryOptions& options) {
  return in_ram(given, options, AnyVocabulary{});
}

VMAP_INLINE AnyMemory AnyMemory::in_ram(const PolicyStack& given, const MemoryOptions& options,
                                         AnyVocabulary vocabulary) {
  const PolicyStack stack = detail::recordable_stack(given);
  AnyMemory out;
  out.stack_ = stack;
  out.kind_ = MemoryKind::other;
  out.writes_ = true;
  out.impl_ = detail::new_any_memory(stack, options, std::move(vocabulary));
  return out;
}

VMAP_INLINE AnyMemory AnyMemory::copy_into_store(AnyMemory&& source, const std::filesystem::path& path,
                                                  const MemoryCreateOptions& how) {
  AnyMemory out = std::move(source);
  if (auto* s = out.impl_->store()) s->flush();
  out.replacement_ = detail::memory_replacement_of(path, how);
  const bool server = pg::is_uri(path.native());
  MemoryStore store = detail::new_memory_store(path, out.replacement_.get(), server ? how.robot : "");
  if (out.stack_.camera && !out.stack_.camera_source.empty())
    store.set_note(detail::camera_source_note, out.stack_.camera_source);
  out.path_ = server ? store.path() : path;
  out.location_ = server ? path.native() : std::string();
  out.robot_ = server ? how.robot : std::string();
  // The memory's records, written whole by the first sync into the new store (a memory
  // bounded by its old store reads its released features through that store's own
  // reader, which stays open).
  out.impl_->attach(std::move(store));
  out.kind_ = MemoryKind::store;
  out.writes_ = true;
  if (server) out.fleet_ = std::make_unique<FleetIndex>(out.location_, out.robot_);
  out.sync();
  out.flush();
  return out;
}

VMAP_INLINE MemoryStep AnyMemory::push(const Frame& frame, const OdometryPose& pose,
                                       const std::vector<Detection>* detections) {
  writable("push");
  MemoryStep step = impl_->push(frame, pose, detections);
  ++unsynced_;
  if (impl_->store() && (step.new_key || !step.loops.empty() || (sync_.every > 0 && unsynced_ >= sync_.every))) sync();
  step.fleet_loops = std::move(fleet_found_);
  fleet_found_.clear();
  return step;
}

VMAP_INLINE std::string AnyMemory::name() const {
  if (!robot_.empty()) return "robot '" + robot_ + "' of memory '" + path_.string() + "'";
  return "memory '" + path_.string() + "'";
}

VMAP_INLINE MemoryStore* AnyMemory::store() noexcept { return closed_ ? nullptr : impl_->store(); }

VMAP_INLINE void AnyMemory::start_session() {
  writable("start_session");
  impl_->start_session();
  if (impl_->store()) sync();
}

VMAP_INLINE GcsTrainStats AnyMemory::train_gcs(const MemoryGcsOptions& options) {
  writable("train_gcs");
  GcsTrainStats s = impl_->train_gcs(options);
  if (impl_->store()) sync();
  return s;
}

VMAP_INLINE void AnyMemory::merge(AnyMemory&& other, const std::string& name, const std::string& other_name) {
  writable("merge");
  if (!(other.stack_ == stack_))
    detail::fail(ErrorKind::policy_mismatch, "cannot merge " + other_name + " (" + summary(other.stack_) + ") into " + name + " (" + summary(stack_) +
                 "): they were built with different policies");
  impl_->merge(*other.impl_, name, other_name);
  other.closed_ = true;
  if (impl_->store()) sync();
}

VMAP_INLINE void AnyMemory::sync() {
  if (closed_ || !impl_->store() || !writes_) return;
  const auto t0 = std::chrono::steady_clock::now();
  impl_->sync();
  sync_seconds_ += std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
  ++syncs_;
  unsynced_ = 0;
  link_fleet();
}

VMAP_INLINE void AnyMemory::link_fleet(bool all) {
  if (!fleet_ || !impl_->store()) return;
  // The other robots see this robot's bags of words once committed; its own query after
  // that commit makes every pair of key images of two robots meet at least once. The
  // key images the sync in flight holds wait for the next call (the commit runs on
  // meanwhile), or for close().
  MemoryStore& store = *impl_->store();
  if (all) store.flush();
  const std::size_t committed = std::min(store.committed_bags(), impl_->checked_key_images());
  if (committed <= fleet_linked_) return;
  std::vector<FleetLoop> found = impl_->link_fleet(*fleet_, fleet_linked_, committed, store.vocabulary_crc());
  fleet_linked_ = committed;
  fleet_->set_linked(fleet_linked_);
  for (auto& l : found) fleet_found_.push_back(std::move(l));
}

VMAP_INLINE void AnyMemory::flush() {
  if (auto* s = store()) s->flush();
}

VMAP_INLINE void AnyMemory::close() {
  if (closed_) return;
  if (auto* s = impl_->store(); s && writes_) {
    sync();
    link_fleet(true);
    s->checkpoint();
  }
  impl_->drop_store();
  closed_ = true;
  if (replacement_) {
    const std::unique_ptr<MemoryReplacement> r = std::move(replacement_);
    r->commit();
  }
}

VMAP_INLINE void AnyMemory::abandon() {
  if (!replacement_) return;
  impl_->drop_store();
  closed_ = true;
  replacement_.reset();
}

VMAP_INLINE void AnyMemory::save(const std::filesystem::path& file, std::optional<ImageStorage> images) const {
  detail::save_vmem(file, impl_->serialize(images));
}

VMAP_INLINE MemoryLocalization AnyMemory::localize(const cv::Mat& image, const PlaceDecisionOptions* decision) {
  return impl_->localize(image, decision);
}

VMAP_INLINE PoseAnswer AnyMemory::loop_pose(const LoopEdge& edge) const { return impl_->loop_pose(edge); }

VMAP_INLINE void AnyMemory::set_pose_options(const MetricPoseOptions& options) { impl_->set_pose_options(options); }

VMAP_INLINE const MetricPoseOptions& AnyMemory::pose_options() const noexcept { return impl_->pose_options(); }

VMAP_INLINE const VisualMap& AnyMemory::map() const noexcept { return impl_->map(); }

VMAP_INLINE std::size_t AnyMemory::frames() const noexcept { return impl_->map().frames; }

VMAP_INLINE std::size_t AnyMemory::key_images() const noexcept { return impl_->map().keys.size(); }

VMAP_INLINE const std::vector<LoopEdge>& AnyMemory::loops() const noexcept { return impl_->loops(); }

VMAP_INLINE const std::vector<OdometryPose>& AnyMemory::poses() const noexcept { return impl_->poses(); }

VMAP_INLINE const std::vector<MemorySession>& AnyMemory::sessions() const noexcept { return impl_->sessions(); }

VMAP_INLINE const MemoryOptions& AnyMemory::options() const noexcept { return impl_->options(); }

VMAP_INLINE const AnyVocabulary& AnyMemory::vocabulary() const noexcept { return impl_->vocabulary(); }

VMAP_INLINE const std::vector<std::vector<Detection>>& AnyMemory::key_detections() const noexcept {
  return impl_->key_detections();
}

VMAP_INLINE const std::array<std::string, 4>& AnyMemory::policy_records() const noexcept { return impl_->policy_records(); }

VMAP_INLINE std::size_t AnyMemory::session_of(std::size_t key) const { return impl_->session_of(key); }

VMAP_INLINE std::optional<std::size_t> AnyMemory::last_frame_index() const noexcept { return impl_->last_frame_index(); }

VMAP_INLINE bool AnyMemory::stationary() const { return impl_->stationary(); }

VMAP_INLINE bool AnyMemory::labelled() const noexcept { return impl_->labelled(); }

VMAP_INLINE bool AnyMemory::has_gcs() const noexcept { return impl_->has_gcs(); }

VMAP_INLINE std::vector<std::uint32_t> AnyMemory::gcs_keys() const { return impl_->gcs_keys(); }

VMAP_INLINE std::size_t AnyMemory::checked_key_images() const noexcept { return impl_->checked_key_images(); }

VMAP_INLINE bool AnyMemory::holds_features(std::size_t key) const noexcept { return impl_->holds_features(key); }

VMAP_INLINE std::size_t AnyMemory::working_memory() const noexcept { return impl_->working_memory(); }

VMAP_INLINE Features AnyMemory::key_features(std::uint32_t key) const { return impl_->key_features(key); }

VMAP_INLINE std::vector<GraphNeighbour> AnyMemory::neighbours(std::uint32_t key) const { return impl_->neighbours(key); }

VMAP_INLINE MemoryRecords AnyMemory::records() const { return impl_->records(); }

VMAP_INLINE void AnyMemory::writable(const char* what) const {
  if (closed_) detail::fail("memory" + where() + ": " + what + ": the memory was closed");
  if (!writes_)
    detail::fail("memory" + where() + ": " + what + ": the memory was opened read-only (open it with write = true)");
}

}  // namespace vmap
