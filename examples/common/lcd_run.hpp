#pragma once

// One loop-closure run over a sequence, shared by `vmap loops` and bench_loops: features
// of every frame (extracted once, reusable across runs) -> labels (from a file or a
// detector) -> label schema from a sample -> vocabulary (a file, or learned on the
// sequence) for the ranked candidate sources -> LoopDetector over every frame (after
// optional distractor key frames) -> per-frame results, timings and the evaluation.

#include "common/bag_options.hpp"
#include "common/policies.hpp"

#include <vmap/core/error.hpp>
#include <vmap/geometry/fundamental.hpp>
#include <vmap/hooks/precomputed_detections.hpp>
#include <vmap/io/frame_source.hpp>
#include <vmap/lcd/evaluation.hpp>
#include <vmap/lcd/influence.hpp>
#include <vmap/lcd/label_sources.hpp>
#include <vmap/lcd/label_vector.hpp>
#include <vmap/lcd/loop_detector.hpp>
#include <vmap/lcd/place_ranking.hpp>
#include <vmap/matching/brute_force.hpp>

#include <algorithm>
#include <chrono>
#include <cstdio>
#include <cmath>
#include <cstddef>
#include <cstdio>
#include <filesystem>
#include <functional>
#include <memory>
#include <optional>
#include <string>
#include <vector>

namespace vmap::examples {

inline double seconds_since(std::chrono::steady_clock::time_point t0) {
  return std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
}

/// The features of every frame of a sequence, extracted once.
struct SequenceFeatures {
  std::vector<Features> frames;
  std::vector<std::string> names;  ///< per frame of `frames`: its file name, or "<video>#<index>"
  std::vector<double> times;       ///< per frame of `frames`: its time in seconds (with the time offset)
  double seconds = 0.0;     ///< reading and extraction of all frames
  std::size_t skipped = 0;  ///< unreadable frames (each reported on stderr; not in `frames`)
};

/// Extracts the features of every frame of `input` with the chosen descriptor;
/// `progress(done, total)` (optional) is called after each frame. `time_offset` is added
/// to every frame time (FrameSourceOptions::time_offset).
inline SequenceFeatures extract_features(const std::filesystem::path& input, const DescriptorChoice& choice,
                                         const std::function<void(std::size_t, std::size_t)>& progress = {},
                                         double time_offset = 0.0) {
  SequenceFeatures out;
  // XFeat runs on colour input; the classic detectors on grey.
  FrameSourceOptions so;
  so.time_offset = time_offset;
  so.grey = choice.name != "xfeat";
  so.on_skip = [](const SkippedFrame& sk) {
    std::fprintf(stderr, "vmap: skipping frame %zu (%s): %s\n", sk.index, sk.name.c_str(), sk.reason.c_str());
  };
  auto source = open_frames(input, so);
  const std::size_t total = source.total().value_or(0);
  const auto t0 = std::chrono::steady_clock::now();
  with_descriptor(choice, [&](auto descriptor) {
    while (auto frame = source.next()) {
      out.frames.push_back(descriptor.extract(frame->image));
      out.names.push_back(frame->name);
      out.times.push_back(frame->timestamp);
      if (progress) progress(out.frames.size(), total);
    }
  });
  out.seconds = seconds_since(t0);
  out.skipped = source.skipped().size();
  return out;
}

/// The vocabulary tree learned by `vmap loops` / `vmap vocabulary`.
struct VocabularyChoice {
  std::filesystem::path file;  ///< a saved vocabulary; empty: learn one
  /// At most this many words: the branching k is the smallest with k^depth >= words.
  /// 1000 (k = 10, L = 3): the prototype used 500 flat words on 84 frames; a
  /// tree leaves small nodes unsplit, so it ends with fewer than k^L words.
  std::size_t words = 1000;
  int depth = 3;  ///< L of the tree
  std::uint64_t seed = 1;

  [[nodiscard]] int branching() const {
    detail::check(depth >= 1, "--depth must be >= 1, got " + std::to_string(depth));
    detail::check(words >= 2, "--words must be >= 2, got " + std::to_string(words));
    int k = 2;
    while (k <= BinaryVocabularyTree::max_branching && std::pow(static_cast<double>(k), depth) < static_cast<double>(words))
      ++k;
    return k;
  }

