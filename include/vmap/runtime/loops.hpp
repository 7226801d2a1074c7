#pragma once

// The offline loop run over a whole sequence (`vmap loops`, the Python module's
// detect_loops, the loop benchmark) and its evaluation, beside the threshold sweep of the
// key images (keyframe/sweep.hpp):
//
//   features of every frame, extracted once (extract_features, progress (done, total))
//   -> labels from files or an object detector (load_labels, detect_labels)
//   -> the label schema from a sample of them (eq. 5's influence band, lcd/influence.hpp)
//   -> a vocabulary for the ranked candidate sources: a file, or learned on the sequence
//      itself (runtime/vocabulary.hpp)
//   -> the loop detector of the policy stack over every frame, after optional distractor
//      key frames (run_loops)
//   -> per-frame decisions, the loops found, timings (LoopRun)
//   -> against a ground truth: precision and recall at the decision threshold, the PR
//      curve and the recall at 100 % precision (evaluate_loop_run).
//
//   vmap::LoopRunOptions o;
//   o.detector.index = vmap::CandidateIndex::bow;
//   o.validate();  // before any frame is read
//   const vmap::LoopRun run = vmap::detect_loops("images/", o, nullptr);
//   const auto gt = vmap::LoopGroundTruth::load("gt.txt", run.results.size());
//   const vmap::LoopEvaluation e = vmap::evaluate_loop_run(run, gt, o.detector.decision.min_confidence);
//   std::printf("recall@100%%P %.3f\n", e.at_full_precision.recall);
//
// A ground truth over a memory's key images comes from the frames' (key_image_ground_truth).
//
// Every function here runs on the calling thread and keeps nothing between calls; the
// callbacks are called on that thread.

#include <vmap/core/error.hpp>
#include <vmap/core/features.hpp>
#include <vmap/core/names.hpp>
#include <vmap/hooks/detection.hpp>
#include <vmap/hooks/precomputed_detections.hpp>
#include <vmap/io/exports.hpp>
#include <vmap/io/frame_source.hpp>
#include <vmap/io/poses.hpp>
#include <vmap/keyframe/visual_map.hpp>
#include <vmap/lcd/evaluation.hpp>
#include <vmap/lcd/influence.hpp>
#include <vmap/lcd/label_sources.hpp>
#include <vmap/lcd/label_vector.hpp>
#include <vmap/lcd/loop_detector.hpp>
#include <vmap/lcd/loop_engine.hpp>
#include <vmap/place/vocabulary.hpp>
#include <vmap/runtime/loop_detector.hpp>
#include <vmap/runtime/option_names.hpp>
#include <vmap/runtime/policies.hpp>
#include <vmap/runtime/stack.hpp>
#include <vmap/runtime/vocabulary.hpp>

#include <opencv2/core.hpp>

#include <algorithm>
#include <chrono>
#include <cstddef>
#include <cstdint>
#include <filesystem>
#include <functional>
#include <memory>
#include <optional>
#include <string>
#include <utility>
#include <vector>

namespace vmap {

/// Progress of one stage: `done` of `total` items (total 0 when the source cannot tell).
using ProgressCallback = std::function<void(std::size_t done, std::size_t total)>;

namespace detail {

inline double seconds_since(std::chrono::steady_clock::time_point t0) {
  return std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
}

}  // namespace detail

// ---------------------------------------------------------------------------------------
// Features of a sequence

/// The features of every frame of a sequence, extracted once (reusable across runs).
struct SequenceFeatures {
  std::vector<Features> frames;
  std::vector<std::string> names;  ///< per frame: its file name, "<video>#<index>", or its index for a list
  std::vector<double> times;       ///< per frame: its time in seconds (with the source's time offset)
  std::vector<std::int64_t> times_ns;  ///< the same times exactly (Frame::time_ns)
  std::string source;              ///< the input, as messages name it
  double seconds = 0.0;            ///< reading and extraction of all frames
  std::size_t skipped = 0;         ///< unreadable frames (FrameSource::skipped; not in `frames`)

