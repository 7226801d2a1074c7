#pragma once

// One visual memory a robot keeps (examples/methods.md, sec. 4): frames are pushed one by one;
// the key-image selector (Algorithm 1 / eq. 6 of García-Pintos et al. 2023, unchanged:
// keyframe/selector.hpp) keeps key images; each new key image is described by its bag of
// words (TF-IDF over a vocabulary tree, place/) from the features the selector already
// extracted and goes to the loop engine (lcd/loop_engine.hpp, the same one LoopDetector
// uses): the best-ranked earlier key images are verified by the selector's own matcher
// and estimator, and an accepted place decision (evidence, confidence, revisit rule) is a
// loop edge. The key images, the chain of F-matrix links and the loop edges form a graph
// (neighbours()). localize(image) answers the visual-map paper's localization stage
// (sec. 1) with the engine's decision: the key image the query shows, or "unknown place"
// with the reason.
//
// Object labels (LFM-LCD, Zhu et al., Sensors 2021; examples/methods.md, sec. 2): frames pushed
// with detections make the loop search go through the binary classified tree: each key
// image's label vector (eq. 3-4) leads to a leaf, backtracked to m candidates (sec.
// 3.3), ranked by BoW score and the best verified (tree_ranked) or all (tree). The
// schema is the user's order, or eq. 5 over the first M key images' detections, fixed
// from then on; the key images before it are then checked in order, so the result is
// the one a schema known from the start gives.
//
// GCS (Trujillo-Romero 2024, examples/methods.md, sec. 3): train_gcs() learns a GCS on the key
// images that have SE(2) poses, from their own features; localize() then also gives the
// position estimate of Algorithm 5.
//
// Sessions: a memory holds several runs of the robot (start_session(); merge() appends
// another memory's runs), each its own chain of key images with its own loops; the
// place rule between runs (link_pair: candidates by heavy score, place/heavy_words.hpp,
// each pair verified on its own) joins a session's key images to the earlier sessions',
// and localize() searches them all.
//
// The state is a set of records (memory/records.hpp): records() gives them, from_records()
// rebuilds the memory, and the back-ends keep them: a .vmem file (save(), load();
// memory/vmem.hpp) or a memory store written key image by key image (memory/store.hpp).
// push() after a load continues exactly as the uninterrupted run would. push() is all
// or nothing: when it throws, the memory is as it was before the call.
//
// What it costs (bench_memory, bench_store; examples/memory.md): per key image its
// features (28 B a keypoint and the descriptor: about 60 KB for ORB 1000), about 8 B per
// distinct word in the place database, about 100 B per link and loop edge, the heavy
// words of the earlier sessions' key images once a second session starts (1 KB each:
// link_sessions), and the pixels when kept. Frames that are not key images leave
// nothing but eq. 6's I_{j-1}. With a working memory (bound_features, as a store's)
// only the N most recent key images keep their features in RAM.
//
// Threading: push() and localize() modify scratch state of the descriptor and must not
// run concurrently on one object; const members only read, except that with a working
// memory those that read released key images (key_features, records, serialize, save) go
// through the one source, so they too run on one thread at a time. The memory is
// move-only (a copy would share the descriptor's detector); separate objects share
// nothing.

#include <vmap/core/concepts.hpp>
#include <vmap/core/error.hpp>
#include <vmap/core/features.hpp>
#include <vmap/geometry/fundamental.hpp>
#include <vmap/geometry/similarity.hpp>
#include <vmap/hooks/detection.hpp>
#include <vmap/io/atomic_file.hpp>
#include <vmap/io/files.hpp>
#include <vmap/io/frame.hpp>
#include <vmap/io/timestamps.hpp>
#include <vmap/keyframe/map_io.hpp>
#include <vmap/keyframe/selector.hpp>
#include <vmap/lcd/binary_tree.hpp>
#include <vmap/lcd/influence.hpp>
#include <vmap/lcd/label_vector.hpp>
#include <vmap/lcd/loop_engine.hpp>
#include <vmap/lcd/place_ranking.hpp>
#include <vmap/matching/brute_force.hpp>
#include <vmap/memory/detail/format.hpp>
#include <vmap/memory/detail/record_codecs.hpp>
#include <vmap/memory/gcs.hpp>
#include <vmap/memory/metric_pose.hpp>
#include <vmap/memory/records.hpp>
#include <vmap/memory/types.hpp>
#include <vmap/memory/vmem.hpp>
#include <vmap/place/database.hpp>
#include <vmap/place/heavy_words.hpp>
#include <vmap/place/vocabulary.hpp>
#include <vmap/som/gcs.hpp>
#include <vmap/som/histogram.hpp>
#include <vmap/som/localizer.hpp>
#include <vmap/som/pose_map.hpp>

