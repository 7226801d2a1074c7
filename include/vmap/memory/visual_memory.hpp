#pragma once

// One visual memory a robot keeps (DESIGN.md sec. 1.4): frames are pushed one by one;
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
// Object labels (LFM-LCD, Zhu et al., Sensors 2021; DESIGN.md sec. 1.2): frames pushed
// with detections (any detector, or a file of precomputed ones) make the loop search
// go through the binary classified tree instead of the whole database: each key
// image's label vector (eq. 3-4) leads to a leaf, backtracked to m candidates (sec.
// 3.3), whose key images are ranked by BoW score and the best verified (tree_ranked) or
// all verified (tree), by the same engine. The schema (label order) is the user's, or eq. 5 over the first
// M key images' detections, fixed from then on; the key images before it are then
// checked in order, so nothing runs over the whole sequence first and the result is
// the one a schema known from the start gives. Frames without detections keep the
// plain BoW search.
//
// GCS (Trujillo-Romero 2024, DESIGN.md sec. 1.3): train_gcs() learns a GCS on the key
// images that have SE(2) poses, from their own features; localize() then also gives the
// position estimate of Algorithm 5.
//
// Sessions: a memory holds several runs of the robot (start_session(); merge() appends
// another memory's runs). Each is its own chain of key images; loops are searched across
// every session (an earlier run's key images are candidates whatever the loop window, and
// revisits by definition), so an accepted loop joins two runs, and localize() searches
// them all.
//
// The whole state saves to one file and loads back; push() after load() continues
// exactly as the uninterrupted run would (same key images, same loops). A memory that
// grows over a long run is better kept in a memory store (memory/store.hpp): an SQLite
// file written key image by key image from the same records as the file's sections.
//
// The file format (version 4, and what versions 1 to 3 lack) is documented in
// examples/memory.md, "The single-file format (.vmem)"; each section is parsed by its own
// reader, so every error names its section, and counts are checked against the bytes
// that remain before anything is allocated. Key images' descriptors are checked against
// the layout of the descriptor given to load (core/concepts.hpp, StatesLayout). The
// memory frames the sections; the parts encode their own state in them: the GCS
// (memory/gcs.hpp), the object labels (memory/labels.hpp), the loop engine's state and
// decision options (lcd/loop_engine.hpp), the selector's links and score
// (keyframe/map_io.hpp), the vocabulary (place/vocabulary.hpp) and the place database;
// the options by codecs beside their structs, each asserting its struct's field count.
//
// Bytes per key image (ORB 1000, 32-byte descriptors): 28 per keypoint + 32 per
// descriptor, about 60 KB of features in the file and in memory (measured by
// bench_memory: 61.4 KB per key image of the whole file on tum_fr1_rpy, 31.8 KB on
// rtabmap_loop's 512x384 frames), about 8 B per distinct word in the place database,
// 97 B per link and per loop edge, and the image when kept (640x480 grey: about +143 KB
// as PNG, +50 KB as JPEG quality 90). With labels: 24 B per detection of each key image
// and one tree entry per key image; the GCS: its vocabulary and network (4 B per weight).
// Nothing is kept for frames that are not key images except the one I_{j-1} of eq. 6
// (its features, pose and detections). With a working memory (bound_features, e.g. a
// MemoryStore's) only the N most recent key images keep their features in RAM; the rest
// is about 9.4 KiB per key image (bench_store at 10,000 key images, examples/memory.md).
//
// Threading: push() and localize() modify scratch state of the descriptor and must not
// run concurrently on one object; const members only read, except that with a working
// memory those that read released key images (key_features, serialize, save) go through
// the one source, so they too run on one thread at a time. The memory is move-only (a
// copy would share the descriptor's detector); separate objects (e.g. each thread
// loading the same file) share nothing.

#include <vmap/core/concepts.hpp>
#include <vmap/core/error.hpp>
#include <vmap/core/features.hpp>
#include <vmap/geometry/pose2.hpp>
#include <vmap/io/atomic_file.hpp>
#include <vmap/io/binary.hpp>
#include <vmap/io/files.hpp>
#include <vmap/io/frame_source.hpp>
#include <vmap/io/image.hpp>
#include <vmap/features/akaze.hpp>
#include <vmap/features/orb.hpp>
#include <vmap/features/sift.hpp>
#include <vmap/geometry/fundamental.hpp>
#include <vmap/geometry/similarity.hpp>
#include <vmap/hooks/detection.hpp>
#include <vmap/keyframe/map_io.hpp>
#include <vmap/keyframe/selector.hpp>
#include <vmap/lcd/binary_tree.hpp>
#include <vmap/lcd/influence.hpp>
#include <vmap/lcd/label_vector.hpp>
#include <vmap/lcd/loop_engine.hpp>
#include <vmap/lcd/place_ranking.hpp>
#include <vmap/matching/brute_force.hpp>
#include <vmap/memory/detail/format.hpp>
#include <vmap/memory/gcs.hpp>
#include <vmap/memory/labels.hpp>
#include <vmap/memory/types.hpp>
#include <vmap/place/bow.hpp>
#include <vmap/place/database.hpp>
#include <vmap/place/vocabulary.hpp>
#include <vmap/som/gcs.hpp>
#include <vmap/som/histogram.hpp>
#include <vmap/som/localizer.hpp>
#include <vmap/som/pose_map.hpp>

#include <opencv2/core.hpp>
#include <opencv2/core/affine.hpp>
#include <opencv2/imgcodecs.hpp>

#include <algorithm>
#include <array>
#include <charconv>
#include <cmath>
#include <cstdint>
#include <cstring>
#include <filesystem>
#include <functional>
#include <optional>
#include <string>
#include <string_view>
#include <type_traits>
#include <utility>
#include <memory>
#include <variant>
#include <vector>

namespace vmap {

class MemoryStore;

/// The memory over the paper's feature stack (Descriptor, Matcher, Estimator,
/// Similarity; keyframe/selector.hpp).
template <Descriptor D, Matcher M, Estimator E, Similarity S>
class VisualMemory {
  // The store (memory/store.hpp) writes the file's sections apart: one row per key
  // image, link and loop edge, the rest as small rows; it joins them back into the
  // sections deserialize() reads.
  friend class MemoryStore;

 public:
  using Selector = KeyframeSelector<D, M, E, S>;
  /// The loop engine over the key images (32-bit key indices in the place database).
  using Engine = LoopEngine<M, E, BasicPlaceRanker<std::uint32_t>>;

