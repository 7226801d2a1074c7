#pragma once

// The memories AnyMemory holds (runtime/memory.hpp): the interface it calls and, for
// each shipped descriptor, the factory of its memories. The run-time layer's own header;
// a program includes runtime/memory.hpp. vmap::stacks compiles the factories once for
// the shipped descriptors (runtime/detail/compiled_stacks.hpp), and a program that links
// it declares them `extern` (the end of this file).

#include <vmap/core/error.hpp>
#include <vmap/hooks/detection.hpp>
#include <vmap/io/frame.hpp>
#include <vmap/memory/fleet.hpp>
#include <vmap/memory/records.hpp>
#include <vmap/memory/store.hpp>
#include <vmap/memory/types.hpp>
#include <vmap/memory/visual_memory.hpp>
#include <vmap/runtime/policies.hpp>
#include <vmap/runtime/stack.hpp>

#include <opencv2/core.hpp>

#include <array>
#include <cstddef>
#include <cstdint>
#include <memory>
#include <optional>
#include <string>
#include <typeinfo>
#include <utility>
#include <vector>

namespace vmap {

/// The memory type of a policy stack (eq. 5's inlier ratio as the similarity).
template <class D, class M, class E>
using MemoryOf = VisualMemory<D, M, E, InlierRatio>;

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
  [[nodiscard]] virtual PoseAnswer loop_pose(const LoopEdge& edge) const = 0;
  virtual void set_pose_options(const MetricPoseOptions& options) = 0;
  [[nodiscard]] virtual const MetricPoseOptions& pose_options() const noexcept = 0;
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
  /// Looks for the checked key images [from, to) among the fleet's other robots
  /// (link_across_fleet): the inter-robot loops found.
  virtual std::vector<FleetLoop> link_fleet(FleetIndex& fleet, std::size_t from, std::size_t to,
                                            std::int64_t vocabulary) = 0;
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
  PoseAnswer loop_pose(const LoopEdge& edge) const override { return memory_.loop_pose(edge); }
  void set_pose_options(const MetricPoseOptions& options) override { memory_.set_pose_options(options); }
  const MetricPoseOptions& pose_options() const noexcept override { return memory_.pose_options(); }
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
  std::vector<FleetLoop> link_fleet(FleetIndex& fleet, std::size_t from, std::size_t to,
                                    std::int64_t vocabulary) override {
    std::vector<FleetLoop> found;
    for (std::size_t k = from; k < to; ++k)
      for (FleetLoop& loop : link_across_fleet(memory_, static_cast<std::uint32_t>(k), fleet, vocabulary))
        found.push_back(std::move(loop));
    return found;
  }

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