#include <opencv2/core.hpp>

#include <algorithm>
#include <array>
#include <cstddef>
#include <cstdint>
#include <filesystem>
#include <functional>
#include <memory>
#include <optional>
#include <string>
#include <string_view>
#include <type_traits>
#include <utility>
#include <variant>
#include <vector>

namespace vmap {

/// The memory over the paper's feature stack (Descriptor, Matcher, Estimator,
/// Similarity; keyframe/selector.hpp).
template <Descriptor D, Matcher M, Estimator E, Similarity S>
class VisualMemory {
 public:
  using Selector = KeyframeSelector<D, M, E, S>;
  /// The loop engine over the key images (32-bit key indices in the place database).
  using Engine = LoopEngine<M, E, BasicPlaceRanker<std::uint32_t>>;

  /// `vocabulary`: a vocabulary for the descriptors' kind (binary / float), or empty to
  /// learn one from the first MemoryOptions::vocabulary_after key images. Options that no
  /// memory can run are an Error naming the option (the same check as a load's).
  explicit VisualMemory(D descriptor = D(), M matcher = M(), E estimator = E(), S similarity = S(),
                        const MemoryOptions& options = {}, AnyVocabulary vocabulary = {})
      : options_(detail::checked_memory_options(options)),
        policies_{detail::memory_policy_record(descriptor), detail::memory_policy_record(matcher),
                  detail::memory_policy_record(estimator), detail::memory_policy_record(similarity)},
        selector_(std::move(descriptor), std::move(matcher), std::move(estimator), std::move(similarity), options_.selector),
        vocabulary_(std::make_shared<const AnyVocabulary>(std::move(vocabulary))) {
    if (!options_.labels.order.empty()) labels_.schema = LabelSchema(options_.labels.order);
  }

  explicit VisualMemory(const MemoryOptions& options, AnyVocabulary vocabulary = {})
      : VisualMemory(D{}, M{}, E{}, S{}, options, std::move(vocabulary)) {}

  // Move-only: a copy would share the descriptor's detector (OrbDescriptor holds a
  // cv::Ptr<cv::ORB> with scratch buffers), so two copies used from two threads would
  // race. Two threads each load their own memory instead.
  VisualMemory(VisualMemory&&) noexcept(std::is_nothrow_move_constructible_v<Selector>) = default;
  VisualMemory& operator=(VisualMemory&&) noexcept(std::is_nothrow_move_assignable_v<Selector>) = default;
  VisualMemory(const VisualMemory&) = delete;
  VisualMemory& operator=(const VisualMemory&) = delete;
  ~VisualMemory() = default;

  /// Pushes a frame of a sequence (its index is its place in the sequence).
  MemoryStep push(const Frame& frame, const OdometryPose& pose = detail::no_odometry_pose) { return push_frame(frame, pose, nullptr); }

  /// Pushes a frame with its object detections (any detector, or precomputed): the
  /// memory then finds loops through LFM-LCD's label tree (MemoryOptions::labels). The
  /// first frame decides: a memory whose frames come with detections needs them with
  /// every frame (an empty list when nothing was detected), and one without takes none.
  MemoryStep push(const Frame& frame, const OdometryPose& pose, const std::vector<Detection>& detections) {
    return push_frame(frame, pose, &detections);
  }

  /// Runs `detector` on the frame (every frame: eq. 6 may take it as the next key
  /// image), then push(frame, pose, detections).
  template <ObjectDetector Detector>
  MemoryStep push(const Frame& frame, const OdometryPose& pose, Detector& detector) {
    detail::check(!frame.image.empty(),
                  [&] { return "VisualMemory::push: frame " + std::to_string(frame.index) + " is empty"; });
    return push(frame, pose, detector.detect(frame.image));
  }

  /// Pushes a bare image: numbered after the last frame pushed (0 for the first); the
  /// timestamp defaults to that number.
  MemoryStep push(const cv::Mat& image, std::optional<double> timestamp = {},
                  const OdometryPose& pose = detail::no_odometry_pose) {
    return push_frame(bare_frame(image, timestamp), pose, nullptr);
  }