  /// `vocabulary`: a vocabulary for the descriptors' kind (binary / float), or empty to
  /// learn one from the first MemoryOptions::vocabulary_after key images.
  explicit VisualMemory(D descriptor = D(), M matcher = M(), E estimator = E(), S similarity = S(),
                        const MemoryOptions& options = {}, AnyVocabulary vocabulary = {})
      : options_(checked(options)),
        policies_{detail::memory_policy_record(descriptor), detail::memory_policy_record(matcher),
                  detail::memory_policy_record(estimator), detail::memory_policy_record(similarity)},
        selector_(std::move(descriptor), std::move(matcher), std::move(estimator), std::move(similarity),
                  selector_options(options_)),
        vocabulary_(std::make_shared<const AnyVocabulary>(std::move(vocabulary))) {
    if (!options_.labels.order.empty()) labels_.schema = LabelSchema(options_.labels.order);
  }

  explicit VisualMemory(const MemoryOptions& options, AnyVocabulary vocabulary = {})
      : VisualMemory(D{}, M{}, E{}, S{}, options, std::move(vocabulary)) {}

  // Move-only: a copy would share the descriptor's detector (OrbDescriptor holds a
  // cv::Ptr<cv::ORB> with scratch buffers), so two copies used from two threads would
  // race. Two threads each load their own memory from the file instead.
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

  /// Pushes a bare image: its index is the number of frames pushed so far; the timestamp
  /// defaults to that index.
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
  /// (every key image while no vocabulary exists yet), the best `localize_candidates`
  /// verified, and the loop engine's place decision (loops.decision) over them: the
  /// key image it shows, or "unknown place" / "ambiguous" / "too little evidence" with the
  /// reason. `decision` overrides loops.decision for this query (e.g. another
  /// confidence threshold).
  [[nodiscard]] MemoryLocalization localize(const cv::Mat& image, const PlaceDecisionOptions* decision = nullptr) {
    detail::check(!image.empty(), "VisualMemory::localize: the query image is empty");
    MemoryLocalization out;
    const VisualMap& map = selector_.map();
    if (map.keys.empty()) return out;
    const Features q = selector_.front_end().descriptor().extract(image);
    if (q.empty()) {
      out.reason = "the query image has no features";
      return out;
    }
    const auto lookup = [this](std::size_t k) -> const Features& { return feature_ref(k); };
    PlaceDecision d;
    if (engine_) {
      d = engine_->localize(q, options_.localize_candidates, lookup, std::nullopt, decision);
    } else {
      // No vocabulary yet: every key image is verified, by an engine without a ranker.
      LoopOptions o = options_.loops;
      o.index = CandidateIndex::brute_force;
      const Engine all(selector_.front_end().matcher(), selector_.front_end().estimator(), o);
      d = all.localize(q, options_.localize_candidates, lookup, map.keys.size(), decision);
    }
    out.status = d.status;
    out.reason = d.reason;
    out.confidence = d.confidence;
    out.evidence = d.evidence;
    out.verified_candidates = d.verifications;
    out.relative_pose = d.verification.relative_pose;
    std::vector<std::pair<double, PlaceLink>> links;
    for (const PlaceCandidate& c : d.considered)
      if (c.stage == CandidateStage::chosen || c.stage == CandidateStage::weaker) {
        PlaceLink l;
        l.key = static_cast<std::uint32_t>(c.frame);
        l.bow_score = std::clamp(c.bow_score, 0.0, 1.0);
        l.status = VerificationStatus::verified;
        l.inliers = c.inliers;
        l.confidence = c.confidence;
        if (d.best && c.frame == *d.best) {
          l.fundamental = d.verification.model;
          l.matches = d.evidence.matches;
          l.similarity = selector_.front_end().similarity()(q, feature_ref(c.frame), d.verification);
        }
        links.emplace_back(c.stage == CandidateStage::chosen ? 2.0 : c.confidence, l);
      }
    std::stable_sort(links.begin(), links.end(), [](const auto& a, const auto& b) { return a.first > b.first; });
    for (auto& [rank, l] : links) out.matches.push_back(std::move(l));
    if (gcs_) out.position = gcs_->localize(q);
    return out;
  }

  /// Trains the GCS localizer on the key images that have an SE(2) pose (at least 3),
  /// from their own features (no second extraction): a BowHistogram vocabulary learned
  /// on them, the network (Trujillo-Romero 2024, Algorithm 1), a pose per neuron
  /// (Algorithm 4). localize() then also answers a position (Algorithm 5). Key images
  /// added later are not in it until train_gcs runs again. Deterministic (seeded).
  GcsTrainStats train_gcs(const MemoryGcsOptions& options = {}) {
    const VisualMap& map = selector_.map();
    std::vector<std::uint32_t> keys;
    std::vector<Features> features;
    std::vector<Pose2> poses;
    for (std::size_t k = 0; k < map.keys.size(); ++k)
      if (const auto* p = std::get_if<Pose2>(&poses_[k])) {
        keys.push_back(static_cast<std::uint32_t>(k));
        features.push_back(key_features(static_cast<std::uint32_t>(k)));
        poses.push_back(*p);
      }
    detail::check(keys.size() >= 3, "VisualMemory::train_gcs: " + std::to_string(keys.size()) +
                                        " key images have an SE(2) pose, the GCS needs at least 3");
    for (const Features& f : features)
      detail::check(f.descriptors.empty() || f.descriptors.type() == CV_8UC1,
                    "VisualMemory::train_gcs: the BowHistogram needs binary (CV_8UC1) descriptors, the key images "
                    "have " + cv::typeToString(f.descriptors.type()));
    BowHistogram histogram(options.histogram);
    PoseMapTraining<GcsXf> trained = train_pose_map<GcsXf>(histogram, options.gcs, features, poses);
    gcs_.emplace(MemoryGcs{options, std::move(histogram), std::move(trained.map), std::move(keys),
                           std::move(trained.winners)});
    ++gcs_generation_;
    return trained.gcs;
  }