  /// Features the caller already holds: frame k is named "k" and timed k seconds.
  [[nodiscard]] static SequenceFeatures of(std::vector<Features> frames, std::string source) {
    SequenceFeatures s;
    s.frames = std::move(frames);
    s.source = std::move(source);
    for (std::size_t k = 0; k < s.frames.size(); ++k) {
      s.names.push_back(std::to_string(k));
      s.times.push_back(static_cast<double>(k));
      s.times_ns.push_back(static_cast<std::int64_t>(k) * 1'000'000'000);
    }
    return s;
  }
};

/// Whether the stack's descriptor reads grey images: XFeat's sparse network reads colour,
/// the classic detectors and XFeat's dense grid grey.
[[nodiscard]] constexpr bool reads_grey(const PolicyStack& s) noexcept { return s.descriptor != DescriptorKind::xfeat; }

/// The features of every frame of `input` (a video, an image folder, a list file, TUM's
/// rgb.txt: FrameSource::open) by the stack's descriptor. `frames` holds the frame source's
/// other options (time offset, range, on_skip); its `grey` is the descriptor's
/// (reads_grey). progress(done, total) after each frame.
[[nodiscard]] inline SequenceFeatures extract_features(const std::filesystem::path& input, const PolicyStack& stack,
                                                       const ProgressCallback& progress = {},
                                                       FrameSourceOptions frames = {}) {
  SequenceFeatures out;
  out.source = input.string();
  frames.grey = reads_grey(stack);
  auto source = FrameSource::open(input, frames);
  const std::size_t total = source.total().value_or(0);
  const auto t0 = std::chrono::steady_clock::now();
  with_descriptor(stack, [&](auto descriptor) {
    while (auto frame = source.next()) {
      out.frames.push_back(descriptor.extract(frame->image));
      out.names.push_back(frame->name);
      out.times.push_back(frame->timestamp);
      out.times_ns.push_back(frame->time_ns);
      if (progress) progress(out.frames.size(), total);
    }
  });
  out.seconds = detail::seconds_since(t0);
  out.skipped = source.skipped().size();
  return out;
}

/// The features of images the caller holds (named and timed as SequenceFeatures::of).
[[nodiscard]] inline SequenceFeatures extract_features(const std::vector<cv::Mat>& images, const PolicyStack& stack,
                                                       const ProgressCallback& progress = {}) {
  std::vector<Features> frames;
  const auto t0 = std::chrono::steady_clock::now();
  with_descriptor(stack, [&](auto descriptor) {
    for (const cv::Mat& image : images) {
      frames.push_back(descriptor.extract(image));
      if (progress) progress(frames.size(), images.size());
    }
  });
  SequenceFeatures out = SequenceFeatures::of(std::move(frames), "<list of " + std::to_string(images.size()) + " frames>");
  out.seconds = detail::seconds_since(t0);
  return out;
}

// ---------------------------------------------------------------------------------------
// Labels

/// One labels file (frame label score x y w h, hooks/precomputed_detections.hpp), or the
/// union of several (detectors with the same label ids: a label is present when any file
/// has it).
[[nodiscard]] inline PrecomputedDetections load_labels(const std::vector<std::filesystem::path>& files) {
  detail::check(!files.empty(), "load_labels: no labels file");
  if (files.size() == 1) return PrecomputedDetections::load(files.front());
  std::vector<PrecomputedDetections> sources;
  for (const auto& f : files) sources.push_back(PrecomputedDetections::load(f));
  return merge_detections(sources);
}

/// Runs `detector` over every frame of `frames` once, unfiltered (the label options'
/// score threshold applies later): its detections feed both eq. 5's sample and the loop
/// detector, whose schema needs the sample before the first query.
template <ObjectDetector D>
[[nodiscard]] PrecomputedDetections detect_labels(FrameSource& frames, D& detector, const ProgressCallback& progress = {}) {
  const std::size_t total = frames.total().value_or(0);
  std::vector<std::vector<Detection>> per_frame;
  while (auto f = frames.next()) {
    per_frame.push_back(detector.detect(f->image));
    if (progress) progress(per_frame.size(), total);
  }
  return PrecomputedDetections(per_frame);
}

// ---------------------------------------------------------------------------------------
// The run

/// The stages of detect_loops, in order: features, vocabulary, loops (core/names.hpp).
enum class LoopStage : std::uint8_t { features, vocabulary, loops };

[[nodiscard]] constexpr auto names_of(LoopStage) noexcept {
  return detail::NameTable<LoopStage, 3>{
      {{{LoopStage::features, "features"}, {LoopStage::vocabulary, "vocabulary"}, {LoopStage::loops, "loops"}}}};
}
[[nodiscard]] constexpr std::string_view to_string(LoopStage s) noexcept { return names_of(s).name(s); }

/// What a run tells its caller while it runs (each optional).
struct LoopRunCallbacks {
  /// progress(stage, done, total): features after each frame (total 0 when the source
  /// cannot tell); vocabulary 0 of 1 before it is learned and 1 of 1 after (not called for
  /// a file); loops after each frame's decision.
  std::function<void(LoopStage stage, std::size_t done, std::size_t total)> progress{};
  /// Each frame's decision as it is made.
  std::function<void(const LoopResult&)> on_result{};
};

/// Where a run's vocabulary comes from (the ranked candidate sources need one).
struct LoopVocabulary {
  std::filesystem::path file{};   ///< a vocabulary file of any format vmap reads; empty: learn one
  VocabularyLearning learning{};  ///< without a file: learned on the sequence's own features
};

/// One loop run's options (see the top of this file).
struct LoopRunOptions {
  LoopOptions detector{};          ///< the candidate source, window, m, top k, decision threshold ...
  InfluenceOptions influence{};    ///< eq. 5's band of kept labels
  std::vector<int> label_order{};  ///< label ids, large objects first; empty: by mean box area
  std::size_t sample = 0;          ///< frames whose labels form eq. 5's sample; 0: all
  PolicyStack stack{};             ///< ORB 1000 + MAGSAC++ by default, as the brute-force baseline
  LoopVocabulary vocabulary{};
  /// Refuse a sequence with unreadable frames even without labels: the caller evaluates
  /// against a per-frame ground truth, which they would shift.
  bool every_frame = false;