  /// A bare image with its detections (see push(frame, pose, detections)).
  MemoryStep push(const cv::Mat& image, std::optional<double> timestamp, const OdometryPose& pose,
                  const std::vector<Detection>& detections) {
    return push_frame(bare_frame(image, timestamp), pose, &detections);
  }

  /// Where `image` was taken (visual-map paper, sec. 1): key images ranked by BoW score
  /// (every key image while no vocabulary exists yet), the best `localize_top_k`
  /// verified, and the loop engine's place decision (loops.decision) over them: the key
  /// image it shows, or "unknown place" / "ambiguous" / "too little evidence" with the
  /// reason. `decision` overrides loops.decision for this query.
  [[nodiscard]] MemoryLocalization localize(const cv::Mat& image, const PlaceDecisionOptions* decision = nullptr);

  /// The pose of a camera whose image (features `query`) shows key image `key`, by the
  /// verified `matches` between them (queryIdx: the query's, trainIdx: the key image's)
  /// and their `verification` (memory/metric_pose.hpp): the points the posed key images
  /// beside `key` in its session triangulate with it, PnP, and the checks. No pose, with
  /// the reason, without a camera (the estimator's), without an SE(3) pose of `key`, and
  /// where the geometry does not hold. localize() answers it for its accepted key image.
  [[nodiscard]] PoseAnswer metric_pose(const Features& query, std::uint32_t key, const Matches& matches,
                                       const Verification& verification) const;

  /// The metric pose of loop edge `edge`'s newer key image (`from`) measured against the
  /// points of the key image it revisits (`link.key`), in the frame of that one's session:
  /// the two are matched and verified again (the edge keeps no matches), then
  /// metric_pose(). A g2o export's loop edge is the relative pose it gives
  /// (runtime/exports.hpp).
  [[nodiscard]] PoseAnswer loop_pose(const LoopEdge& edge) const;

  /// When a query gets a metric pose (memory/metric_pose.hpp); not recorded with the
  /// memory (a setting of the program that reads it). Invalid options are an Error.
  void set_pose_options(const MetricPoseOptions& options) {
    detail::check_metric_pose_options(options);
    pose_options_ = options;
  }
  [[nodiscard]] const MetricPoseOptions& pose_options() const noexcept { return pose_options_; }
  /// The camera of the memory's estimator (Calibrated, EssentialEstimator), or nullptr.
  [[nodiscard]] const Camera* camera() const noexcept { return detail::camera_of(selector_.front_end().estimator()); }

  /// Trains the GCS localizer on the key images that have an SE(2) pose (at least 3),
  /// from their own features (no second extraction): a BowHistogram vocabulary learned
  /// on them, the network (Trujillo-Romero 2024, Algorithm 1), a pose per neuron
  /// (Algorithm 4). localize() then also answers a position (Algorithm 5). Key images
  /// added later are not in it until train_gcs runs again. Deterministic (seeded).
  GcsTrainStats train_gcs(const MemoryGcsOptions& options = {});

  /// Whether a GCS was trained (train_gcs) or loaded with the memory.
  [[nodiscard]] bool has_gcs() const noexcept { return gcs_.has_value(); }
  /// The trained GCS and its pose per neuron; an Error without one.
  [[nodiscard]] const PoseMap<GcsXf>& gcs() const {
    detail::check(gcs_.has_value(), "VisualMemory::gcs: no GCS trained (call train_gcs first)");
    return gcs_->map;
  }
  /// The key images the GCS was trained on (ascending).
  [[nodiscard]] std::vector<std::uint32_t> gcs_keys() const { return gcs_ ? gcs_->keys : std::vector<std::uint32_t>{}; }
  /// Counts train_gcs calls: a back-end rewrites the GCS when it changed (RecordsHeld::gcs).
  [[nodiscard]] std::uint64_t gcs_generation() const noexcept { return gcs_generation_; }

  /// Key images linked to `key`: the chain neighbours (key - 1, key + 1), then loop edges.
  [[nodiscard]] std::vector<GraphNeighbour> neighbours(std::uint32_t key) const {
    const std::size_t m = selector_.map().keys.size();
    detail::check(key < m,
                  [&] { return "VisualMemory::neighbours: key " + std::to_string(key) + " of " + std::to_string(m); });
    std::vector<GraphNeighbour> out;
    if (key > 0 && !starts_session(key)) out.push_back({key - 1, GraphNeighbour::Kind::link});
    if (key + 1 < m && !starts_session(key + 1)) out.push_back({key + 1, GraphNeighbour::Kind::link});
    for (const auto& e : loops_) {
      if (e.from == key) out.push_back({e.link.key, GraphNeighbour::Kind::loop});
      if (e.link.key == key) out.push_back({e.from, GraphNeighbour::Kind::loop});
    }
    return out;
  }