  /// Whether a GCS was trained (train_gcs) or loaded with the memory.
  [[nodiscard]] bool has_gcs() const noexcept { return gcs_.has_value(); }
  /// The trained GCS and its pose per neuron; an Error without one.
  [[nodiscard]] const PoseMap<GcsXf>& gcs() const {
    detail::check(gcs_.has_value(), "VisualMemory::gcs: no GCS trained (call train_gcs first)");
    return gcs_->map;
  }
  /// The key images the GCS was trained on (ascending).
  [[nodiscard]] std::vector<std::uint32_t> gcs_keys() const { return gcs_ ? gcs_->keys : std::vector<std::uint32_t>{}; }

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
  /// searches every earlier session's key images whatever its window, and takes them
  /// as revisits (the camera left them: it was another run), so an accepted loop joins
  /// the sessions. A no-op before the first frame and right after another start_session.
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
  /// continues other's last session. The two must have the same options and policies,
  /// and other must hold its key images' features (not bounded): anything else is an
  /// Error naming both (`name`, `other_name`), and this memory is left as it was.
  void merge(VisualMemory&& other, const std::string& name = "the memory",
             const std::string& other_name = "the other memory") {
    const auto refuse = [&](const std::string& why) {
      detail::fail("cannot merge " + other_name + " into " + name + ": " + why);
    };
    if (other.frames() == 0) return;
    if (policies_ != other.policies_)
      refuse("they were made with other policies (" + policies_[0] + " against " + other.policies_[0] + ", ...)");
    if (options_bytes(options_.images) != other.options_bytes(other.options_.images) ||
        decision_options_bytes() != other.decision_options_bytes())
      refuse("they were made with other options (threshold, key images' storage, vocabulary, loop or decision options)");
    if (frames() > 0 && labels_.labelled != other.labels_.labelled)
      refuse(std::string("the frames of ") + (labels_.labelled ? name : other_name) +
             " came with detections, the other's without");
    if (other.released_ > 0) refuse(other_name + " holds only its working memory's features in RAM (load it whole)");
    if (pixels_unread_ || other.pixels_unread_) refuse("a memory was loaded without its key images' pixels");
    // Checked: from here on nothing refuses.

    const std::size_t m0 = key_images();
    const std::size_t f0 = frames();
    const std::size_t added = other.key_images();
    const std::size_t other_frames = other.frames();
    SelectorState<Features> state = other.selector_.pending_state();
    state.map = selector_.take_map();
    VisualMap theirs = other.selector_.take_map();
    for (std::size_t i = 0; i < added; ++i) {
      if (i > 0)
        state.map.pairs.push_back(theirs.pairs[i - 1]);
      else if (m0 > 0)
        state.map.pairs.push_back(KeyPair{});  // other's first session starts a chain here
      state.map.keys.push_back(std::move(theirs.keys[i]));
    }
    state.map.frames = f0 + other_frames;
    selector_.restore(std::move(state));
    if (m0 == 0) {
      sessions_.clear();
      labels_.labelled = other.labels_.labelled;
    } else if (sessions_.size() > 1 && sessions_.back().first_frame == f0) {
      sessions_.pop_back();  // a session started here and never pushed into: other's first takes its place
    }
    for (const MemorySession& s : other.sessions_) sessions_.push_back({s.first_key + m0, s.first_frame + f0});
    poses_.insert(poses_.end(), other.poses_.begin(), other.poses_.end());
    const auto& theirs_detections = other.labels_.key_detections;
    labels_.key_detections.insert(labels_.key_detections.end(), theirs_detections.begin(),
                                  theirs_detections.end());
    previous_pose_ = other.previous_pose_;
    labels_.previous_detections = other.labels_.previous_detections;
    last_index_ = other.last_index_;
    if (sessions_.back().first_key == key_images()) selector_.start_chain();
    for (std::size_t k = m0; k < key_images(); ++k) {
      std::vector<LoopEdge> found;
      on_new_key(static_cast<std::uint32_t>(k), found);
    }
  }

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
  /// Whether the camera never left its place (LoopEngine::stationary); false before the
  /// loop detection runs.
  [[nodiscard]] bool stationary() const { return engine_ && engine_->stationary(); }
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
  /// similarity): name and options, "" for a policy that does not describe itself (file "plcy").
  [[nodiscard]] const std::array<std::string, 4>& policy_records() const noexcept { return policies_; }

  // ---- working memory ---------------------------------------------------------------

  /// Reads key image k's features where the memory no longer holds them in RAM (e.g.
  /// MemoryStore::features(): the store the memory is synced into).
  using KeyFeatureSource = std::function<Features(std::uint32_t key)>;