  /// An Error naming the option when a value is out of its range: the stack, the loop
  /// engine's options (check_loop_options), the influence band and, without a vocabulary
  /// file, the vocabulary to learn (its words and depth named as `names` spells them).
  void validate(const OptionNames& names = OptionNames::keywords()) const {
    stack.validate();
    check_loop_options(detector, "LoopOptions");
    detail::check_influence_options(influence);
    if (vocabulary.file.empty() && ranks(detector.index)) vocabulary.learning.validate(names);
  }
};

/// The score the evaluation gives a decision: its confidence when the threshold alone
/// decides it (accepted, or an unknown place), else 0 (ambiguous, too little evidence, not
/// a revisit: no threshold would make it a loop).
[[nodiscard]] inline double evaluation_score(const PlaceDecision& d) noexcept {
  const bool by_threshold = d.status == PlaceStatus::accepted || d.status == PlaceStatus::unknown_place;
  return by_threshold ? d.confidence : 0.0;
}

/// One loop a run accepted: the query frame, the older frame it closes a loop with, and the
/// evidence (lcd/place_decision.hpp).
struct DetectedLoop {
  std::size_t query = 0, match = 0;
  std::string query_name{}, match_name{};
  double query_time = 0.0, match_time = 0.0;     ///< seconds
  std::int64_t query_time_ns = 0, match_time_ns = 0;  ///< the same times exactly (Frame::time_ns)
  double confidence = 0.0;  ///< in [0, 1]
  PlaceEvidence evidence{}; ///< inliers, matches, ratio, significance, spread, bag-of-words score