  // ---- sessions -------------------------------------------------------------------

  /// Starts a session (another run of the robot, e.g. tomorrow's): the next frame
  /// pushed becomes a key image as the first frame of a memory does, not linked to the
  /// last key image (map().pairs holds a link of no matches there). The loop engine
  /// searches the session's own key images, as if the memory started with it; what joins
  /// it to the earlier sessions is the place rule between runs (link_pair): each of its
  /// key images against the earlier sessions' whose heavy score reaches
  /// run_link_min_score, each pair verified and decided on its own, so the loops between
  /// two runs do not depend on which came first (nor, in a fleet's memory, on the order
  /// robots map in). A no-op before the first frame and right after another start_session.
  void start_session() {
    if (frames() == 0 || sessions_.back().first_frame == frames()) return;
    sessions_.push_back({key_images(), frames()});
    selector_.start_chain();
    previous_pose_ = OdometryPose{};
    labels_.previous_detections.clear();
  }

  /// The sessions, in order; the first starts at key image 0 and frame 0.
  [[nodiscard]] const std::vector<MemorySession>& sessions() const noexcept { return sessions_; }

  /// The session key image `key` belongs to (its index in sessions()).
  [[nodiscard]] std::size_t session_of(std::size_t key) const {
    detail::check(key < key_images(),
                  [&] { return "VisualMemory::session_of: key " + std::to_string(key) + " of " + std::to_string(key_images()); });
    return session_of_key(key);
  }

  /// Appends `other`'s sessions after this memory's, as if its runs had been pushed
  /// here, each after start_session(): its key images, links, poses and detections as
  /// they are, and loop detection of each of its key images against every key image
  /// before it, this memory's included. The result equals the memory built with both
  /// memories' runs (the key images of a session depend only on its frames), ranked
  /// with this memory's vocabulary and label schema (learned as that build would learn
  /// them); other's loop edges, bags of words and GCS are not used. Pushing then
  /// continues other's last session. The two must have the same options (every one, as
  /// their records compare) and policies, and other must hold its key images' features
  /// (not bounded): anything else is an Error naming both (`name`, `other_name`), and
  /// this memory is left as it was.
  void merge(VisualMemory&& other, const std::string& name = "the memory",
             const std::string& other_name = "the other memory");