  /// A usage error (exit 2) when --words and --depth ask for a branching the tree cannot
  /// have: checked when the command starts, not after the features are extracted.
  void check_usage() const {
    if (branching() > BinaryVocabularyTree::max_branching) {
      std::string what = "--words ";
      what += std::to_string(words);
      what += " with --depth ";
      what += std::to_string(depth);
      what += " needs a branching above ";
      what += std::to_string(BinaryVocabularyTree::max_branching);
      what += "; raise --depth or lower --words";
      usage_error(what);
    }
  }
};

/// --words and --depth of a vocabulary learned by the command, with their bounds (the
/// same in every subcommand that learns one).
inline void add_vocabulary_options(CLI::App& app, VocabularyChoice& c, const std::string& context) {
  app.add_option("--words", c.words, context + "at most this many words (branching k: smallest with k^depth >= words)")
      ->capture_default_str()
      ->check(count_in(2, 100000000));
  app.add_option("--depth", c.depth, context + "depth L of the tree")
      ->capture_default_str()
      ->check(count_in(1, 16));
}

/// Learns a vocabulary from the descriptors of a set of frames (binary descriptors by
/// k-majority, float ones by k-means: the Features say which).
inline AnyVocabulary learn_vocabulary(const std::vector<Features>& frames, const VocabularyChoice& c) {
  std::vector<cv::Mat> sets;
  for (const Features& f : frames)
    if (!f.descriptors.empty()) sets.push_back(f.descriptors);
  detail::check(!sets.empty(), "learn_vocabulary: the frames have no descriptors");
  return AnyVocabulary::learn(sets, {.branching = c.branching(), .depth = c.depth, .seed = c.seed});
}

struct LoopRunConfig {
  std::filesystem::path input;             ///< a FrameSource input (folder, list, video, rgb.txt)
  LoopDetectorOptions detector{};          ///< window, m, thresholds, candidate source, top k
  InfluenceOptions influence{};            ///< eq. 5 band
  std::vector<int> label_order;            ///< user's large-to-small order (optional)
  std::size_t sample = 0;                  ///< frames whose labels form the eq. 5 sample; 0: all
  DescriptorChoice descriptor{};           ///< ORB 1000 by default, as the baseline
  FundamentalOptions estimator{.check_degeneracy = false};  ///< MAGSAC, 1 px, 0.99 as the baseline
};

struct LoopRun {
  std::vector<LoopResult> results;        ///< one per frame of the sequence (distractors left out)
  LabelSchema schema;
  std::vector<LabelInfluence> influence;  ///< every label of the sample, schema order
  double seconds = 0.0;                   ///< extraction of the sequence + the detector over it
  double detector_seconds = 0.0;          ///< the detector alone (labels, ranking, verification)
  double rank_seconds = 0.0;              ///< of which bag-of-words description and ranking
  std::size_t verifications = 0;          ///< over the sequence's frames
  std::size_t distractors = 0;            ///< key frames added before the sequence
  std::size_t memory_bytes = 0;           ///< the detector's frames and index after the run
  bool stationary = false;                ///< the camera never left its place (LoopEngine::stationary)