  /// The loop as a timestamp pair (loops.txt, io/exports.hpp).
  [[nodiscard]] LoopPair pair() const {
    return {query, match, query_time_ns, match_time_ns, query_name, match_name, evidence.inliers};
  }
};

/// What a loop run gives: every frame's decision, the loops, the schema and the timings.
struct LoopRun {
  /// One per frame of the sequence (distractors left out), numbered as the detector
  /// numbers its frames: after the distractors (scores() maps them to the sequence's).
  std::vector<LoopResult> results;
  std::vector<DetectedLoop> loops;        ///< the accepted loops, in frame order
  LoopOptions options;                    ///< the detector's
  LabelSchema schema;
  std::vector<LabelInfluence> influence;  ///< every label of the sample, schema order
  std::vector<std::string> names;         ///< per frame (SequenceFeatures)
  std::vector<double> times;              ///< per frame, seconds
  std::size_t skipped = 0;                ///< unreadable frames of the sequence
  std::shared_ptr<const AnyVocabulary> vocabulary;  ///< the ranked sources'; else null
  bool vocabulary_learned = false;        ///< learned on the sequence (not read from a file)
  double vocabulary_seconds = 0.0;        ///< loading or learning it
  double seconds = 0.0;                   ///< extraction of the sequence + the detector over it
  double detector_seconds = 0.0;          ///< the detector alone (labels, ranking, verification)
  double rank_seconds = 0.0;              ///< of which bag-of-words description and ranking
  std::size_t verifications = 0;          ///< over the sequence's frames
  std::size_t distractors = 0;            ///< key frames added before the sequence
  std::size_t memory_bytes = 0;           ///< the detector's frames and index after the run
  bool stationary = false;                ///< the camera never left its place (LoopEngine::stationary)