  [[nodiscard]] const VisualMap& map() const noexcept { return selector_.map(); }
  [[nodiscard]] std::size_t frames() const noexcept { return selector_.map().frames; }
  [[nodiscard]] std::size_t key_images() const noexcept { return selector_.map().keys.size(); }
  /// The index of the last frame pushed (nullopt before the first): a program that
  /// resumes a stream from a saved memory goes on with the frames after it.
  [[nodiscard]] std::optional<std::size_t> last_frame_index() const noexcept { return last_index_; }
  [[nodiscard]] const std::vector<LoopEdge>& loops() const noexcept { return loops_; }
  /// Odometry poses of the key images (std::monostate where none was given).
  [[nodiscard]] const std::vector<OdometryPose>& poses() const noexcept { return poses_; }
  [[nodiscard]] const AnyVocabulary& vocabulary() const noexcept { return *vocabulary_; }
  /// The key images checked for loops so far, by bag of words (empty before the
  /// vocabulary, and with detections before the label schema).
  [[nodiscard]] const PlaceDatabase<std::uint32_t>& database() const noexcept {
    static const PlaceDatabase<std::uint32_t> none;
    return engine_ ? engine_->ranker().database() : none;
  }
  /// The loop engine once loop detection runs (a vocabulary and, with detections, a
  /// schema); nullptr before.
  [[nodiscard]] const Engine* loop_engine() const noexcept { return engine_ ? &*engine_ : nullptr; }
  /// A verified candidate of a place decision as a PlaceLink (its key is c.frame): the one
  /// conversion of the loop edges, the localization answers and the loops between robots
  /// (memory/fleet.hpp). Its similarity is eq. 5 (the memory's similarity policy) between
  /// the query and the candidate's features `candidate`.
  [[nodiscard]] PlaceLink link_to(const PlaceCandidate& c, const Features& query, const Features& candidate);
  /// The place rule between two runs (sessions of this memory, robots of a fleet's):
  /// key image features `query` of one against `candidate`, a key image of another whose
  /// heavy score against it (place/heavy_words.hpp) is `score`. The two are verified in
  /// the pair's own order (detail::features_before), not the asker's, and decided as
  /// localization decides a single candidate, at a confidence of run_link_min_confidence
  /// at least, so the answer is the pair's whichever of the two asks: the link from
  /// `query` to `candidate` (its key left 0) or nothing.
  /// Nothing before loop detection runs (loop_engine()).
  [[nodiscard]] std::optional<PlaceLink> link_pair(const Features& query, const Features& candidate, double score);
  /// Whether the camera never left its place: more frames than the loop window were
  /// pushed into the current session and its chain holds one key image (the selector
  /// never saw the view change; the revisit rule's chain, lcd/loop_engine.hpp). No
  /// vocabulary is needed.
  [[nodiscard]] bool stationary() const {
    const MemorySession& s = sessions_.back();
    return frames() - s.first_frame > std::max<std::size_t>(options_.loops.window, 1) && key_images() == s.first_key + 1;
  }
  [[nodiscard]] const MemoryOptions& options() const noexcept { return options_; }
  [[nodiscard]] Selector& selector() noexcept { return selector_; }
  /// Whether the frames come with detections (the label-tree loop detection runs).
  [[nodiscard]] bool labelled() const noexcept { return labels_.labelled; }
  /// The label schema once fixed (given order, or after MemoryLabelOptions::sample key
  /// images); nullopt before, and in a memory without detections.
  [[nodiscard]] const std::optional<LabelSchema>& label_schema() const noexcept { return labels_.schema; }
  /// The binary classified tree: the key images older than the window of the last one
  /// checked for loops, each at the leaf of its label vector (empty before the schema).
  [[nodiscard]] const BinaryClassifiedTree<std::size_t>& label_tree() const noexcept {
    static const BinaryClassifiedTree<std::size_t> none;
    return engine_ ? engine_->tree() : none;
  }
  /// The detections pushed with each key image's frame (empty without detections).
  [[nodiscard]] const std::vector<std::vector<Detection>>& key_detections() const noexcept {
    return labels_.key_detections;
  }
  /// What the memory records of its policies (descriptor, matcher, estimator,
  /// similarity): each one's describe(), "" for a policy that does not describe itself.
  [[nodiscard]] const std::array<std::string, 4>& policy_records() const noexcept { return policies_; }

  // ---- working memory ---------------------------------------------------------------

  /// Reads key image k's features where the memory no longer holds them in RAM (e.g.
  /// MemoryStore::features(): the store the memory is synced into).
  using KeyFeatureSource = std::function<Features(std::uint32_t key)>;

  /// Bounds the features held in RAM to the `working_memory` (>= 1) most recent key
  /// images: release_features() then drops older key images' features, which are read
  /// through `source` when a loop or localization candidate is verified, for
  /// train_gcs() and for records(). What ranking needs stays in RAM (each key image's bag
  /// of words in the place database, its detections, pose and links), so the answers
  /// are the same as with every key image's features held. map() shows released key
  /// images without keypoints or descriptors. `released`: the first key images already
  /// hold none (a memory rebuilt from records read so).
  void bound_features(std::size_t working_memory, KeyFeatureSource source, std::size_t released = 0) {
    detail::check(working_memory >= 1, "VisualMemory::bound_features: the working memory must hold at least 1 key image");
    detail::check(static_cast<bool>(source), "VisualMemory::bound_features: no source of released features");
    detail::check(released <= key_images(), "VisualMemory::bound_features: more key images released than held");
    working_memory_ = working_memory;
    source_ = std::move(source);
    released_ = std::max(released_, released);
    read_.reset();
  }

  /// The bound set by bound_features (0: every key image's features are held).
  [[nodiscard]] std::size_t working_memory() const noexcept { return working_memory_; }

  /// Drops the features of the key images that are both among the first `stored` (those
  /// the source can read) and older than the working memory; a no-op without
  /// bound_features.
  void release_features(std::size_t stored) {
    if (working_memory_ == 0) return;
    const std::size_t m = key_images();
    const std::size_t until = std::min(stored, m > working_memory_ ? m - working_memory_ : 0);
    for (; released_ < until; ++released_) selector_.release_key_features(released_);
  }

