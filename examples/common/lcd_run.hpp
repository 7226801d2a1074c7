#pragma once

// One loop-closure run over a sequence, shared by `vmap loops` and bench_loops: labels
// (from a file or a detector) -> label schema from a sample -> LoopDetector over every
// frame -> per-frame results, timings and the evaluation against ground truth.

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
#include <vmap/matching/brute_force.hpp>

#include <algorithm>
#include <chrono>
#include <cstdio>
#include <cstddef>
#include <filesystem>
#include <functional>
#include <optional>
#include <string>
#include <vector>

namespace vmap::examples {

struct LoopRunConfig {
  std::filesystem::path input;             ///< a FrameSource input (folder, list, video, rgb.txt)
  LoopDetectorOptions detector{};          ///< window, m, thresholds, index
  InfluenceOptions influence{};            ///< eq. 5 band
  std::vector<int> label_order;            ///< user's large-to-small order (optional)
  std::size_t sample = 0;                  ///< frames whose labels form the eq. 5 sample; 0: all
  DescriptorChoice descriptor{};           ///< ORB 1000 by default, as the baseline
  FundamentalOptions estimator{.check_degeneracy = false};  ///< MAGSAC, 1 px, 0.99 as the baseline
  bool colour = false;                     ///< decode frames in colour (detectors need it)
};

struct LoopRun {
  std::vector<LoopResult> results;
  LabelSchema schema;
  std::vector<LabelInfluence> influence;  ///< every label of the sample, schema order
  double seconds = 0.0;                   ///< reading, features, index, verification
  std::size_t verifications = 0;
  std::size_t skipped = 0;                ///< unreadable frames (reported on stderr, not in results)

  [[nodiscard]] std::vector<LoopScore> scores() const {
    std::vector<LoopScore> out;
    for (const LoopResult& r : results) out.push_back({r.frame, r.best, static_cast<double>(r.inliers)});
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

/// Runs LoopDetector over every frame with the given per-frame detections.
inline LoopRun run_loops(const LoopRunConfig& config, const PrecomputedDetections& labels,
                         const std::function<void(const LoopResult&)>& on_frame = {}) {
  FrameSourceOptions so;
  so.grey = !config.colour;
  so.on_skip = [](const SkippedFrame& s) {
    std::fprintf(stderr, "vmap: skipping frame %zu (%s): %s\n", s.index, s.name.c_str(), s.reason.c_str());
  };
  auto source = FrameSource::open(config.input, so);
  const std::size_t frames = source.total().value_or(0);
  if (labels.frames_declared() && labels.frames() != frames)
    detail::fail("the labels cover " + std::to_string(labels.frames()) + " frames but '" + config.input.string() +
                 "' has " + std::to_string(frames));
  LabelStatistics stats(config.detector.labels);
  const std::size_t sample = config.sample == 0 ? frames : std::min(config.sample, frames);
  for (std::size_t k = 0; k < sample; ++k) stats.observe(labels.at(k));
  LoopRun run;
  run.schema = make_label_schema(stats, config.influence, config.label_order, &run.influence);
  with_descriptor(config.descriptor, [&](auto descriptor) {
    LoopDetector detector(run.schema, labels, std::move(descriptor), BruteForceMatcher{},
                          FundamentalEstimator(config.estimator), config.detector);
    detector.detector().seek(0);
    const auto t0 = std::chrono::steady_clock::now();
    while (auto frame = source.next()) {
      run.results.push_back(detector.push(frame->image));
      if (on_frame) on_frame(run.results.back());
    }
    run.seconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
    run.verifications = detector.verifications();
  });
  run.skipped = source.skipped().size();
  return run;
}

/// The figures `vmap loops` prints (and its --json names).
struct LoopSummary {
  std::size_t frames = 0;
  std::size_t loops_gt = 0;
  PrecisionRecall at_decision;  ///< at the detector's min_inliers
  RecallAtFullPrecision at_full_precision;
  std::vector<PrecisionRecall> curve;
  std::size_t verifications = 0;
  double ms_per_frame = 0.0;
};

inline LoopSummary summarize(const LoopRun& run, const LoopGroundTruth& gt, int min_inliers) {
  detail::check(gt.frames() == run.results.size(), "the ground truth covers " + std::to_string(gt.frames()) +
                                                       " frames but the sequence has " +
                                                       std::to_string(run.results.size()));
  LoopSummary s;
  const auto scores = run.scores();
  s.frames = run.results.size();
  s.loops_gt = gt.loop_frames();
  s.at_decision = evaluate_loops(scores, gt, min_inliers);
  s.curve = precision_recall_curve(scores, gt);
  s.at_full_precision = recall_at_full_precision(s.curve);
  s.verifications = run.verifications;
  s.ms_per_frame = run.ms_per_frame();
  return s;
}

}  // namespace vmap::examples