  /// Bounds the features held in RAM to the `working_memory` (>= 1) most recent key
  /// images: release_features() then drops older key images' features, which are read
  /// through `source` when a loop or localization candidate is verified, for
  /// train_gcs() and for save(). What ranking needs stays in RAM (each key image's bag of
  /// words in the place database, its detections, pose and links), so the answers are
  /// the same as with every key image's features held. map() shows released key images
  /// without keypoints or descriptors. MemoryStore::sync releases them once stored.
  void bound_features(std::size_t working_memory, KeyFeatureSource source) {
    detail::check(working_memory >= 1, "VisualMemory::bound_features: the working memory must hold at least 1 key image");
    detail::check(static_cast<bool>(source), "VisualMemory::bound_features: no source of released features");
    working_memory_ = working_memory;
    source_ = std::move(source);
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
  [[nodiscard]] Features key_features(std::uint32_t k) const {
    const std::size_t m = key_images();
    detail::check(k < m, [&] { return "VisualMemory::key_features: key " + std::to_string(k) + " of " + std::to_string(m); });
    if (holds_features(k)) return selector_.map().keys[k].features;
    Features f = source_(k);
    const Features& kept = selector_.map().keys[k].features;  // released: its norm and image size remain
    detail::check(f.norm == kept.norm && f.image_size == kept.image_size, [&] {
      return "VisualMemory: the features read for key image " + std::to_string(k) +
             " are not that key image's (another norm or image size)";
    });
    return f;
  }

  /// The memory file's bytes (format: examples/memory.md, "The single-file format"). `images` overrides
  /// MemoryOptions::images for this file (e.g. none for a small copy; png or jpeg store
  /// only the pixels the memory kept).
  [[nodiscard]] std::string serialize(std::optional<ImageStorage> images = {}) const {
    const ImageStorage storage = images.value_or(options_.images);
    check_pixels_read(storage, "VisualMemory::serialize");
    return file_bytes({options_bytes(storage), keys_bytes(storage), links_bytes(), loops_bytes(),
                       selector_bytes(storage, detail::ScoreDegeneracy::complete), vocabulary_bytes(),
                       database_section(engine_ ? database().serialize()
                                                : PlaceDatabase<std::uint32_t>(vocabulary_->size(), options_.scoring)
                                                      .serialize()),
                       policies_bytes(), labels_bytes(), gcs_bytes(), decision_bytes(), sessions_bytes()});
  }

  /// Writes the memory atomically (temporary file, fsync, rename, fsync of the folder):
  /// a crash during save leaves the previous file as it was.
  void save(const std::filesystem::path& path, std::optional<ImageStorage> images = {}) const {
    write_file_atomically(path, serialize(images));
  }

  /// Parses a memory file's bytes; the policies are the caller's (their options are not
  /// in the file), the options are the file's. Anything invalid is a vmap::Error naming
  /// the file and the section.
  /// `limits` bound the key images' pixels (each, and all together, checked before any
  /// is decoded): the most pixels a memory file can make the reader allocate.
  [[nodiscard]] static VisualMemory deserialize(std::string_view bytes, const std::string& name = "<memory>",
                                                D descriptor = D(), M matcher = M(), E estimator = E(),
                                                S similarity = S(), const MapLoadOptions& limits = {}) {
    detail::BinaryReader file(bytes, "memory file '" + name + "'");
    if (bytes.size() < 16) file.corrupt("header: too short (" + std::to_string(bytes.size()) + " bytes)");
    if (file.bytes(8, "magic") != std::string_view(detail::memory_magic, 8))
      file.corrupt("header: not a vmap memory (wrong magic bytes)");
    const std::uint32_t version = file.u32("version");
    if (version < 1 || version > memory_format_version)
      file.corrupt("header: format version " + std::to_string(version) + " is not supported (this build reads 1 to " +
                   std::to_string(memory_format_version) + ")");
    const std::uint32_t sections = version == 1   ? detail::memory_sections_v1
                                   : version == 2 ? detail::memory_sections_v2
                                   : version == 3 ? detail::memory_sections_v3
                                                  : detail::memory_sections;
    if (const std::uint32_t n = file.u32("section count"); n != sections)
      file.corrupt("header: " + std::to_string(n) + " sections, expected " + std::to_string(sections) +
                   " in version " + std::to_string(version));

    auto opts = detail::memory_open_section(file, "opts");
    const MemoryOptions options = read_options(opts, version);
    VisualMemory mem(std::move(descriptor), std::move(matcher), std::move(estimator), std::move(similarity), options);

    SelectorState<Features> state;
    std::uint64_t total_pixels = 0;
    auto keys = detail::memory_open_section(file, "keys");
    const std::uint64_t frames = keys.u64("frame count");
    if (frames > detail::memory_max_frames)
      keys.corrupt("frame count " + std::to_string(frames) + " is more than a memory can hold (2^40)");
    state.map.frames = static_cast<std::size_t>(frames);
    const std::uint32_t m = keys.u32("key image count");
    keys.require_items(m, 50, "key image count");
    if (m > state.map.frames) keys.corrupt(std::to_string(m) + " key images for " + std::to_string(state.map.frames) + " frames");
    for (std::uint32_t i = 0; i < m; ++i) {
      KeyImage k = read_key(keys, limits, total_pixels, &mem.pixels_unread_);
      mem.check_layout(keys, k.features, [&] { return "key image " + std::to_string(i); });
      state.map.keys.push_back(std::move(k));
      mem.poses_.push_back(detail::memory_read_pose(keys));
    }
    keys.expect_end("the last key image");

    auto links = detail::memory_open_section(file, "link");
    const std::uint32_t p = links.u32("pair count");
    if (p != (m == 0 ? 0U : m - 1U)) links.corrupt("pair count " + std::to_string(p) + " for " + std::to_string(m) + " key images");
    for (std::uint32_t i = 0; i < p; ++i)
      state.map.pairs.push_back(detail::read_key_pair(links, "verification status"));
    links.expect_end("the last pair");

    auto loops = detail::memory_open_section(file, "loop");
    const std::uint32_t e = loops.u32("loop edge count");
    loops.require_items(e, 8 + 97, "loop edge count");
    for (std::uint32_t i = 0; i < e; ++i) {
      LoopEdge edge;
      edge.from = loops.u32("loop from");
      edge.link.key = loops.u32("loop to");
      if (edge.from >= m || edge.link.key >= edge.from) loops.corrupt("loop edge between invalid key images");
      edge.link = with_key(detail::memory_read_link(loops), edge.link.key);
      mem.loops_.push_back(edge);
    }
    loops.expect_end("the last loop edge");

    auto sel = detail::memory_open_section(file, "selc");
    const std::uint8_t has_prev = sel.u8("previous frame flag");
    if (has_prev > 1) sel.corrupt("previous frame flag is not 0 or 1");
    if (has_prev == 1) {
      if (m == 0) sel.corrupt("a previous frame without a key image");
      PreparedFrame<Features> prev;
      KeyImage k = read_key(sel, limits, total_pixels, &mem.pixels_unread_);
      mem.check_layout(sel, k.features, [] { return std::string("the previous frame"); });
      if (k.frame_index <= state.map.keys.back().frame_index) sel.corrupt("previous frame is not after the key image");
      prev.item = std::move(k.features);
      prev.index = k.frame_index;
      prev.name = std::move(k.name);
      prev.timestamp = k.timestamp;
      prev.image = std::move(k.image);
      state.previous = std::move(prev);
      mem.previous_pose_ = detail::memory_read_pose(sel);
    }
    detail::read_previous_score(sel, state);
    const std::uint8_t has_last = sel.u8("last frame flag");
    if (has_last > 1 || (has_last == 0 && m > 0)) sel.corrupt("invalid last frame flag");
    if (has_last == 1) {
      const std::uint64_t last = sel.u64("last frame index");
      if (last > detail::memory_max_frames) sel.corrupt("last frame index " + std::to_string(last) + " is above 2^40");
      mem.last_index_ = static_cast<std::size_t>(last);
      const std::size_t at_least = state.previous ? state.previous->index : (m > 0 ? state.map.keys.back().frame_index : 0);
      if (*mem.last_index_ < at_least) sel.corrupt("the last frame index is before the selector's frames");
    }
    sel.expect_end("the selector state");

    auto voc = detail::memory_open_section(file, "voca");
    const std::uint8_t has_voc = voc.u8("vocabulary flag");
    if (has_voc > 1) voc.corrupt("vocabulary flag is not 0 or 1");
    if (has_voc == 1) {
      const std::uint64_t len = voc.u64("vocabulary length");
      const std::string_view vb = voc.bytes(len, "vocabulary");
      mem.vocabulary_ =
          std::make_shared<const AnyVocabulary>(AnyVocabulary::deserialize(vb, voc.source() + " vocabulary"));
    }
    voc.expect_end("the vocabulary");

    auto db = detail::memory_open_section(file, "plcd");
    const std::uint64_t dlen = db.u64("database length");
    PlaceDatabase<std::uint32_t> database =
        PlaceDatabase<std::uint32_t>::deserialize(db.bytes(dlen, "database"), db.source() + " database");
    db.expect_end("the database");

    if (database.scoring() != options.scoring || database.words() != mem.vocabulary_->size())
      detail::fail(db.source() + ": the database does not match the vocabulary or the scoring");
    {
      // The database holds the key images checked for loops: 0 .. n-1, in order.
      const auto ids = database.ids();
      for (std::size_t i = 0; i < ids.size(); ++i)
        if (ids[i] != i || ids[i] >= m) detail::fail(db.source() + ": image id " + std::to_string(ids[i]) + " is not key image " + std::to_string(i));
    }
    mem.labels_.key_detections.assign(m, {});
    if (version >= 2) {
      auto plcy = detail::memory_open_section(file, "plcy");
      mem.read_policies(plcy);
      auto labl = detail::memory_open_section(file, "labl");
      mem.labels_ = MemoryLabels::read(labl, mem.options_, m, has_prev == 1,
                                       [](const MemoryOptions& o) { return checked(o); });
      auto gcsl = detail::memory_open_section(file, "gcsl");
      mem.read_gcs(gcsl);
    }
    LoopEngineState engine_state;
    if (version >= 3) {
      auto dcsn = detail::memory_open_section(file, "dcsn");
      engine_state = mem.read_decision(dcsn, database.size());
    }
    if (version >= 4) {
      auto sess = detail::memory_open_section(file, "sess");
      mem.read_sessions(sess, m, state.map.frames);
    }
    if (!file.at_end()) file.corrupt(std::to_string(file.remaining()) + " unexpected bytes after the last section");
    // Frame indices increase within a session (each run numbers its own frames).
    for (std::size_t i = 1; i < m; ++i)
      if (!mem.starts_session(i) && state.map.keys[i].frame_index <= state.map.keys[i - 1].frame_index)
        detail::fail(file.source() + " section 'keys': key image frame indices are not increasing within a session "
                                     "(key image " + std::to_string(i) + ")");
    if (!database.empty()) {
      if (!mem.detecting()) detail::fail(db.source() + ": key images checked for loops without a label schema");
      mem.start_engine(std::move(database));
      std::vector<LabelVector> labels;
      for (std::size_t k = 0; k < mem.engine_->ranker().database().size(); ++k) labels.push_back(mem.label_vector(k));
      try {
        // The session of the last key image checked: as the engine was when it checked it.
        const std::size_t last_checked = mem.engine_->ranker().database().size() - 1;
        const std::size_t session_start = mem.sessions_[mem.session_of_key(last_checked)].first_key;
        mem.engine_->restore(std::move(labels), engine_state, session_start);
      } catch (const Error& err) {
        detail::fail(file.source() + " section 'dcsn': " + err.what());
      }
    }
    mem.selector_.restore(std::move(state));
    if (m > 0 && mem.sessions_.back().first_key == m) mem.selector_.start_chain();  // a session started, no frame yet
    return mem;
  }

  [[nodiscard]] static VisualMemory load(const std::filesystem::path& path, D descriptor = D(), M matcher = M(),
                                         E estimator = E(), S similarity = S(), const MapLoadOptions& limits = {}) {
    return deserialize(read_file(path, limits.max_file_bytes, "memory file"), path.string(), std::move(descriptor),
                       std::move(matcher), std::move(estimator), std::move(similarity), limits);
  }

 private:
  static MemoryOptions checked(MemoryOptions o) {
    detail::check(o.vocabulary_after >= 1, "MemoryOptions.vocabulary_after must be >= 1");
    detail::check(o.localize_candidates >= 1, "MemoryOptions.localize_candidates must be >= 1");
    Engine::check_options(o.loops, "MemoryOptions.loops");
    detail::check(o.loops.top_k >= 1, "MemoryOptions.loops.top_k must be >= 1");
    detail::check(o.jpeg_quality >= 1 && o.jpeg_quality <= 100, "MemoryOptions.jpeg_quality must be in 1..100, got " +
                                                                    std::to_string(o.jpeg_quality));
    detail::check(o.images <= ImageStorage::jpeg, "MemoryOptions.images is not a known ImageStorage");
    const MemoryLabelOptions& l = o.labels;
    detail::check_influence_options(l.influence);
    detail::check(l.sample >= 1, "MemoryOptions.labels.sample must be >= 1");
    detail::check(uses_labels(o.loops.index), "MemoryOptions.loops.index must be tree or tree_ranked (the source "
                                              "with detections), got " + std::string(to_string(o.loops.index)));
    try {
      (void)LabelSchema(l.order);
    } catch (const Error& e) {
      detail::fail(std::string("MemoryOptions.labels.order: ") + e.what());
    }
    o.selector.keep_images = o.images != ImageStorage::none;
    return o;
  }

  static Frame bare_frame(const cv::Mat& image, std::optional<double> timestamp, std::size_t index) {
    Frame f;
    f.image = image;
    f.index = index;
    f.name = "frame#" + std::to_string(f.index);
    f.timestamp = timestamp.value_or(static_cast<double>(f.index));
    f.time_ns = nanoseconds_from_seconds(f.timestamp);
    return f;
  }

  Frame bare_frame(const cv::Mat& image, std::optional<double> timestamp) const {
    return bare_frame(image, timestamp, frames());
  }

  MemoryStep push_frame(const Frame& frame, const OdometryPose& pose, const std::vector<Detection>* detections) {
    const bool with = detections != nullptr;
    if (!last_index_) {
      labels_.labelled = with;  // the first frame decides
    } else if (with != labels_.labelled) {
      detail::fail("VisualMemory::push: frame " + std::to_string(frame.index) +
                   (with ? " comes with detections, but the memory's frames had none"
                         : " comes without detections, but the memory's frames had them (give an empty list when "
                           "nothing was detected)"));
    }
    // Scores are checked before anything changes, so a bad detection leaves the memory as it was.
    if (with) (void)present_labels(*detections, options_.loops.labels.min_score);
    MemoryStep step;
    step.frame = selector_.push(frame);
    after_push(step, frame.index, pose, detections);
    return step;
  }

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

  static SelectorOptions selector_options(const MemoryOptions& o) { return o.selector; }

  static PlaceLink with_key(PlaceLink l, std::uint32_t key) {
    l.key = key;
    return l;
  }

  void after_push(MemoryStep& step, std::size_t index, const OdometryPose& pose,
                  const std::vector<Detection>* detections) {
    const FrameResult& r = step.frame;
    static const std::vector<Detection> none;
    const std::vector<Detection>& current = detections ? *detections : none;
    if (r.key_taken) {
      // Eq. 6 takes I_{j-1}: its pose and detections are the ones pushed with it.
      const bool this_frame = *r.key_frame == index;
      poses_.push_back(this_frame ? pose : previous_pose_);
      labels_.key_detections.push_back(this_frame ? current : labels_.previous_detections);
      step.new_key = static_cast<std::uint32_t>(key_images() - 1);
      on_new_key(*step.new_key, step.loops);
    }
    previous_pose_ = pose;
    labels_.previous_detections = current;
    last_index_ = index;
  }

  /// Adds key image `key` to the place database and detects its loops; learns the
  /// vocabulary once enough key images exist (and, with detections, fixes the label
  /// schema after the sample), then catches up with the earlier ones in order.
  void on_new_key(std::uint32_t key, std::vector<LoopEdge>& found) {
    const auto& keys = selector_.map().keys;
    // Key images 0 .. key count (merge() appends later ones before it checks these).
    const std::size_t known = std::size_t{key} + 1;
    sample_schema(known);
    if (vocabulary_->empty()) {
      if (known < options_.vocabulary_after) return;
      std::vector<cv::Mat> sets;
      for (std::size_t k = 0; k < known; ++k)
        sets.push_back(holds_features(k) ? keys[k].features.descriptors : key_features(static_cast<std::uint32_t>(k)).descriptors);
      std::size_t rows = 0;
      for (const auto& d : sets) rows += static_cast<std::size_t>(d.rows);
      // Too few descriptors to split into `branching` words (blank frames): try again
      // at the next key image.
      if (rows < static_cast<std::size_t>(std::max(options_.vocabulary.branching, 1))) return;
      vocabulary_ = std::make_shared<const AnyVocabulary>(AnyVocabulary::learn(sets, options_.vocabulary));
    }
    if (!detecting()) return;
    if (!engine_) start_engine(PlaceDatabase<std::uint32_t>(vocabulary_->size(), options_.scoring));
    // The engine holds exactly the key images already checked, in order.
    const auto lookup = [this](std::size_t k) -> const Features& { return feature_ref(k); };
    for (std::size_t k = engine_->frames(); k <= key; ++k) {
      // A query the working memory no longer holds (a catch-up after the label sample)
      // is read once and kept here: the lookup's own copy is replaced at its next read.
      if (k > 0 && starts_session(k)) engine_->begin_session();
      std::optional<Features> read;
      const Features& query = holds_features(k) ? keys[k].features : read.emplace(key_features(static_cast<std::uint32_t>(k)));
      const PlaceDecision d = engine_->add(query, label_vector(k), lookup);
      if (!d.accepted()) continue;
      PlaceLink l;
      l.key = static_cast<std::uint32_t>(*d.best);
      l.bow_score = std::clamp(d.evidence.bow_score, 0.0, 1.0);
      l.status = d.verification.status;
      l.fundamental = d.verification.model;
      l.matches = d.evidence.matches;
      l.inliers = d.evidence.inliers;
      l.similarity = selector_.front_end().similarity()(query, feature_ref(*d.best), d.verification);
      l.confidence = d.confidence;
      loops_.push_back({static_cast<std::uint32_t>(k), l});
      found.push_back(loops_.back());
    }
  }

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

  // ---- file sections ------------------------------------------------------------

  /// The file of the current version from its 12 sections' bytes, in the order of the
  /// format (examples/memory.md, "The single-file format").
  static std::string file_bytes(const std::array<std::string, detail::memory_sections>& sections) {
    static constexpr const char tags[detail::memory_sections][5] = {"opts", "keys", "link", "loop", "selc", "voca",
                                                                    "plcd", "plcy", "labl", "gcsl", "dcsn", "sess"};
    detail::MemorySectionWriter s;
    for (std::size_t i = 0; i < sections.size(); ++i) s.add(tags[i], sections[i]);
    detail::BinaryWriter h;
    h.bytes(detail::memory_magic, 8);
    h.u32(memory_format_version);
    h.u32(detail::memory_sections);
    h.bytes(s.out_.data());
    return std::move(h).take();
  }

  /// "sess": the sessions after the first (which starts at key image 0 and frame 0).
  std::string sessions_bytes() const {
    detail::BinaryWriter w;
    w.u32(static_cast<std::uint32_t>(sessions_.size() - 1));
    for (std::size_t i = 1; i < sessions_.size(); ++i) {
      w.u64(sessions_[i].first_key);
      w.u64(sessions_[i].first_frame);
    }
    return std::move(w).take();
  }

  /// Reads "sess" for a memory of `m` key images and `frames` frames: each session
  /// starts after the one before, at or before the end.
  void read_sessions(detail::BinaryReader& r, std::size_t m, std::size_t frames) {
    const std::uint32_t n = r.u32("session count");
    r.require_items(n, 16, "session count");
    sessions_.assign(1, MemorySession{});
    for (std::uint32_t i = 0; i < n; ++i) {
      MemorySession s;
      s.first_key = static_cast<std::size_t>(r.u64("session's first key image"));
      s.first_frame = static_cast<std::size_t>(r.u64("session's first frame"));
      const MemorySession& before = sessions_.back();
      // The first frame of a session is a key image, so every session but the last
      // holds one; the last holds none only while no frame was pushed into it.
      if (s.first_key <= before.first_key || s.first_frame <= before.first_frame || s.first_key > m ||
          s.first_frame > frames || (s.first_key == m) != (s.first_frame == frames))
        r.corrupt("session " + std::to_string(i + 1) + " does not start after session " + std::to_string(i) +
                  " (key image " + std::to_string(s.first_key) + ", frame " + std::to_string(s.first_frame) + ")");
      sessions_.push_back(s);
    }
    r.expect_end("the sessions");
  }

  std::string vocabulary_bytes() const {
    detail::BinaryWriter v;
    v.u8(vocabulary_->empty() ? 0 : 1);
    if (!vocabulary_->empty()) {
      const std::string bytes = vocabulary_->serialize();
      v.u64(bytes.size());
      v.bytes(bytes);
    }
    return std::move(v).take();
  }

  /// "plcd" around a place database file's bytes.
  static std::string database_section(std::string_view database_file) {
    detail::BinaryWriter d;
    d.u64(database_file.size());
    d.bytes(database_file);
    return std::move(d).take();
  }

  std::string options_bytes(ImageStorage storage) const {
    static_assert(detail::field_count<MemoryOptions>() == 9,
                  "a new MemoryOptions field must be written here (or by its part's codec) and read by read_options");
    const MemoryOptions& o = options_;
    detail::BinaryWriter w;
    detail::write_selector_options(w, o.selector);
    w.u8(static_cast<std::uint8_t>(storage));
    w.i32(o.jpeg_quality);
    w.u64(o.vocabulary_after);
    detail::write_vocabulary_tree_options(w, o.vocabulary);
    w.u8(static_cast<std::uint8_t>(o.scoring));
    detail::write_loop_search_options(w, o.loops);
    w.u64(o.localize_candidates);
    w.i32(o.loops.decision.min_inliers);  // where version 2 kept a second floor
    return std::move(w).take();
  }

  /// "opts": the selector's, the vocabulary's and the loop search's options by their
  /// parts' codecs, with the memory's own; the decision's are in "dcsn" and the labels'
  /// in "labl".
  static MemoryOptions read_options(detail::BinaryReader& r, std::uint32_t version) {
    MemoryOptions o;
    o.selector = detail::read_selector_options(r);
    const std::uint8_t images = r.u8("image storage");
    if (images > 2) r.corrupt("unknown image storage " + std::to_string(images));
    o.images = static_cast<ImageStorage>(images);
    o.jpeg_quality = r.i32("jpeg quality");
    o.vocabulary_after = static_cast<std::size_t>(r.u64("vocabulary_after"));
    o.vocabulary = detail::read_vocabulary_tree_options(r);
    const std::uint8_t scoring = r.u8("scoring");
    if (scoring > 2) r.corrupt("unknown scoring " + std::to_string(scoring));
    o.scoring = static_cast<BowScoring>(scoring);
    detail::read_loop_search_options(r, o.loops);
    o.localize_candidates = static_cast<std::size_t>(r.u64("localize_candidates"));
    // Version 2 had a separate floor for localization; version 3 one floor for both.
    if (const int again = r.i32("min_localize_inliers"); version >= 3 && again != o.loops.decision.min_inliers)
      r.corrupt("the two inlier floors differ");
    r.expect_end("the options");
    try {
      return checked(o);
    } catch (const Error& e) {
      r.corrupt(e.what());
    }
  }

  void write_key(detail::BinaryWriter& w, std::size_t index, double timestamp, const std::string& name,
                 const Features& f, const cv::Mat& image, ImageStorage storage) const {
    w.u64(index);
    w.f64(timestamp);
    w.str(name, detail::map_max_string, "VisualMemory::save: a key image name");
    detail::write_features(w, f);
    detail::write_memory_image(w, image, storage, options_.jpeg_quality);
  }

  /// Features read from a file against the layout of the descriptor given to load
  /// (core/concepts.hpp, StatesLayout), so that key images holding other descriptors (a
  /// memory built with a descriptor that does not describe itself, or a crafted file)
  /// are refused when the memory loads, not when they are first matched.
  template <class What>
  void check_layout(detail::BinaryReader& r, const Features& f, const What& what) const {
    if constexpr (StatesLayout<D>) {
      if (f.descriptors.empty()) return;
      const DescriptorLayout want = selector_.front_end().descriptor().layout();
      if (const DescriptorLayout got = layout_of(f); got != want)
        r.corrupt(what() + " has descriptors of " + to_string(got) + ", the descriptor given to load makes " +
                  to_string(want));
    }
  }

  static KeyImage read_key(detail::BinaryReader& r, const MapLoadOptions& limits, std::uint64_t& total_pixels,
                           bool* pixels_skipped) {
    KeyImage k;
    k.frame_index = static_cast<std::size_t>(r.u64("frame index"));
    k.timestamp = r.f64("timestamp");
    k.name = r.str("name", detail::map_max_string);
    k.features = detail::read_features(r);
    k.image = detail::read_memory_image(r, limits, total_pixels, pixels_skipped);
    return k;
  }

  /// Key image i as "keys" holds it: the key image, then its pose.
  void write_key_record(detail::BinaryWriter& w, std::size_t i, ImageStorage storage) const {
    const KeyImage& k = selector_.map().keys[i];
    if (holds_features(i))
      write_key(w, k.frame_index, k.timestamp, k.name, k.features, k.image, storage);
    else
      write_key(w, k.frame_index, k.timestamp, k.name, key_features(static_cast<std::uint32_t>(i)), k.image, storage);
    detail::memory_write_pose(w, poses_[i]);
  }

  std::string keys_bytes(ImageStorage storage) const {
    const VisualMap& map = selector_.map();
    detail::BinaryWriter w;
    w.u64(map.frames);
    w.u32(static_cast<std::uint32_t>(map.keys.size()));
    for (std::size_t i = 0; i < map.keys.size(); ++i) write_key_record(w, i, storage);
    return std::move(w).take();
  }

  /// Link i (key image i to i + 1) as "link" holds it.
  void write_link_record(detail::BinaryWriter& w, std::size_t i) const {
    detail::write_key_pair(w, selector_.map().pairs[i]);
  }

  std::string links_bytes() const {
    detail::BinaryWriter w;
    const auto& pairs = selector_.map().pairs;
    w.u32(static_cast<std::uint32_t>(pairs.size()));
    for (std::size_t i = 0; i < pairs.size(); ++i) write_link_record(w, i);
    return std::move(w).take();
  }

  /// Loop edge i as "loop" holds it (its confidence is in "dcsn").
  void write_loop_record(detail::BinaryWriter& w, std::size_t i) const {
    const LoopEdge& e = loops_[i];
    w.u32(e.from);
    w.u32(e.link.key);
    detail::memory_write_link(w, e.link);
  }

  std::string loops_bytes() const {
    detail::BinaryWriter w;
    w.u32(static_cast<std::uint32_t>(loops_.size()));
    for (std::size_t i = 0; i < loops_.size(); ++i) write_loop_record(w, i);
    return std::move(w).take();
  }

  /// "selc". The store writes it at every sync with the score's degeneracy test left
  /// deferred (flag 2, with the inlier mask that completes it); a file saved whole
  /// completes it (flag 1).
  std::string selector_bytes(ImageStorage storage, detail::ScoreDegeneracy degeneracy) const {
    const SelectorState<Features> s =
        degeneracy == detail::ScoreDegeneracy::deferred ? selector_.deferred_state() : selector_.pending_state();
    detail::BinaryWriter w;
    w.u8(s.previous ? 1 : 0);
    if (s.previous) {
      const auto& p = *s.previous;
      write_key(w, p.index, p.timestamp, p.name, p.item, p.image, storage);
      detail::memory_write_pose(w, previous_pose_);
    }
    detail::write_previous_score(w, s);
    w.u8(last_index_ ? 1 : 0);
    if (last_index_) w.u64(*last_index_);
    return std::move(w).take();
  }

  std::string policies_bytes() const {
    detail::BinaryWriter w;
    for (const std::string& p : policies_) w.str(p, detail::memory_max_policy, "VisualMemory::save: a policy record");
    return std::move(w).take();
  }

  void read_policies(detail::BinaryReader& r) const {
    static constexpr const char* roles[4] = {"descriptor", "matcher", "estimator", "similarity"};
    for (std::size_t i = 0; i < 4; ++i) {
      // A policy that did not describe itself when the memory was made recorded nothing,
      // so there is nothing to contradict the one given now.
      const std::string recorded = r.str("policy record", detail::memory_max_policy);
      if (!recorded.empty() && recorded != policies_[i])
        detail::fail(r.source() + ": the " + roles[i] + " given to load (" +
                     (policies_[i].empty() ? std::string("not recorded") : policies_[i]) +
                     ") is not the one the memory was built with (" +
                     (recorded.empty() ? std::string("not recorded") : recorded) + ")");
    }
    r.expect_end("the policies");
  }

  /// "labl" up to the key images' detections (the store writes their rows apart).
  std::string labels_head_bytes() const { return labels_.head_bytes(options_); }

  /// Whether the selector holds an I_{j-1} (not when the last frame is the last key
  /// image): only then can a later key image be that frame, and its detections are kept.
  bool holds_previous_frame() const {
    const auto& keys = selector_.map().keys;
    return last_index_ && !(!keys.empty() && keys.back().frame_index == *last_index_);
  }

  /// "labl"'s last part: the detections of I_{j-1} (MemoryLabels::previous_bytes).
  std::string previous_detections_bytes() const { return labels_.previous_bytes(holds_previous_frame()); }

  std::string labels_bytes() const { return labels_.bytes(options_, holds_previous_frame()); }

  /// The decision's options, as "dcsn" begins (lcd/loop_engine.hpp).
  std::string decision_options_bytes() const {
    detail::BinaryWriter w;
    detail::write_decision_options(w, options_.loops);
    return std::move(w).take();
  }

  /// "dcsn" without the loop edges' confidences: the decision's options and the loop
  /// engine's state (LoopEngineState; zero before the engine runs).
  std::string decision_head_bytes() const {
    detail::BinaryWriter w;
    w.bytes(decision_options_bytes());
    if (engine_)
      engine_->state().write(w);
    else
      LoopEngineState{}.write(w);
    return std::move(w).take();
  }

  std::string decision_bytes() const {
    detail::BinaryWriter w;
    w.bytes(decision_head_bytes());
    w.u32(static_cast<std::uint32_t>(loops_.size()));
    for (const LoopEdge& e : loops_) w.f64(e.link.confidence);
    return std::move(w).take();
  }

  /// Reads "dcsn": the decision's options (checked with the rest), the engine's state and
  /// the loop edges' confidences; `checked_keys` is the number of key images the
  /// database holds.
  LoopEngineState read_decision(detail::BinaryReader& r, std::size_t checked_keys) {
    MemoryOptions all = options_;
    detail::read_decision_options(r, all.loops);
    try {
      options_ = checked(all);
    } catch (const Error& e) {
      r.corrupt(e.what());
    }
    LoopEngineState s = LoopEngineState::read(r, checked_keys);
    const std::uint32_t e = r.u32("loop edge count");
    if (e != loops_.size())
      r.corrupt(std::to_string(e) + " confidences for " + std::to_string(loops_.size()) + " loop edges");
    r.require_items(e, 8, "loop edge count");
    for (LoopEdge& edge : loops_) {
      edge.link.confidence = r.f64("loop confidence");
      if (!(edge.link.confidence >= 0.0 && edge.link.confidence <= 1.0)) r.corrupt("a loop confidence outside [0, 1]");
    }
    r.expect_end("the decision");
    return s;
  }

  /// "gcsl": a flag, then the trained GCS (MemoryGcs::bytes).
  std::string gcs_bytes() const {
    detail::BinaryWriter w;
    w.u8(gcs_ ? 1 : 0);
    if (gcs_) w.bytes(gcs_->bytes());
    return std::move(w).take();
  }

  /// Reads "gcsl" for the key images' poses (read before it, from "keys").
  void read_gcs(detail::BinaryReader& r) {
    const std::uint8_t has = r.u8("GCS flag");
    if (has > 1) r.corrupt("GCS flag is not 0 or 1");
    if (has == 0) {
      r.expect_end("the GCS flag");
      return;
    }
    gcs_.emplace(MemoryGcs::read(r, poses_));
  }

  /// A memory loaded without decoding its pixels (MapLoadOptions::decode_images) cannot
  /// write them: refused, so that no file loses the pixels it had.
  void check_pixels_read(ImageStorage storage, const char* who) const {
    if (pixels_unread_ && storage != ImageStorage::none)
      detail::fail(std::string(who) + ": the memory was loaded without its key images' pixels "
                   "(MapLoadOptions::decode_images = false) and cannot write them; write it with ImageStorage::none, "
                   "or load it with its pixels");
  }

  /// Key image k's features for a verification: held, or read into `read_`, so the
  /// reference is valid until the next read of a released key image.
  const Features& feature_ref(std::size_t k) {
    if (holds_features(k)) return selector_.map().keys[k].features;
    if (!read_ || read_->first != k) read_.emplace(k, key_features(static_cast<std::uint32_t>(k)));
    return read_->second;
  }

  MemoryOptions options_;
  std::array<std::string, 4> policies_;  ///< detail::memory_policy_record of each policy
  Selector selector_;
  std::shared_ptr<const AnyVocabulary> vocabulary_;  ///< never null (empty before one is learned)
  std::optional<Engine> engine_;                     ///< once loop detection runs (detecting())
  std::vector<LoopEdge> loops_;
  std::vector<OdometryPose> poses_;  ///< per key image
  OdometryPose previous_pose_;       ///< of the last pushed frame (eq. 6's I_{j-1})
  std::optional<std::size_t> last_index_;
  MemoryLabels labels_;  ///< the frames' object labels (LFM-LCD)
  std::optional<MemoryGcs> gcs_;  ///< once train_gcs ran (or loaded)
  std::uint64_t gcs_generation_ = 0;  ///< counts train_gcs calls (a store rewrites the GCS when it changes)
  std::size_t working_memory_ = 0;    ///< bound_features (0: unbounded)
  KeyFeatureSource source_;           ///< where released features are read
  std::size_t released_ = 0;          ///< key images 0 .. released_ - 1 hold no features in RAM
  std::optional<std::pair<std::size_t, Features>> read_;  ///< the last released key image read (feature_ref)
  bool pixels_unread_ = false;  ///< loaded with MapLoadOptions::decode_images false, and pixels were left undecoded
  std::vector<MemorySession> sessions_{MemorySession{}};  ///< never empty: the first starts at 0
};

// Named stacks: the paper's ORB 1000 + mutual NN + MAGSAC++ + eq. 5, and A-KAZE / SIFT.
using OrbVisualMemory = VisualMemory<OrbDescriptor, BruteForceMatcher, FundamentalEstimator, InlierRatio>;
using AkazeVisualMemory = VisualMemory<AkazeDescriptor, BruteForceMatcher, FundamentalEstimator, InlierRatio>;
using SiftVisualMemory = VisualMemory<SiftDescriptor, BruteForceMatcher, FundamentalEstimator, InlierRatio>;

}  // namespace vmap