  /// Whether key image k's features are held in RAM.
  [[nodiscard]] bool holds_features(std::size_t k) const noexcept { return k >= released_; }

  /// Key image k's features: a copy of the held ones, or read through the source.
  [[nodiscard]] Features key_features(std::uint32_t k) const;

  // ---- records ------------------------------------------------------------------------

  /// The memory's records (memory/records.hpp): whole, or what it made since a back-end
  /// took the records it holds (`held`): the lists from there on, the vocabulary and the
  /// GCS when they changed. Released key images' features are read back through the
  /// working memory's source. `complete_score`: I_{j-1}'s score with its homography
  /// degeneracy test done (a file saved whole), or deferred with the inlier mask that
  /// completes it (a store, which rewrites it at every sync; SelectorState).
  [[nodiscard]] MemoryRecords records(const RecordsHeld& held = {}, bool complete_score = true) const;

  /// The memory whole records (a back-end's) describe, with the given policies (their
  /// options are not in the records; the options are the records'). Everything the
  /// records hold is checked against the rest and against the policies (each policy
  /// that describes itself against what was recorded, key images' descriptors against
  /// the descriptor's layout): anything inconsistent is an Error naming `name`.
  /// `pixels_unread`: the key images' pixels were checked but not decoded (the memory
  /// then cannot be written with pixels).
  [[nodiscard]] static VisualMemory from_records(MemoryRecords r, const std::string& name, D descriptor = D(),
                                                 M matcher = M(), E estimator = E(), S similarity = S(),
                                                 bool pixels_unread = false);

  /// The bytes of a .vmem file of this memory (memory/vmem.hpp). `images` overrides
  /// MemoryOptions::images for this file (e.g. none for a small copy; png or jpeg store
  /// only the pixels the memory kept).
  [[nodiscard]] std::string serialize(std::optional<ImageStorage> images = {}) const {
    const ImageStorage storage = images.value_or(options_.images);
    check_pixels_read(storage, "VisualMemory::serialize");
    return detail::vmem_file_bytes(records(), storage);
  }

  /// Writes the memory atomically (temporary file, fsync, rename, fsync of the folder):
  /// a crash during save leaves the previous file as it was. An existing file is replaced
  /// only when it is a .vmem memory file (detail::save_vmem).
  void save(const std::filesystem::path& path, std::optional<ImageStorage> images = {}) const {
    detail::save_vmem(path, serialize(images));
  }

  /// Parses a .vmem file's bytes; the policies are the caller's (their options are not
  /// in the file), the options are the file's. `limits` bound the key images' pixels
  /// (each, and all together, checked before any is decoded). Anything invalid is a
  /// vmap::Error naming the file.
  [[nodiscard]] static VisualMemory deserialize(std::string_view bytes, const std::string& name = "<memory>",
                                                D descriptor = D(), M matcher = M(), E estimator = E(),
                                                S similarity = S(), const MapLoadOptions& limits = {}) {
    bool pixels_skipped = false;
    MemoryRecords r = detail::read_vmem(bytes, name, limits, &pixels_skipped);
    return from_records(std::move(r), "memory file '" + name + "'", std::move(descriptor), std::move(matcher),
                        std::move(estimator), std::move(similarity), pixels_skipped);
  }

  [[nodiscard]] static VisualMemory load(const std::filesystem::path& path, D descriptor = D(), M matcher = M(),
                                         E estimator = E(), S similarity = S(), const MapLoadOptions& limits = {}) {
    return deserialize(read_file(path, limits.max_file_bytes, "memory file"), path.string(), std::move(descriptor),
                       std::move(matcher), std::move(estimator), std::move(similarity), limits);
  }

  /// A memory loaded without decoding its pixels (MapLoadOptions::decode_images) cannot
  /// write them: refused, so that no file or store loses the pixels it had. `who` names
  /// the writer.
  void check_pixels_read(ImageStorage storage, const char* who) const {
    if (pixels_unread_ && storage != ImageStorage::none)
      detail::fail(std::string(who) + ": the memory was loaded without its key images' pixels "
                   "(MapLoadOptions::decode_images = false) and cannot write them; write it with ImageStorage::none, "
                   "or load it with its pixels");
  }