  /// The evaluation's view: frame indices of the sequence; a loop with a distractor is
  /// reported as a match with `distractor_frame` (a frame no query has a loop with).
  [[nodiscard]] std::vector<LoopScore> scores(std::optional<std::size_t> distractor_frame = std::nullopt) const {
    std::vector<LoopScore> out;
    for (const LoopResult& r : results) {
      std::optional<std::size_t> match = r.best;
      if (match) match = *match >= distractors ? *match - distractors : distractor_frame.value_or(r.frame - distractors);
      // The PR curve runs over the confidence of the decisions the threshold alone
      // decides (accepted or unknown place); the others score 0.
      const bool by_threshold = r.status == PlaceStatus::accepted || r.status == PlaceStatus::unknown_place;
      out.push_back({r.frame - distractors, match, by_threshold ? r.confidence : 0.0});
    }
    return out;
  }
  [[nodiscard]] double ms_per_frame() const {
    return results.empty() ? 0.0 : 1e3 * seconds / static_cast<double>(results.size());
  }
  /// What these label vectors allow any tree (lcd/label_sources.hpp).
  [[nodiscard]] LabelVectorAgreement agreement(const LoopGroundTruth& gt, std::size_t window) const {
    std::vector<LabelVector> vectors;
    for (const LoopResult& r : results) vectors.push_back(r.labels);
    return label_vector_agreement(vectors, gt, window);
  }
};

/// One labels file, or the union of several (detectors with the same label ids).
inline PrecomputedDetections load_labels(const std::vector<std::filesystem::path>& files) {
  if (files.size() == 1) return PrecomputedDetections::load(files.front());
  std::vector<PrecomputedDetections> sources;
  for (const auto& f : files) sources.push_back(PrecomputedDetections::load(f));
  return merge_detections(sources);
}

/// Runs LoopDetector over the frames' features with their detections; `vocabulary` is
/// needed by the ranked sources only. `distractors` (optional) are added first, without
/// labels, as older key frames. `on_frame` sees each sequence frame's result.
inline LoopRun run_loops(const LoopRunConfig& config, const SequenceFeatures& features,
                         const PrecomputedDetections& labels, std::shared_ptr<const AnyVocabulary> vocabulary,
                         const std::function<void(const LoopResult&)>& on_frame = {},
                         const std::vector<Features>* distractors = nullptr) {
  const std::size_t frames = features.frames.size();
  if (labels.frames_declared() && labels.frames() != frames)
    detail::fail("the labels cover " + std::to_string(labels.frames()) + " frames but '" + config.input.string() +
                 "' has " + std::to_string(frames));
  if (ranks(config.detector.index))
    detail::check(vocabulary != nullptr, "the " + std::string(to_string(config.detector.index)) +
                                             " candidate source needs a vocabulary");
  LabelStatistics stats(config.detector.labels);
  const std::size_t sample = config.sample == 0 ? frames : std::min(config.sample, frames);
  for (std::size_t k = 0; k < sample; ++k) stats.observe(labels.at(k));
  LoopRun run;
  run.schema = make_label_schema(stats, config.influence, config.label_order, &run.influence);
  with_descriptor(config.descriptor, [&](auto descriptor) {
    // The features come pre-extracted (LoopDetector::add); the descriptor is the one
    // that made them, so a caller could push further images through the detector.
    // The matcher and estimator that go with the descriptor: XFeat's dense grid is
    // matched by blocked mutual NN, and xfeat-star refines each verified pair (XFeat*).
    auto matcher = matcher_for(descriptor);
    auto estimator = estimator_for(descriptor, config.descriptor, FundamentalEstimator(config.estimator));
    LoopDetector detector(run.schema, std::move(descriptor), std::move(matcher), std::move(estimator), config.detector,
                          // the score that goes with the vocabulary's weighting (an FBoW file: L2)
                          PlaceRanker(vocabulary, vocabulary ? vocabulary->scoring() : BowScoring::l1));
    if (distractors) {
      for (const Features& f : *distractors) (void)detector.add(f, {});
      run.distractors = distractors->size();
    }
    const std::size_t before = detector.verifications();
    const auto t0 = std::chrono::steady_clock::now();
    for (std::size_t k = 0; k < frames; ++k) {
      run.results.push_back(detector.add(features.frames[k], labels.at(k)));
      run.rank_seconds += run.results.back().rank_ms / 1e3;
      if (on_frame) on_frame(run.results.back());
    }
    run.detector_seconds = seconds_since(t0);
    run.verifications = detector.verifications() - before;
    run.memory_bytes = detector.memory_bytes();
    run.stationary = detector.stationary();
  });
  run.seconds = features.seconds + run.detector_seconds;
  return run;
}

/// The figures `vmap loops` prints (and its --json names).
struct LoopSummary {
  std::size_t frames = 0;
  std::size_t loops_gt = 0;
  PrecisionRecall at_decision;  ///< at the decision's min_confidence
  RecallAtFullPrecision at_full_precision;
  std::vector<PrecisionRecall> curve;
  std::size_t verifications = 0;
  double ms_per_frame = 0.0;
};

/// The run's figures against `gt` (the sequence's frames; distractor matches are false).
inline LoopSummary summarize(const LoopRun& run, const LoopGroundTruth& gt, double min_confidence) {
  detail::check(gt.frames() == run.results.size(), "the ground truth covers " + std::to_string(gt.frames()) +
                                                       " frames but the sequence has " +
                                                       std::to_string(run.results.size()));
  LoopSummary s;
  std::vector<LoopScore> scores;
  LoopGroundTruth with_distractor = gt;
  if (run.distractors > 0) {
    // One extra all-zero frame stands for every distractor: a loop with it is false.
    with_distractor = LoopGroundTruth(gt.frames() + 1);
    for (std::size_t q = 0; q < gt.frames(); ++q)
      for (std::size_t j = 0; j < gt.frames(); ++j) with_distractor.set(q, j, gt(q, j));
    scores = run.scores(gt.frames());
  } else {
    scores = run.scores();
  }
  s.frames = run.results.size();
  s.loops_gt = gt.loop_frames();
  s.at_decision = evaluate_loops(scores, with_distractor, min_confidence);
  s.curve = precision_recall_curve(scores, with_distractor);
  s.at_full_precision = recall_at_full_precision(s.curve);
  s.verifications = run.verifications;
  s.ms_per_frame = run.ms_per_frame();
  return s;
}

}  // namespace vmap::examples