  /// The evaluation's view (evaluation_score): frame indices of the sequence; a loop with
  /// a distractor is reported as a match with `distractor_frame` (a frame no query has a
  /// loop with).
  [[nodiscard]] std::vector<LoopScore> scores(std::optional<std::size_t> distractor_frame = std::nullopt) const {
    std::vector<LoopScore> out;
    out.reserve(results.size());
    for (const LoopResult& r : results) {
      std::optional<std::size_t> match = r.best;
      if (match) match = *match >= distractors ? *match - distractors : distractor_frame.value_or(r.frame - distractors);
      out.push_back({r.frame - distractors, match, evaluation_score(r)});
    }
    return out;
  }
  [[nodiscard]] double ms_per_frame() const {
    return results.empty() ? 0.0 : 1e3 * seconds / static_cast<double>(results.size());
  }
  /// What these label vectors allow any tree (lcd/label_sources.hpp).
  [[nodiscard]] LabelVectorAgreement agreement(const LoopGroundTruth& gt, std::size_t window) const {
    std::vector<LabelVector> vectors;
    vectors.reserve(results.size());
    for (const LoopResult& r : results) vectors.push_back(r.labels);
    return label_vector_agreement(vectors, gt, window);
  }
};

/// The loop detector of `o.stack` over the frames' features (already extracted) with their
/// detections, after `distractors` (optional: older key frames without labels); the
/// vocabulary is needed by the ranked sources only. The label schema comes from the
/// labels of the first `o.sample` frames. An Error when the labels cover another number of
/// frames than the sequence, or a ranked source has no vocabulary.
[[nodiscard]] inline LoopRun run_loops(const LoopRunOptions& o, const SequenceFeatures& features,
                                       const PrecomputedDetections& labels,
                                       std::shared_ptr<const AnyVocabulary> vocabulary,
                                       const LoopRunCallbacks& callbacks = {},
                                       const std::vector<Features>* distractors = nullptr) {
  const std::size_t frames = features.frames.size();
  if (labels.frames_declared() && labels.frames() != frames)
    detail::fail("the labels cover " + std::to_string(labels.frames()) + " frames but '" + features.source + "' has " +
                 std::to_string(frames));
  if (ranks(o.detector.index))
    detail::check(vocabulary != nullptr, [&] {
      return "the " + std::string(to_string(o.detector.index)) + " candidate source needs a vocabulary";
    });
  LabelStatistics stats(o.detector.labels);
  const std::size_t sample = o.sample == 0 ? frames : std::min(o.sample, frames);
  for (std::size_t k = 0; k < sample; ++k) stats.observe(labels.at(k));
  LoopRun run;
  run.schema = make_label_schema(stats, o.influence, o.label_order, &run.influence);
  run.options = o.detector;
  run.names = features.names;
  run.times = features.times;
  run.skipped = features.skipped;
  run.vocabulary = vocabulary;
  // The features come pre-extracted (add); the detector's descriptor is the one that made
  // them, so a caller could push further images through it.
  AnyLoopDetector detector(o.stack, run.schema, o.detector, std::move(vocabulary));
  if (distractors) {
    for (const Features& f : *distractors) (void)detector.add(f, {});
    run.distractors = distractors->size();
  }
  const std::size_t before = detector.verifications();
  const auto t0 = std::chrono::steady_clock::now();
  run.results.reserve(frames);
  for (std::size_t k = 0; k < frames; ++k) {
    run.results.push_back(detector.add(features.frames[k], labels.at(k)));
    run.rank_seconds += run.results.back().rank_ms / 1e3;
    if (callbacks.on_result) callbacks.on_result(run.results.back());
    if (callbacks.progress) callbacks.progress(LoopStage::loops, k + 1, frames);
  }
  run.detector_seconds = detail::seconds_since(t0);
  run.verifications = detector.verifications() - before;
  run.memory_bytes = detector.memory_bytes();
  run.stationary = detector.stationary();
  run.seconds = features.seconds + run.detector_seconds;
  // The detector numbers the distractors first; a loop with one has no frame of the
  // sequence to name.
  for (const LoopResult& r : run.results)
    if (r.loop() && *r.best >= run.distractors) {
      const std::size_t q = r.frame - run.distractors, m = *r.best - run.distractors;
      run.loops.push_back({q, m, features.names[q], features.names[m], features.times[q], features.times[m],
                           features.times_ns[q], features.times_ns[m], r.confidence, r.evidence});
    }
  return run;
}

namespace detail {

/// A run's vocabulary and where it came from.
struct RunVocabulary {
  std::shared_ptr<const AnyVocabulary> vocabulary;
  bool learned = false;
  double seconds = 0.0;  ///< loading or learning it
};

/// The vocabulary file of a run whose candidate source ranks, read before any frame so
/// that a bad one fails at once.
inline RunVocabulary vocabulary_file_of(const LoopRunOptions& o) {
  RunVocabulary v;
  if (ranks(o.detector.index) && !o.vocabulary.file.empty()) {
    const auto t0 = std::chrono::steady_clock::now();
    v.vocabulary = std::make_shared<const AnyVocabulary>(AnyVocabulary::load(o.vocabulary.file));
    v.seconds = seconds_since(t0);
  }
  return v;
}

inline LoopRun detect_loops_in(const SequenceFeatures& features, const LoopRunOptions& o,
                               const PrecomputedDetections* labels, const LoopRunCallbacks& callbacks, RunVocabulary v) {
  check(!features.frames.empty(), [&] { return "no frames to detect loops in ('" + features.source + "')"; });
  if (features.skipped > 0 && (labels != nullptr || o.every_frame))
    fail(std::to_string(features.skipped) + " frame(s) of '" + features.source +
         "' could not be read; the labels and the ground truth are per frame, so they would be shifted");
  if (!v.vocabulary && ranks(o.detector.index)) {
    if (callbacks.progress) callbacks.progress(LoopStage::vocabulary, 0, 1);
    const auto t0 = std::chrono::steady_clock::now();
    v.vocabulary = std::make_shared<const AnyVocabulary>(learn_vocabulary(features.frames, o.vocabulary.learning));
    v.seconds = seconds_since(t0);
    v.learned = true;
    if (callbacks.progress) callbacks.progress(LoopStage::vocabulary, 1, 1);
  }
  LoopRun run = run_loops(o, features, labels ? *labels : PrecomputedDetections{}, v.vocabulary, callbacks);
  run.vocabulary_learned = v.learned;
  run.vocabulary_seconds = v.seconds;
  return run;
}

}  // namespace detail

/// The whole run over a sequence of frames (see the top of this file): the options
/// validated, the vocabulary file read, the features extracted (`frames`: the frame
/// source's options, as extract_features), a vocabulary learned when there is no file,
/// then run_loops. `labels` (optional) hold a detection list per frame for the label
/// sources. An Error when a frame cannot be read and the labels (or, with
/// `o.every_frame`, a ground truth) are per frame.
[[nodiscard]] inline LoopRun detect_loops(const std::filesystem::path& input, const LoopRunOptions& o,
                                          const PrecomputedDetections* labels, const LoopRunCallbacks& callbacks = {},
                                          FrameSourceOptions frames = {}) {
  o.validate();
  detail::RunVocabulary vocabulary = detail::vocabulary_file_of(o);
  const SequenceFeatures features = extract_features(
      input, o.stack,
      [&](std::size_t done, std::size_t total) {
        if (callbacks.progress) callbacks.progress(LoopStage::features, done, total);
      },
      std::move(frames));
  return detail::detect_loops_in(features, o, labels, callbacks, std::move(vocabulary));
}

/// The same run over features already extracted by the stack's descriptor.
[[nodiscard]] inline LoopRun detect_loops(const SequenceFeatures& features, const LoopRunOptions& o,
                                          const PrecomputedDetections* labels, const LoopRunCallbacks& callbacks = {}) {
  o.validate();
  return detail::detect_loops_in(features, o, labels, callbacks, detail::vocabulary_file_of(o));
}

// ---------------------------------------------------------------------------------------
// Ground truth and evaluation

/// How far in time a pose may lie from the frame it is taken for: 50 ms rather than
/// TUM's associate.py's 20 ms, as fr1's ground truth has gaps of up to 49 ms (tum_fr1_rpy).
inline constexpr double pose_association_seconds = 0.05;

/// One pose per frame from a pose file (TUM, KITTI or EuRoC): by order when the counts
/// agree, else the nearest in time within pose_association_seconds (TUM's 100 Hz
/// groundtruth.txt against rgb.txt at 30 Hz). An Error naming the file for a frame
/// without one.
[[nodiscard]] inline std::vector<CameraPose> frame_poses(const std::filesystem::path& file,
                                                         const std::vector<double>& frame_times) {
  return poses_for_frames(load_camera_poses(file), frame_times, file.string(), pose_association_seconds);
}

/// The ground truth over a memory's key images from the frames' ground truth: (i, j)
/// when the frames' marks (f_i, f_j) and j + window < i (the pairs a memory could find,
/// as ground_truth_from_poses' window leaves out the near ones). An Error naming `who`
/// when a key image's frame lies outside the frames' matrix.
[[nodiscard]] inline LoopGroundTruth key_image_ground_truth(const LoopGroundTruth& frames,
                                                            const std::vector<KeyImage>& keys, std::size_t window,
                                                            const std::string& who) {
  for (const auto& k : keys)
    if (k.frame_index >= frames.frames())
      detail::fail(who + " covers " + std::to_string(frames.frames()) + " frames, the memory has frame " +
                   std::to_string(k.frame_index) + " (" + k.name + ")");
  LoopGroundTruth gt(keys.size());
  for (std::size_t i = 0; i < keys.size(); ++i)
    for (std::size_t j = 0; j + window < i; ++j) gt.set(i, j, frames(keys[i].frame_index, keys[j].frame_index));
  return gt;
}

/// The ground truth over a memory's key images from a pose file: each key image's pose
/// by its time (within pose_association_seconds; never by order, as key images are a
/// subset of the frames), then ground_truth_from_poses.
[[nodiscard]] inline LoopGroundTruth key_image_ground_truth(const std::filesystem::path& poses,
                                                            const std::vector<KeyImage>& keys,
                                                            const PoseLoopOptions& options) {
  std::vector<double> times;
  times.reserve(keys.size());
  for (const auto& k : keys) times.push_back(k.timestamp);
  return ground_truth_from_poses(
      poses_for_frames(load_camera_poses(poses), times, poses.string(), pose_association_seconds, false), options);
}

/// A run's figures against a ground truth (lcd/evaluation.hpp): each query proposes its
/// best candidate; at threshold t a query scoring >= t is a detection, true when the
/// ground truth marks (query, candidate).
struct LoopEvaluation {
  LoopGroundTruth ground_truth;       ///< what the run was evaluated against
  double threshold = 0.5;             ///< the decision threshold `at_threshold` is taken at
  std::size_t frames = 0;             ///< query frames
  std::size_t positives = 0;          ///< query frames with a ground-truth loop
  PrecisionRecall at_threshold;       ///< precision and recall at `threshold`
  RecallAtFullPrecision at_full_precision;
  std::vector<PrecisionRecall> curve;  ///< from the highest threshold to the lowest
  std::size_t verifications = 0;      ///< of the run (0 for bare scores)
  double ms_per_frame = 0.0;          ///< of the run (0 for bare scores)
};

/// The figures of bare scores (one per query: its best candidate and score).
[[nodiscard]] inline LoopEvaluation evaluate_loop_scores(const std::vector<LoopScore>& scores, LoopGroundTruth gt,
                                                         double threshold) {
  detail::check(std::isfinite(threshold), "evaluate_loop_scores: the threshold must be finite");
  LoopEvaluation e;
  e.threshold = threshold;
  e.frames = gt.frames();
  e.positives = gt.loop_frames();
  e.at_threshold = evaluate_loops(scores, gt, threshold);
  e.curve = precision_recall_curve(scores, gt);
  e.at_full_precision = recall_at_full_precision(e.curve);
  e.ground_truth = std::move(gt);
  return e;
}

/// The figures of a run against the ground truth of its sequence's frames (a loop with a
/// distractor key frame is false). An Error naming `who` when the ground truth covers
/// another number of frames, or when frames of the run could not be read.
[[nodiscard]] inline LoopEvaluation evaluate_loop_run(const LoopRun& run, LoopGroundTruth gt, double threshold,
                                                      const std::string& who = "the ground truth") {
  detail::check(run.skipped == 0, [&] {
    return std::to_string(run.skipped) +
           " frame(s) of the run could not be read; the ground truth is per frame, so the evaluation would be shifted";
  });
  detail::check(gt.frames() == run.results.size(), [&] {
    return who + ": covers " + std::to_string(gt.frames()) + " frames but the run has " +
           std::to_string(run.results.size());
  });
  LoopEvaluation e;
  if (run.distractors > 0) {
    // One extra all-zero frame stands for every distractor: a loop with it is false.
    LoopGroundTruth with_distractor(gt.frames() + 1);
    for (std::size_t q = 0; q < gt.frames(); ++q)
      for (std::size_t j = 0; j < gt.frames(); ++j) with_distractor.set(q, j, gt(q, j));
    e = evaluate_loop_scores(run.scores(gt.frames()), std::move(with_distractor), threshold);
    e.frames = gt.frames();
    e.ground_truth = std::move(gt);
  } else {
    e = evaluate_loop_scores(run.scores(), std::move(gt), threshold);
  }
  e.frames = run.results.size();
  e.verifications = run.verifications;
  e.ms_per_frame = run.ms_per_frame();
  return e;
}

}  // namespace vmap