 private:
  /// The frame state besides the selector's, the labels and the engine that push()
  /// changes: what rollback() restores when a push throws.
  struct PushCheckpoint {
    typename Selector::Checkpoint selector;
    std::size_t keys = 0, loops = 0;
    OdometryPose previous_pose;
    std::vector<Detection> previous_detections;
    std::optional<std::size_t> last_index;
    bool labelled = false;
    std::optional<LabelSchema> schema;
    std::shared_ptr<const AnyVocabulary> vocabulary;
    std::optional<std::size_t> engine_frames;  ///< nullopt: no engine yet
    LoopEngineState engine_state;
    std::size_t engine_session = 0;
  };

  PushCheckpoint checkpoint() const {
    PushCheckpoint c{selector_.checkpoint(), poses_.size(), loops_.size(), previous_pose_,
                     labels_.previous_detections, last_index_, labels_.labelled, labels_.schema, vocabulary_,
                     std::nullopt, {}, 0};
    if (engine_) {
      c.engine_frames = engine_->frames();
      c.engine_state = engine_->state();
      c.engine_session = engine_->session_start();
    }
    return c;
  }

  /// Undoes a push that threw after `c` (the failure path: it may rebuild the engine).
  void rollback(PushCheckpoint c);

  static Frame bare_frame(const cv::Mat& image, std::optional<double> timestamp, std::size_t index) {
    Frame f;
    f.image = image;
    f.index = index;
    f.name = "frame#" + std::to_string(f.index);
    f.timestamp = timestamp.value_or(static_cast<double>(f.index));
    f.time_ns = frame_time_ns(f.timestamp, "push: timestamp");
    return f;
  }

  Frame bare_frame(const cv::Mat& image, std::optional<double> timestamp) const {
    return bare_frame(image, timestamp, last_index_ ? *last_index_ + 1 : 0);
  }

  MemoryStep push_frame(const Frame& frame, const OdometryPose& pose, const std::vector<Detection>* detections);

  /// Eq. 5 over the first `sample` key images' detections (label order by mean box area).
  void sample_schema(std::size_t key_images) {
    if (!labels_.labelled || labels_.schema || key_images < options_.labels.sample) return;
    LabelStatistics stats(options_.loops.labels);
    for (std::size_t k = 0; k < options_.labels.sample; ++k) stats.observe(labels_.key_detections[k]);
    labels_.schema = make_label_schema(stats, options_.labels.influence);
  }

  /// Loop detection runs once there is a vocabulary and, for labels, a schema.
  [[nodiscard]] bool detecting() const noexcept {
    return !vocabulary_->empty() && (!labels_.labelled || labels_.schema);
  }

  /// Key image k's label vector (eq. 3-4; empty without detections).
  [[nodiscard]] LabelVector label_vector(std::size_t k) const {
    return labels_.labelled ? labels_.schema->vector(labels_.key_detections[k], options_.loops.labels)
                            : LabelVector{};
  }

  /// The loop engine over the key images, its ranker over `database` (the key images
  /// checked so far): label sources with detections, bag of words without.
  void start_engine(PlaceDatabase<std::uint32_t> database) {
    LoopOptions o = options_.loops;
    if (!labels_.labelled) o.index = CandidateIndex::bow;
    engine_.emplace(selector_.front_end().matcher(), selector_.front_end().estimator(), o,
                    BasicPlaceRanker<std::uint32_t>(vocabulary_, std::move(database)),
                    labels_.labelled ? *labels_.schema : LabelSchema{});
  }

  /// The model the memory's verifications fit (the engine's inference from its estimator).
  [[nodiscard]] static constexpr PlaceModel model_kind() noexcept { return place_model_of<E>(); }

  /// link_to() for a candidate that is one of this memory's key images.
  PlaceLink link_of(const PlaceCandidate& c, const Features& query);

  void after_push(MemoryStep& step, std::size_t index, const OdometryPose& pose,
                  const std::vector<Detection>* detections);

  /// Adds key image `key` to the place database and detects its loops; learns the
  /// vocabulary once enough key images exist (and, with detections, fixes the label
  /// schema after the sample), then catches up with the earlier ones in order.
  void on_new_key(std::uint32_t key, std::vector<LoopEdge>& found);

  /// The loops of key image k (features `query`, in the place database) to the key images
  /// of the sessions before its own, by the place rule between runs (link_pair): the
  /// candidates are those whose heavy score reaches run_link_min_score, the best
  /// run_link_candidates of them.
  void link_sessions(std::uint32_t k, const Features& query, std::vector<LoopEdge>& found);

  /// The session of key image k (any k: no check against the key images).
  [[nodiscard]] std::size_t session_of_key(std::size_t k) const noexcept {
    const auto it = std::upper_bound(sessions_.begin(), sessions_.end(), k,
                                     [](std::size_t key, const MemorySession& s) { return key < s.first_key; });
    return static_cast<std::size_t>(it - sessions_.begin()) - 1;
  }

  /// Whether key image k is the first of a session other than the first.
  [[nodiscard]] bool starts_session(std::size_t k) const {
    return std::any_of(sessions_.begin() + 1, sessions_.end(), [k](const MemorySession& s) { return s.first_key == k; });
  }

  /// The options as their record holds them (write_memory_options): what merge compares.
  [[nodiscard]] std::string options_record() const {
    detail::BinaryWriter w;
    detail::write_memory_options(w, options_, options_.images);
    return std::move(w).take();
  }

  /// Each recorded policy against the one given (a policy that did not describe itself
  /// when the memory was made recorded nothing, so there is nothing to contradict).
  void check_policies(const std::array<std::string, 4>& recorded, const std::string& name) const;

  /// Features of the records against the layout of the descriptor given to load
  /// (core/concepts.hpp, StatesLayout), so that key images holding other descriptors are
  /// refused when the memory loads, not when they are first matched.
  template <class What>
  void check_layout(const Features& f, const std::string& name, const What& what) const {
    if constexpr (StatesLayout<D>) {
      if (f.descriptors.empty()) return;
      const DescriptorLayout want = selector_.front_end().descriptor().layout();
      if (const DescriptorLayout got = layout_of(f); got != want)
        detail::fail(ErrorKind::policy_mismatch, name + ": " + what() + " has descriptors of " + to_string(got) + ", the descriptor given to load makes " +
                     to_string(want));
    }
  }

  /// Key image k's features for a verification: held, or read into `read_`, so the
  /// reference is valid until the next read of a released key image.
  const Features& feature_ref(std::size_t k) {
    if (holds_features(k)) return selector_.map().keys[k].features;
    if (!read_ || read_->first != k) read_.emplace(k, key_features(static_cast<std::uint32_t>(k)));
    return read_->second;
  }

  /// What the memory knows of its frames' object labels (LFM-LCD).
  struct Labels {
    bool labelled = false;                               ///< frames come with detections (the first frame decides)
    std::vector<std::vector<Detection>> key_detections;  ///< per key image
    std::vector<Detection> previous_detections;          ///< of the last pushed frame (eq. 6's I_{j-1})
    std::optional<LabelSchema> schema;                   ///< the given order, or eq. 5's after the sample
  };

  MemoryOptions options_;
  std::array<std::string, 4> policies_;  ///< detail::memory_policy_record of each policy
  Selector selector_;
  std::shared_ptr<const AnyVocabulary> vocabulary_;  ///< never null (empty before one is learned)
  std::optional<Engine> engine_;                     ///< once loop detection runs (detecting())
  std::vector<LoopEdge> loops_;
  std::vector<OdometryPose> poses_;  ///< per key image
  OdometryPose previous_pose_;       ///< of the last pushed frame (eq. 6's I_{j-1})
  std::optional<std::size_t> last_index_;
  Labels labels_;                    ///< the frames' object labels (LFM-LCD)
  std::optional<MemoryGcs> gcs_;     ///< once train_gcs ran (or loaded)
  std::uint64_t gcs_generation_ = 0;  ///< counts train_gcs calls (a back-end rewrites the GCS when it changes)
  std::size_t working_memory_ = 0;    ///< bound_features (0: unbounded)
  KeyFeatureSource source_;           ///< where released features are read
  std::size_t released_ = 0;          ///< key images 0 .. released_ - 1 hold no features in RAM
  std::optional<std::pair<std::size_t, Features>> read_;  ///< the last released key image read (feature_ref)
  bool pixels_unread_ = false;  ///< loaded without decoding the key images' pixels
  std::vector<MemorySession> sessions_{MemorySession{}};  ///< never empty: the first starts at 0
  HeavyIndex heavy_;  ///< heavy words of the key images before the current session's (link_sessions; built when needed)
  MetricPoseOptions pose_options_{};  ///< set_pose_options
};

}  // namespace vmap

#include <vmap/memory/detail/visual_memory_impl.hpp>
