// Benchmark of the place decision (lcd/loop_engine.hpp, lcd/place_decision.hpp): how
// often vmap says "I know this place", and whether it is right, on every sequence of
// ../shared/data and the 60 sample frames, in one run. Each figure is given for the
// decision ("now") and for the rule it replaced ("before": the best verified candidate
// is a loop at 50 inliers, a localization at 20, with no revisit rule), computed from the
// same verifications.
//
//   1. Loops with the defaults (`vmap loops` without options: ORB 1000, bag-of-words
//      ranking with a vocabulary learned on the sequence, top 2, window 10): precision,
//      recall, recall at 100 % precision over the confidence, verifications per query,
//      the time per query of ranking, verification and the decision, and the evidence of
//      the best candidates that are true and false loops; the same stream decided by
//      temporal consistency and by the sequence's evidence (lcd/sequence.hpp).
//   2. Foreign places: a visual memory (`vmap build --memory` defaults) of each sequence;
//      every 5th frame of every other sequence localized in it: accepted answers.
//   3. Own places: tum_fr1_rpy with every 10th frame held out of the memory: accepted,
//      and accepted within 15 frames of the query.
//   4. Memories: loop edges of rtabmap_loop against its ground truth; a stream of
//      tum_fr1_rpy then rtabmap_loop: loop edges between the two.
//   5. A camera that does not move: one real frame repeated with seeded sensor noise and
//      sub-pixel jitter: loops, and whether the run is reported as stationary.
//   6. Localization where ORB fails: a memory of tum_fr3_cabinet_kf (nearly textureless)
//      with every 5th frame held out, built and queried with ORB 1000, SIFT and XFeat*
//      (the dense grid, blocked mutual NN and XFeat's refinement before the F-matrix):
//      held-out frames accepted and right by the poses (0.5 m, 30 degrees), and every
//      10th frame of the other sequences (foreign places) accepted, with the time per query.
//
//   7. The chance rate of each named stack (lcd/calibration.hpp): 200 pairs of images of
//      two different shared sequences, verified with the stack's own matcher and
//      estimator, at full size and with the sequences resized to --small-width; the rate
//      runtime/policy_stack.hpp's measured_chance_rate holds.
//
//   8. Sequences as evidence (memory/sequence.hpp): each sequence's memory without every
//      5th frame, the held-out frames localized in order alone and with windows of 2, 4,
//      8, 16 and 30 of them (centred, and 8 trailing); every 10th frame of the other
//      sequences as foreign sequences; the time per answer.
//
//   9. Small images: every sequence resized to 160 (or --small-width) pixels wide; ORB
//      with and without its small-image rule (features/orb.hpp), and variants: loops,
//      held-out frames and foreign frames as in sections 1 and 8.
//
//  10. Foreign sequences on every named stack: a memory of each of four shared sequences,
//      each other sequence localized in it in order and answered alone and as sequences
//      (windows 1, 2, 4, 8, 16, 30, centred and trailing): accepted answers, the strongest
//      confidence, the time per single localization and per sequence answer.
//
//  11. Small images as sequences: every sequence resized to 160 (--small-width) pixels
//      wide, ORB's defaults: held-out frames (section 8's protocol), two traverses of one
//      place (rtabmap_loop's second lap in a memory of its first; tum_fr1_rpy's second half
//      in a memory of its first) alone and as sequences, and section 10's foreign matrix.
//
//  12. The sequence rules' values (SequenceOptions::min_margin and min_support): sections
//      10's (ORB) and 11's foreign matrices, section 8's held-out frames and section 11's
//      two traverses of rtabmap_loop, decided with each value from one set of answers.
//
//   bench_places [--shared DIR] [--static-frames 120] [--seed 1] [--max-speed 5] [--small-width 160]
//                [--part all|loops|localize|calibrate|sequences|small|trust|small-sequences|rules] [--trust-stack all]
#include <vmap/features/orb.hpp>
#include <vmap/features/sift.hpp>
#include <vmap/geometry/fundamental.hpp>
#include <vmap/hooks/xfeat_dense.hpp>
#include <vmap/hooks/xfeat_fine.hpp>
#include <vmap/io/frame_source.hpp>
#include <vmap/io/poses.hpp>
#include <vmap/lcd/calibration.hpp>
#include <vmap/lcd/evaluation.hpp>
#include <vmap/lcd/loop_detector.hpp>
#include <vmap/lcd/sequence.hpp>
#include <vmap/place/consistency.hpp>
#include <vmap/matching/brute_force.hpp>
#include <vmap/memory/sequence.hpp>
#include <vmap/memory/stacks.hpp>
#include <vmap/memory/visual_memory.hpp>
#include <vmap/runtime/calibration.hpp>
#include <vmap/runtime/memory.hpp>

#include <CLI/CLI.hpp>

#include <opencv2/imgproc.hpp>

#include <algorithm>
#include <chrono>
#include <cstdio>
#include <filesystem>
#include <functional>
#include <map>
#include <memory>
#include <random>
#include <string>
#include <vector>

namespace {

namespace fs = std::filesystem;

struct Sequence {
  std::string name;
  std::vector<vmap::Frame> frames;  ///< grey
  std::optional<vmap::LoopGroundTruth> gt;
};

std::vector<vmap::Frame> read_grey(const fs::path& input) {
  auto src = vmap::FrameSource::open(input, {.grey = true});
  std::vector<vmap::Frame> out;
  while (auto f = src.next()) out.push_back(std::move(*f));
  return out;
}

std::vector<Sequence> load_sequences(const fs::path& shared) {
  const fs::path d = shared / "data";
  const vmap::PoseLoopOptions pose_gt{.max_distance = 0.5, .max_angle_deg = 30, .window = 10};
  std::vector<Sequence> out;
  const auto timed_gt = [&](const std::vector<vmap::Frame>& frames, const fs::path& poses) {
    std::vector<double> t;
    for (const auto& f : frames) t.push_back(f.timestamp);
    return vmap::ground_truth_from_poses(
        vmap::poses_for_frames(vmap::load_tum_poses(poses), t, poses.string(), 0.05, false), pose_gt);
  };
  {
    Sequence s{"rtabmap_loop", read_grey(d / "rtabmap_loop/images"), {}};
    s.gt = vmap::LoopGroundTruth::load(d / "rtabmap_loop/gt_loop_matrix_84x84.txt", s.frames.size());
    out.push_back(std::move(s));
  }
  {
    Sequence s{"tum_fr3_cabinet_kf", read_grey(d / "tum_fr3_cabinet_kf/rgb.txt"), {}};
    // One pose per image, in the order of rgb.txt (its timestamps are frame numbers).
    s.gt = vmap::ground_truth_from_poses(vmap::load_tum_poses(d / "tum_fr3_cabinet_kf/truth_cam_poses.txt"), pose_gt);
    out.push_back(std::move(s));
  }
  {
    Sequence s{"tum_fr1_rpy", read_grey(d / "tum_fr1_rpy/rgb.txt"), {}};
    s.gt = timed_gt(s.frames, d / "tum_fr1_rpy/groundtruth.txt");
    out.push_back(std::move(s));
  }
  {
    Sequence s{"kitti07_160", read_grey(d / "kitti07_160/image_0"), {}};
    s.gt = vmap::ground_truth_from_poses(vmap::load_kitti_poses(d / "kitti07_160/poses.txt"), pose_gt);
    out.push_back(std::move(s));
  }
  {
    Sequence s{"sample_60", read_grey(fs::path(VMAP_SOURCE_DIR) / "examples/data/tum_fr1_rpy_60/rgb.txt"), {}};
    s.gt = timed_gt(s.frames, d / "tum_fr1_rpy/groundtruth.txt");
    out.push_back(std::move(s));
  }
  return out;
}

/// Sequences that show the same place (the sample frames are tum_fr1_rpy's first 60).
bool same_place(const std::string& a, const std::string& b) {
  const auto tum = [](const std::string& n) { return n == "tum_fr1_rpy" || n == "sample_60"; };
  return a == b || (tum(a) && tum(b));
}

double median(std::vector<double> v) {
  if (v.empty()) return 0.0;
  std::sort(v.begin(), v.end());
  return v[v.size() / 2];
}

// ---- 1. loops with the defaults -----------------------------------------------------

struct LoopRow {
  std::string name;
  std::size_t frames = 0, loops_gt = 0, verifications = 0;
  std::size_t tp = 0, fp = 0, before_tp = 0, before_fp = 0;
  double recall_full = 0.0, before_recall_full = 0.0;
  double rank_ms = 0.0, verify_ms = 0.0, decide_ms = 0.0;
  double total_ms = 0.0;  ///< the whole add(), the chain's view test included
  std::map<std::string, std::size_t> statuses;
  std::vector<double> true_conf, false_conf, true_inliers, false_inliers, true_ratio, false_ratio, true_spread,
      false_spread;
  bool stationary = false;
  // The same stream decided by temporal consistency (2 earlier queries) and by the
  // sequence's evidence (the trailing 8 queries), from the same verifications.
  std::size_t tc_tp = 0, tc_fp = 0, seq_tp = 0, seq_fp = 0;
  // The same with candidates older than the loop window of the sequence's first query.
  std::size_t beyond_tp = 0, beyond_fp = 0;
  double seq_recall_full = 0.0;
};

LoopRow run_loops(const Sequence& s, const std::vector<vmap::Features>& features) {
  std::vector<cv::Mat> sets;
  for (const auto& f : features) sets.push_back(f.descriptors);
  auto voc = std::make_shared<const vmap::AnyVocabulary>(
      vmap::AnyVocabulary::learn(sets, {.branching = 10, .depth = 3, .seed = 1}));
  vmap::LoopDetector det(vmap::LabelSchema{}, vmap::OrbDescriptor{}, vmap::BruteForceMatcher{},
                         vmap::FundamentalEstimator({.check_degeneracy = false}),
                         {.index = vmap::CandidateIndex::bow}, vmap::PlaceRanker(voc));
  LoopRow row;
  row.name = s.name;
  row.frames = features.size();
  const auto& gt = *s.gt;
  row.loops_gt = gt.loop_frames();
  std::vector<vmap::LoopScore> now, before;
  std::vector<vmap::SequenceQuery> seq_queries, beyond_queries;
  std::vector<vmap::PlaceStatus> single_status;
  const vmap::PlaceDecisionOptions dec;
  vmap::TemporalConsistency<std::size_t> consistency({.required = 3});
  for (const auto& f : features) {
    const auto t0 = std::chrono::steady_clock::now();
    const vmap::LoopResult r = det.add(f, {});
    row.total_ms += std::chrono::duration<double, std::milli>(std::chrono::steady_clock::now() - t0).count();
    ++row.statuses[std::string(vmap::to_string(r.status))];
    row.rank_ms += r.rank_ms;
    row.verify_ms += r.verify_ms;
    row.decide_ms += r.decide_ms;
    const bool by_threshold = r.status == vmap::PlaceStatus::accepted || r.status == vmap::PlaceStatus::unknown_place;
    now.push_back({r.frame, r.best, by_threshold ? r.confidence : 0.0});
    if (r.loop()) (gt(r.frame, *r.best) ? row.tp : row.fp) += 1;
    if (consistency.update(r.loop() ? r.best : std::nullopt).accepted) (gt(r.frame, *r.best) ? row.tc_tp : row.tc_fp) += 1;
    vmap::SequenceQuery sq, beyond;
    if (r.status != vmap::PlaceStatus::not_a_revisit)  // the revisit rule stands for sequences too
      for (const auto& c : r.considered) {
        if (c.stage != vmap::CandidateStage::chosen && c.stage != vmap::CandidateStage::weaker) continue;
        if (r.loop() && c.stage == vmap::CandidateStage::chosen) sq.accepted = sq.candidates.size();
        sq.candidates.push_back({c.frame, vmap::weighed_significance(c.evidence, dec)});
        // A line of the recent past is the robot's own trajectory: only candidates older
        // than the loop window of the sequence's first query (10 + 7 frames back).
        if (c.frame + 17 < r.frame) {
          if (r.loop() && c.stage == vmap::CandidateStage::chosen) beyond.accepted = beyond.candidates.size();
          beyond.candidates.push_back(sq.candidates.back());
        }
      }
    seq_queries.push_back(std::move(sq));
    beyond_queries.push_back(std::move(beyond));
    single_status.push_back(r.status);
    if (r.best && by_threshold) {
      const bool t = gt(r.frame, *r.best);
      (t ? row.true_conf : row.false_conf).push_back(r.confidence);
      (t ? row.true_inliers : row.false_inliers).push_back(r.evidence.inliers);
      (t ? row.true_ratio : row.false_ratio).push_back(r.evidence.inlier_ratio);
      (t ? row.true_spread : row.false_spread).push_back(r.evidence.spread);
    }
    // Before: the verified candidate with the most inliers, revisit or not.
    std::optional<std::size_t> best;
    int inliers = 0;
    for (const auto& c : r.considered)
      if (c.inliers > inliers) best = c.frame, inliers = c.inliers;
    before.push_back({r.frame, best, static_cast<double>(inliers)});
    if (best && inliers >= 50) (gt(r.frame, *best) ? row.before_tp : row.before_fp) += 1;
  }
  const auto seq = vmap::sequence_evidence(
      seq_queries, [](std::size_t) { return 0; }, {.window = 8}, dec, vmap::SequencePlacement::trailing);
  std::vector<vmap::LoopScore> seq_scores;
  for (std::size_t i = 0; i < seq.size(); ++i) {
    const auto& a = seq[i];
    if (!a.candidate) {
      seq_scores.push_back({i, std::nullopt, 0.0});
      continue;
    }
    const std::size_t match = seq_queries[i].candidates[*a.candidate].key;
    seq_scores.push_back({i, match, a.confidence});
    if (vmap::sequence_reason(a, single_status[i], dec) == vmap::DecisionReason::confident) {
      (gt(i, match) ? row.seq_tp : row.seq_fp) += 1;
      if (!gt(i, match))
        std::fprintf(stderr, "%s, a false loop of the sequence of 8: frame %zu -> frame %zu (%zu of %zu on the line)\n",
                     s.name.c_str(), i, match, a.on_line, a.weighed);
    }
  }
  row.seq_recall_full = vmap::recall_at_full_precision(vmap::precision_recall_curve(seq_scores, gt)).recall;
  const auto beyond = vmap::sequence_evidence(
      beyond_queries, [](std::size_t) { return 0; }, {.window = 8}, dec, vmap::SequencePlacement::trailing);
  for (std::size_t i = 0; i < beyond.size(); ++i) {
    const auto& a = beyond[i];
    if (!a.candidate || vmap::sequence_reason(a, single_status[i], dec) != vmap::DecisionReason::confident) continue;
    const std::size_t match = beyond_queries[i].candidates[*a.candidate].key;
    (gt(i, match) ? row.beyond_tp : row.beyond_fp) += 1;
    if (!gt(i, match))
      std::fprintf(stderr, "%s, a false loop of the sequence of 8 beyond its window: frame %zu -> frame %zu\n",
                   s.name.c_str(), i, match);
  }
  row.verifications = det.verifications();
  row.recall_full = vmap::recall_at_full_precision(vmap::precision_recall_curve(now, gt)).recall;
  row.before_recall_full = vmap::recall_at_full_precision(vmap::precision_recall_curve(before, gt)).recall;
  row.stationary = det.stationary();
  return row;
}

std::string fraction(std::size_t tp, std::size_t fp) {
  char b[32];
  std::snprintf(b, sizeof b, "%.3f", tp + fp ? static_cast<double>(tp) / static_cast<double>(tp + fp) : 1.0);
  return b;
}

// ---- 2-4. memories ------------------------------------------------------------------

vmap::OrbVisualMemory build_memory(const std::vector<const vmap::Frame*>& frames) {
  vmap::OrbVisualMemory mem;
  std::size_t index = 0;
  for (const vmap::Frame* f : frames) {
    vmap::Frame g = *f;
    g.index = index++;  // one stream: the frames in push order
    mem.push(g);
  }
  return mem;
}

std::vector<const vmap::Frame*> all_of(const Sequence& s) {
  std::vector<const vmap::Frame*> out;
  for (const auto& f : s.frames) out.push_back(&f);
  return out;
}

/// A 'before' localization: a verified key image with at least 20 inliers.
bool before_localized(const vmap::MemoryLocalization& a) {
  return std::any_of(a.matches.begin(), a.matches.end(), [](const vmap::PlaceLink& l) { return l.inliers >= 20; });
}

// ---- 6. localization with another verifier ------------------------------------------

/// Pushes every frame of `home` into `mem` but every 5th (from frame 2), and returns those.
template <class Memory>
std::vector<const vmap::Frame*> hold_out(Memory& mem, const Sequence& home) {
  std::vector<const vmap::Frame*> held;
  for (std::size_t i = 0; i < home.frames.size(); ++i) {
    if (i % 5 == 2)
      held.push_back(&home.frames[i]);
    else
      mem.push(home.frames[i]);
  }
  return held;
}

/// Section 6 for one feature stack: the memory of `home` without its held-out frames,
/// then the held-out frames and the other sequences' every 10th frame localized in it.
template <class Memory>
void localization_row(const char* stack, Memory mem, const Sequence& home, const vmap::LoopGroundTruth& same,
                      const std::vector<Sequence>& sequences) {
  const auto t0 = std::chrono::steady_clock::now();
  const std::vector<const vmap::Frame*> held = hold_out(mem, home);
  const double build_s = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
  std::size_t accepted = 0, right = 0, foreign = 0, foreign_accepted = 0;
  double query_ms = 0.0;
  std::size_t queries = 0;
  const auto ask = [&](const vmap::Frame& f) {
    const auto t = std::chrono::steady_clock::now();
    auto a = mem.localize(f.image);
    query_ms += std::chrono::duration<double, std::milli>(std::chrono::steady_clock::now() - t).count();
    ++queries;
    return a;
  };
  std::string wrong;  // the accepted answers the poses call another place
  std::map<std::string, std::size_t> statuses;
  std::vector<double> best_inliers, best_confidence;
  for (const vmap::Frame* f : held) {
    const auto a = ask(*f);
    ++statuses[std::string(vmap::to_string(a.status))];
    if (!a.matches.empty()) {
      best_inliers.push_back(a.matches.front().inliers);
      best_confidence.push_back(a.confidence);
    }
    if (!a.ok()) continue;
    ++accepted;
    const std::size_t k = mem.map().keys[a.best()->key].frame_index;
    if (k < f->index ? same(f->index, k) : same(k, f->index)) {  // the matrix holds each pair once, newer first
      ++right;
    } else {
      char b[128];
      std::snprintf(b, sizeof b, " frame %zu -> key frame %zu (confidence %.2f, %d of %d inliers, spread %.2f);",
                    f->index, k, a.confidence, a.best()->inliers, a.best()->matches, a.evidence.spread);
      wrong += b;
    }
  }
  for (const auto& t : sequences) {
    if (same_place(home.name, t.name)) continue;
    for (std::size_t i = 0; i < t.frames.size(); i += 10) {
      ++foreign;
      foreign_accepted += ask(t.frames[i]).ok() ? 1 : 0;
    }
  }
  std::printf("| %s | %zu | %zu | %zu | %zu | %zu | %zu | %.1f | %.1f |\n", stack, mem.key_images(), held.size(), accepted,
              right, foreign, foreign_accepted, queries ? query_ms / static_cast<double>(queries) : 0.0, build_s);
  if (!wrong.empty()) std::fprintf(stderr, "%s, another place:%s\n", stack, wrong.c_str());
  std::fprintf(stderr, "%s, held-out answers:", stack);
  for (const auto& [k, v] : statuses) std::fprintf(stderr, " %s %zu,", k.c_str(), v);
  std::fprintf(stderr, " best verified candidate: median %.0f inliers, median confidence %.2f\n", median(best_inliers),
               median(best_confidence));
  std::fflush(stdout);
}

void localization_section(const std::vector<Sequence>& sequences, const fs::path& shared) {
  const Sequence& cabinet = sequences[1];
  // The same place by the poses alone (no window: a held-out frame's neighbours count).
  const vmap::LoopGroundTruth same = vmap::ground_truth_from_poses(
      vmap::load_tum_poses(shared / "data/tum_fr3_cabinet_kf/truth_cam_poses.txt"),
      {.max_distance = 0.5, .max_angle_deg = 30, .window = 0});
  std::printf("\n## 6. Localization where ORB fails (tum_fr3_cabinet_kf, every 5th frame held out; every 10th frame of "
              "the other sequences)\n\n");
  std::printf("| verifier | key images | held out | accepted | right (0.5 m, 30 deg) | foreign queries | foreign "
              "accepted | ms per query | s to build the memory |\n|---|---|---|---|---|---|---|---|---|\n");
  std::fflush(stdout);
  const vmap::FundamentalEstimator f{};
  // Each stack's decision weighs its inliers against the chance rate measured for it
  // (section 7), as the command line's and the Python module's memories do.
  const auto options_of = [](vmap::DescriptorKind d) {
    vmap::PolicyStack stack;
    stack.descriptor = d;
    vmap::MemoryOptions o;
    o.loops.decision.chance_inlier_rate = vmap::measured_chance_rate(stack);
    return o;
  };
  localization_row("ORB 1000", vmap::OrbVisualMemory(options_of(vmap::DescriptorKind::orb)), cabinet, same, sequences);
  localization_row("SIFT", vmap::SiftVisualMemory(options_of(vmap::DescriptorKind::sift)), cabinet, same, sequences);
  const fs::path models = shared / "models";
  using XFeatStarMemory = vmap::VisualMemory<vmap::XFeatDenseDescriptor, vmap::DenseMutualMatcher,
                                             vmap::XFeatRefined<vmap::FundamentalEstimator>, vmap::InlierRatio>;
  localization_row(
      "XFeat*",
      XFeatStarMemory(vmap::XFeatDenseDescriptor({.model = models / "xfeat_anysize.onnx", .grid = vmap::XFeatGrid::refinable}),
                      vmap::DenseMutualMatcher({.normalise = true}),
                      vmap::XFeatRefined<vmap::FundamentalEstimator>(vmap::XFeatFineOptions{.model = models / "xfeat_fine.onnx"}, f),
                      vmap::InlierRatio{}, options_of(vmap::DescriptorKind::xfeat_star)),
      cabinet, same, sequences);
}

// ---- 8. sequences of images as evidence ------------------------------------------------

/// Whether key frame `k` shows the place of frame `f`: by the poses (0.5 m, 30 degrees;
/// 2 m for kitti07_160), or for rtabmap_loop (no poses) within 10 frames or a loop of its
/// matrix.
struct SamePlace {
  std::optional<vmap::LoopGroundTruth> poses;
  const vmap::LoopGroundTruth* loops = nullptr;
  bool operator()(std::size_t f, std::size_t k) const {
    const std::size_t a = std::max(f, k), b = std::min(f, k);  // the matrices hold each pair once, newer first
    if (poses) return a == b || (*poses)(a, b);
    return a - b <= 10 || (*loops)(a, b);
  }
};

struct SequenceCount {
  std::size_t accepted = 0, right = 0;
  void add(const vmap::MemoryLocalization& a, const vmap::OrbVisualMemory& mem, std::size_t frame, const SamePlace& same) {
    if (!a.ok()) return;
    ++accepted;
    right += same(frame, mem.map().keys[a.best()->key].frame_index) ? 1 : 0;
  }
};

/// The ground truth of section 8 for rtabmap_loop, tum_fr3_cabinet_kf, tum_fr1_rpy and
/// kitti07_160 (sequences[0..3]).
std::vector<SamePlace> same_places(const std::vector<Sequence>& sequences, const fs::path& shared) {
  const fs::path d = shared / "data";
  const vmap::PoseLoopOptions near{.max_distance = 0.5, .max_angle_deg = 30, .window = 0};
  std::vector<double> rpy_times;
  for (const auto& f : sequences[2].frames) rpy_times.push_back(f.timestamp);
  std::vector<SamePlace> same(4);
  same[0].loops = &*sequences[0].gt;
  same[1].poses = vmap::ground_truth_from_poses(vmap::load_tum_poses(d / "tum_fr3_cabinet_kf/truth_cam_poses.txt"), near);
  same[2].poses = vmap::ground_truth_from_poses(
      vmap::poses_for_frames(vmap::load_tum_poses(d / "tum_fr1_rpy/groundtruth.txt"), rpy_times, "groundtruth.txt", 0.05,
                             false),
      near);
  // A car drives 0.57 m per frame of kitti07_160, and its memory keeps a key image every
  // 2-3 frames: the nearest key image of a held-out frame lies 0.6-1.7 m away.
  same[3].poses = vmap::ground_truth_from_poses(vmap::load_kitti_poses(d / "kitti07_160/poses.txt"),
                                                {.max_distance = 2.0, .max_angle_deg = 30, .window = 0});
  return same;
}

void sequence_section(const std::vector<Sequence>& sequences, const fs::path& shared, double max_speed) {
  const std::vector<SamePlace> same = same_places(sequences, shared);
  const std::vector<std::size_t> windows{2, 4, 8, 16, 30};
  std::printf("\n## 8. Sequences as evidence (ORB defaults; memory without every 5th frame; the held-out frames "
              "localized in order, alone and with the window of held-out frames around each (centred) or ending at "
              "each (trailing), lines of at most %.1f key images per query; foreign: every 10th frame of each other sequence, in order)\n\n", max_speed);
  std::printf("| sequence | key images | held out | alone: accepted, right | ");
  for (std::size_t w : windows) std::printf("window %zu: accepted, right | ", w);
  std::printf("trailing 8: accepted, right | foreign queries | foreign accepted: alone, window 8, trailing 8 | ms per "
              "query alone | ms per answer, window 8 |\n|---|---|---|---|");
  for (std::size_t i = 0; i < windows.size(); ++i) std::printf("---|");
  std::printf("---|---|---|---|---|\n");
  std::fflush(stdout);
  for (std::size_t si = 0; si < 4; ++si) {
    const Sequence& home = sequences[si];
    vmap::OrbVisualMemory mem;
    const std::vector<const vmap::Frame*> held = hold_out(mem, home);
    const auto t0 = std::chrono::steady_clock::now();
    std::vector<vmap::MemoryLocalization> singles;
    for (const vmap::Frame* f : held) singles.push_back(mem.localize(f->image));
    const double single_ms =
        std::chrono::duration<double, std::milli>(std::chrono::steady_clock::now() - t0).count() / static_cast<double>(held.size());
    const vmap::PlaceDecisionOptions& dec = mem.options().loops.decision;
    SequenceCount alone;
    for (std::size_t i = 0; i < held.size(); ++i) {
      alone.add(singles[i], mem, held[i]->index, same[si]);
      if (singles[i].ok() && !same[si](held[i]->index, mem.map().keys[singles[i].best()->key].frame_index))
        std::fprintf(stderr, "%s alone, another place: frame %zu -> key frame %zu (confidence %.2f)\n", home.name.c_str(),
                     held[i]->index, mem.map().keys[singles[i].best()->key].frame_index, singles[i].confidence);
    }
    std::printf("| %s | %zu | %zu | %zu, %zu |", home.name.c_str(), mem.key_images(), held.size(), alone.accepted,
                alone.right);
    double seq_ms = 0.0;
    for (std::size_t w : windows) {
      const auto ts = std::chrono::steady_clock::now();
      const auto answers = vmap::with_sequence_evidence(singles, mem.sessions(), {.window = w, .line = {.max_speed = max_speed}}, dec);
      if (w == 8)
        seq_ms = std::chrono::duration<double, std::milli>(std::chrono::steady_clock::now() - ts).count() /
                 static_cast<double>(held.size());
      SequenceCount c;
      for (std::size_t i = 0; i < held.size(); ++i) c.add(answers[i], mem, held[i]->index, same[si]);
      std::printf(" %zu, %zu |", c.accepted, c.right);
    }
    {
      const auto answers = vmap::with_sequence_evidence(singles, mem.sessions(), {.window = 8, .line = {.max_speed = max_speed}}, dec,
                                                        vmap::SequencePlacement::trailing);
      SequenceCount c;
      for (std::size_t i = 0; i < held.size(); ++i) c.add(answers[i], mem, held[i]->index, same[si]);
      std::printf(" %zu, %zu |", c.accepted, c.right);
    }
    std::size_t foreign = 0, f_alone = 0, f_seq = 0, f_trail = 0;
    for (const auto& t : sequences) {
      if (same_place(home.name, t.name)) continue;
      std::vector<vmap::MemoryLocalization> theirs;
      for (std::size_t i = 0; i < t.frames.size(); i += 10) theirs.push_back(mem.localize(t.frames[i].image));
      foreign += theirs.size();
      for (const auto& a : theirs) f_alone += a.ok() ? 1 : 0;
      for (const auto& a : vmap::with_sequence_evidence(theirs, mem.sessions(), {.window = 8, .line = {.max_speed = max_speed}}, dec))
        f_seq += a.ok() ? 1 : 0;
      for (const auto& a : vmap::with_sequence_evidence(theirs, mem.sessions(), {.window = 8, .line = {.max_speed = max_speed}}, dec,
                                                        vmap::SequencePlacement::trailing))
        f_trail += a.ok() ? 1 : 0;
    }
    std::printf(" %zu | %zu, %zu, %zu | %.1f | %.3f |\n", foreign, f_alone, f_seq, f_trail, single_ms, seq_ms);
    std::fflush(stdout);
  }
}

// ---- 9. small images ----------------------------------------------------------------

/// ORB on the image upsampled by `factor`, keypoints mapped back to the image's pixels.
struct UpsampledOrb {
  vmap::OrbDescriptor orb;
  double factor = 2.0;
  vmap::Features extract(const cv::Mat& image) {
    cv::Mat big;
    cv::resize(image, big, cv::Size(), factor, factor, cv::INTER_LINEAR);
    vmap::Features f = orb.extract(big);
    for (auto& k : f.keypoints) {
      k.pt.x = static_cast<float>((k.pt.x + 0.5) / factor - 0.5);
      k.pt.y = static_cast<float>((k.pt.y + 0.5) / factor - 0.5);
      k.size /= static_cast<float>(factor);
    }
    f.image_size = image.size();
    return f;
  }
  static vmap::DescriptorLayout layout() noexcept { return vmap::OrbDescriptor::layout(); }
};

std::vector<Sequence> shrink(const std::vector<Sequence>& sequences, int width) {
  std::vector<Sequence> out;
  for (const auto& s : sequences) {
    if (s.name == "sample_60") continue;
    Sequence t{s.name, {}, s.gt};
    for (const auto& f : s.frames) {
      vmap::Frame g = f;
      const int height = static_cast<int>(std::lround(f.image.rows * static_cast<double>(width) / f.image.cols));
      cv::resize(f.image, g.image, cv::Size(width, height), 0, 0, cv::INTER_AREA);
      t.frames.push_back(std::move(g));
    }
    out.push_back(std::move(t));
  }
  return out;
}

template <class D>
void small_row(const char* variant, const D& descriptor, const std::vector<Sequence>& small,
               const std::vector<SamePlace>& same) {
  for (std::size_t si = 0; si < small.size(); ++si) {
    const Sequence& home = small[si];
    D d = descriptor;
    std::vector<vmap::Features> features;
    double feats = 0.0;
    for (const auto& f : home.frames) {
      features.push_back(d.extract(f.image));
      feats += static_cast<double>(features.back().size());
    }
    std::string loop_text;
    try {
      const LoopRow loops = run_loops(home, features);
      char buf[64];
      std::snprintf(buf, sizeof buf, "%zu / %zu, %.3f", loops.tp, loops.fp, loops.recall_full);
      loop_text = buf;
    } catch (const vmap::Error& e) {  // e.g. no features at all to learn a vocabulary from
      loop_text = e.what();
    }
    vmap::VisualMemory<D, vmap::BruteForceMatcher, vmap::FundamentalEstimator, vmap::InlierRatio> mem(descriptor);
    const std::vector<const vmap::Frame*> held = hold_out(mem, home);
    std::size_t accepted = 0, right = 0, foreign = 0, foreign_accepted = 0;
    for (const vmap::Frame* f : held) {
      const auto a = mem.localize(f->image);
      if (!a.ok()) continue;
      ++accepted;
      right += same[si](f->index, mem.map().keys[a.best()->key].frame_index) ? 1 : 0;
    }
    for (const auto& t : small) {
      if (same_place(home.name, t.name)) continue;
      for (std::size_t i = 0; i < t.frames.size(); i += 10) {
        ++foreign;
        foreign_accepted += mem.localize(t.frames[i].image).ok() ? 1 : 0;
      }
    }
    std::printf("| %s | %s %dx%d | %.0f | %s | %zu | %zu of %zu, %zu right | %zu of %zu |\n", variant,
                home.name.c_str(), home.frames[0].image.cols, home.frames[0].image.rows,
                feats / static_cast<double>(features.size()), loop_text.c_str(), mem.key_images(), accepted,
                held.size(), right, foreign_accepted, foreign);
    std::fflush(stdout);
  }
}

void small_section(const std::vector<Sequence>& sequences, const fs::path& shared, int width) {
  const auto small = shrink(sequences, width);
  const auto same = same_places(sequences, shared);
  std::printf("\n## 9. Small images (every sequence resized to %d pixels wide): ORB variants; loops with the defaults "
              "(section 1), a memory without every 5th frame (section 8's ground truth), every 10th frame of the "
              "other sequences as foreign queries\n\n", width);
  std::printf("| ORB | sequence | features per frame | loops: TP / FP, recall@100%%P | key images | held out: accepted, "
              "right | foreign accepted |\n|---|---|---|---|---|---|---|\n");
  std::fflush(stdout);
  // Without the small-image rule (max_side 0): ORB as it was for every image size.
  const vmap::OrbSmallImages none{.max_side = 0};
  small_row("border 31, FAST 20 (before)", vmap::OrbDescriptor({.small = none}), small, same);
  small_row("border 15, FAST 20", vmap::OrbDescriptor({.edge_threshold = 15, .small = none}), small, same);
  small_row("border 15, FAST 10", vmap::OrbDescriptor({.edge_threshold = 15, .fast_threshold = 10, .small = none}), small,
            same);
  small_row("default (the rule: border 15, FAST 10 up to 200 px)", vmap::OrbDescriptor{}, small, same);
  small_row("border 15, FAST 10, 4 levels",
            vmap::OrbDescriptor({.levels = 4, .edge_threshold = 15, .fast_threshold = 10, .small = none}), small, same);
  small_row("upsampled x2, border 31, FAST 20", UpsampledOrb{vmap::OrbDescriptor({.small = none}), 2.0}, small, same);
}

// ---- 10. sequences that hold ------------------------------------------------------------

/// The windows of section 10, each answered centred and trailing.
const std::vector<std::size_t> trust_windows{1, 2, 4, 8, 16, 30};

/// The stacks of section 7, their models from `shared`/models.
std::vector<vmap::PolicyStack> named_stacks(const fs::path& shared) {
  const fs::path models = shared / "models";
  std::vector<vmap::PolicyStack> stacks(6);
  stacks[1].descriptor = vmap::DescriptorKind::akaze;
  stacks[2].descriptor = vmap::DescriptorKind::sift;
  stacks[3].descriptor = vmap::DescriptorKind::xfeat;
  stacks[3].model = (models / "xfeat_640x480.onnx").string();
  stacks[4].descriptor = vmap::DescriptorKind::xfeat_dense;
  stacks[4].model = (models / "xfeat_anysize.onnx").string();
  stacks[5].descriptor = vmap::DescriptorKind::xfeat_star;
  stacks[5].model = stacks[4].model;
  stacks[5].refine_model = (models / "xfeat_fine.onnx").string();
  return stacks;
}

/// A memory of `stack` in RAM with the decision's chance rate measured for it, as the
/// command line's and the Python module's memories have.
vmap::AnyMemory stack_memory(const vmap::PolicyStack& stack) {
  vmap::MemoryOptions o;
  o.loops.decision.chance_inlier_rate = vmap::measured_chance_rate(stack);
  return vmap::AnyMemory::in_ram(stack, o);
}

/// Accepted answers of `singles` as a sequence of `window` (centred, trailing).
std::pair<std::size_t, std::size_t> accepted_as_sequence(const std::vector<vmap::MemoryLocalization>& singles,
                                                         const std::vector<vmap::MemorySession>& sessions,
                                                         std::size_t window, const vmap::PlaceDecisionOptions& d,
                                                         double* strongest) {
  std::pair<std::size_t, std::size_t> n{0, 0};
  for (const auto placement : {vmap::SequencePlacement::centred, vmap::SequencePlacement::trailing}) {
    const auto answers = vmap::with_sequence_evidence(singles, sessions, {.window = window}, d, placement);
    for (const auto& a : answers) {
      (placement == vmap::SequencePlacement::centred ? n.first : n.second) += a.ok() ? 1 : 0;
      if (strongest && !a.matches.empty()) *strongest = std::max(*strongest, a.confidence);
    }
  }
  return n;
}

/// Section 10's foreign matrix for one stack: a memory of each of rtabmap_loop, the
/// cabinet, every 2nd frame of tum_fr1_rpy and kitti07_160; each other sequence (every
/// 2nd frame of rtabmap_loop, every cabinet frame, every 12th of tum_fr1_rpy, every 4th
/// of kitti07_160) localized in it in order, and answered alone and as sequences.
void foreign_matrix(const std::vector<Sequence>& sequences, const vmap::PolicyStack& stack, const char* label) {
  const std::size_t memory_step[4] = {1, 1, 2, 1}, query_step[4] = {2, 1, 12, 4};
  std::printf("\n%s (%s): images accepted, centred / trailing\n\n| memory | query sequence | queries |", label,
              vmap::summary(stack).c_str());
  for (std::size_t w : trust_windows) std::printf(" window %zu |", w);
  std::printf(" strongest confidence |\n|---|---|---|");
  for (std::size_t i = 0; i < trust_windows.size(); ++i) std::printf("---|");
  std::printf("---|\n");
  std::fflush(stdout);
  std::vector<std::pair<std::size_t, std::size_t>> total(trust_windows.size(), {0, 0});
  std::size_t queries = 0;
  double single_ms = 0.0, answer_ms = 0.0;
  std::size_t answers = 0;
  double strongest_all = 0.0;
  for (std::size_t m = 0; m < 4; ++m) {
    vmap::AnyMemory mem = stack_memory(stack);
    std::size_t index = 0;
    for (std::size_t i = 0; i < sequences[m].frames.size(); i += memory_step[m]) {
      vmap::Frame g = sequences[m].frames[i];
      g.index = index++;
      (void)mem.push(g);
    }
    const vmap::PlaceDecisionOptions& d = mem.options().loops.decision;
    for (std::size_t q = 0; q < 4; ++q) {
      if (q == m) continue;
      std::vector<vmap::MemoryLocalization> singles;
      const auto t0 = std::chrono::steady_clock::now();
      for (std::size_t i = 0; i < sequences[q].frames.size(); i += query_step[q])
        singles.push_back(mem.localize(sequences[q].frames[i].image));
      single_ms += std::chrono::duration<double, std::milli>(std::chrono::steady_clock::now() - t0).count();
      queries += singles.size();
      std::printf("| %s | %s | %zu |", sequences[m].name.c_str(), sequences[q].name.c_str(), singles.size());
      double strongest = 0.0;
      for (std::size_t k = 0; k < trust_windows.size(); ++k) {
        const auto t1 = std::chrono::steady_clock::now();
        const auto n = accepted_as_sequence(singles, mem.sessions(), trust_windows[k], d, &strongest);
        answer_ms += std::chrono::duration<double, std::milli>(std::chrono::steady_clock::now() - t1).count();
        answers += 2 * singles.size();
        total[k].first += n.first;
        total[k].second += n.second;
        std::printf(" %zu / %zu |", n.first, n.second);
      }
      strongest_all = std::max(strongest_all, strongest);
      std::printf(" %.2f |\n", strongest);
      std::fflush(stdout);
    }
  }
  std::printf("| all | | %zu |", queries);
  for (const auto& t : total) std::printf(" **%zu / %zu** |", t.first, t.second);
  std::printf(" %.2f |\n\nms per single localization %.1f; ms per sequence answer (every window, centred and trailing) "
              "%.3f\n",
              strongest_all, single_ms / static_cast<double>(queries), answer_ms / static_cast<double>(answers));
  std::fflush(stdout);
}

void trust_section(const std::vector<Sequence>& sequences, const fs::path& shared, const std::string& which) {
  std::printf("\n## 10. Foreign sequences on every stack (the decision's defaults, the stack's measured chance rate; "
              "windows of queries centred and trailing)\n");
  for (const auto& stack : named_stacks(shared)) {
    if (which != "all" && which != std::string(vmap::to_string(stack.descriptor))) continue;
    foreign_matrix(sequences, stack, "Full size");
  }
}

/// Section 11's two traverses: rtabmap_loop's second lap (frames 40-83) in a memory of
/// its first (frames 0-39, every `step`-th), the ground truth its matrix; tum_fr1_rpy's
/// second half (every 3rd frame) in a memory of its first half (every `step`-th), the
/// ground truth its poses (0.5 m, 30 degrees).
void traverse_rows(const std::vector<Sequence>& small, const std::vector<SamePlace>& same, std::size_t step) {
  struct Traverse {
    std::size_t seq, memory_end, query_begin, query_step;
  };
  const std::size_t half = small[2].frames.size() / 2;
  for (const Traverse t : {Traverse{0, 40, 40, 1}, Traverse{2, half, half, 3}}) {
    const Sequence& s = small[t.seq];
    vmap::OrbVisualMemory mem;
    for (std::size_t i = 0; i < t.memory_end; i += step) mem.push(s.frames[i]);
    std::vector<vmap::MemoryLocalization> singles;
    std::vector<std::size_t> frames;
    const auto t0 = std::chrono::steady_clock::now();
    for (std::size_t i = t.query_begin; i < s.frames.size(); i += t.query_step) {
      singles.push_back(mem.localize(s.frames[i].image));
      frames.push_back(i);
    }
    const double single_ms = std::chrono::duration<double, std::milli>(std::chrono::steady_clock::now() - t0).count() /
                             static_cast<double>(singles.size());
    // rtabmap_loop's second lap: right only by the matrix (its band is +-2 frames), not
    // by section 8's 10 frames, which would count the lap's own frames.
    const auto right = [&](std::size_t f, std::size_t k) {
      return t.seq == 0 ? (*s.gt)(std::max(f, k), std::min(f, k)) : same[t.seq](f, k);
    };
    std::size_t top_right = 0;
    for (std::size_t i = 0; i < singles.size(); ++i)
      top_right += !singles[i].matches.empty() && right(frames[i], mem.map().keys[singles[i].matches.front().key].frame_index);
    std::printf("| %s, memory every %zu%s | %zu | %zu | %zu |", s.name.c_str(), step, step == 1 ? "st" : "th",
                mem.key_images(), singles.size(), top_right);
    double answer_ms = 0.0;
    for (const std::size_t w : {std::size_t{1}, std::size_t{4}, std::size_t{8}, std::size_t{16}}) {
      const auto ts = std::chrono::steady_clock::now();
      const auto answers = vmap::with_sequence_evidence(singles, mem.sessions(), {.window = w},
                                                        mem.options().loops.decision);
      if (w == 8)
        answer_ms = std::chrono::duration<double, std::milli>(std::chrono::steady_clock::now() - ts).count() /
                    static_cast<double>(singles.size());
      std::size_t accepted = 0, good = 0;
      for (std::size_t i = 0; i < answers.size(); ++i) {
        if (!answers[i].ok()) continue;
        ++accepted;
        good += right(frames[i], mem.map().keys[answers[i].best()->key].frame_index) ? 1 : 0;
      }
      std::printf(" %zu, %zu |", accepted, good);
    }
    std::printf(" %.1f | %.3f |\n", single_ms, answer_ms);
    std::fflush(stdout);
  }
}

/// Section 11: small images, alone and as sequences, with ORB's defaults.
void small_sequence_section(const std::vector<Sequence>& sequences, const fs::path& shared, int width) {
  const auto small = shrink(sequences, width);
  const auto same = same_places(sequences, shared);
  std::printf("\n## 11. Small images as sequences (every sequence resized to %d pixels wide; ORB defaults)\n\n", width);
  std::printf("Held out (section 8's protocol): accepted, right\n\n| sequence | key images | held out | alone | window 4 "
              "| window 8 | window 16 | trailing 8 |\n|---|---|---|---|---|---|---|---|\n");
  std::fflush(stdout);
  for (std::size_t si = 0; si < small.size(); ++si) {
    const Sequence& home = small[si];
    vmap::OrbVisualMemory mem;
    const std::vector<const vmap::Frame*> held = hold_out(mem, home);
    std::vector<vmap::MemoryLocalization> singles;
    for (const vmap::Frame* f : held) singles.push_back(mem.localize(f->image));
    const vmap::PlaceDecisionOptions& dec = mem.options().loops.decision;
    std::printf("| %s %dx%d | %zu | %zu |", home.name.c_str(), home.frames[0].image.cols, home.frames[0].image.rows,
                mem.key_images(), held.size());
    const auto count = [&](const std::vector<vmap::MemoryLocalization>& answers) {
      SequenceCount c;
      for (std::size_t i = 0; i < held.size(); ++i) c.add(answers[i], mem, held[i]->index, same[si]);
      std::printf(" %zu, %zu |", c.accepted, c.right);
    };
    count(singles);
    for (const std::size_t w : {std::size_t{4}, std::size_t{8}, std::size_t{16}})
      count(vmap::with_sequence_evidence(singles, mem.sessions(), {.window = w}, dec));
    count(vmap::with_sequence_evidence(singles, mem.sessions(), {.window = 8}, dec, vmap::SequencePlacement::trailing));
    std::printf("\n");
    std::fflush(stdout);
  }
  std::printf("\nTwo traverses (a reference and a query run through the same places): key images, queries, queries "
              "whose best verified candidate is right; accepted, right alone and as sequences (centred); ms per "
              "query alone and per answer of a window of 8\n\n| traverses | key images | queries | best candidate "
              "right | alone | window 4 | window 8 | window 16 | ms per query | ms per answer |\n"
              "|---|---|---|---|---|---|---|---|---|---|\n");
  std::fflush(stdout);
  for (const std::size_t step : {std::size_t{1}, std::size_t{3}}) traverse_rows(small, same, step);
  vmap::PolicyStack orb;
  foreign_matrix(small, orb, "Foreign sequences at this width");
}

// ---- 12. the rules' values ----------------------------------------------------------------

/// One sequence of single answers with what makes an answer right.
struct AnsweredRun {
  std::string name;
  std::vector<vmap::MemoryLocalization> singles;
  std::vector<vmap::MemorySession> sessions;
  vmap::PlaceDecisionOptions decision;
  std::function<bool(std::size_t, std::uint32_t)> right;  ///< query index, key image: the same place
};

/// The foreign runs of section 10's matrix (ORB defaults) for `sequences`.
std::vector<AnsweredRun> foreign_runs(const std::vector<Sequence>& sequences) {
  const std::size_t memory_step[4] = {1, 1, 2, 1}, query_step[4] = {2, 1, 12, 4};
  std::vector<AnsweredRun> out;
  for (std::size_t m = 0; m < 4; ++m) {
    vmap::OrbVisualMemory mem;
    std::size_t index = 0;
    for (std::size_t i = 0; i < sequences[m].frames.size(); i += memory_step[m]) {
      vmap::Frame g = sequences[m].frames[i];
      g.index = index++;
      (void)mem.push(g);
    }
    for (std::size_t q = 0; q < 4; ++q) {
      if (q == m) continue;
      AnsweredRun r{sequences[m].name + " <- " + sequences[q].name, {}, mem.sessions(), mem.options().loops.decision,
                    [](std::size_t, std::uint32_t) { return false; }};
      for (std::size_t i = 0; i < sequences[q].frames.size(); i += query_step[q])
        r.singles.push_back(mem.localize(sequences[q].frames[i].image));
      out.push_back(std::move(r));
    }
  }
  return out;
}

/// Section 12: the sequence rules' values (SequenceOptions::min_margin, min_support) on
/// the foreign matrices at full size and at `width`, the held-out frames of section 8
/// and the two traverses of section 11, from one set of single answers.
void rules_section(const std::vector<Sequence>& sequences, const fs::path& shared, int width) {
  const auto small = shrink(sequences, width);
  const auto same = same_places(sequences, shared);
  std::printf("\n## 12. The sequence rules' values (ORB defaults; one set of single answers, decided with each value)\n\n");
  std::fflush(stdout);
  std::vector<AnsweredRun> foreign = foreign_runs(sequences), foreign_small = foreign_runs(small);
  std::vector<AnsweredRun> held;
  for (std::size_t si = 0; si < 4; ++si) {
    vmap::OrbVisualMemory mem;
    const std::vector<const vmap::Frame*> out = hold_out(mem, sequences[si]);
    AnsweredRun r{sequences[si].name, {}, mem.sessions(), mem.options().loops.decision, {}};
    std::vector<std::size_t> frames, keys;
    for (const vmap::Frame* f : out) {
      r.singles.push_back(mem.localize(f->image));
      frames.push_back(f->index);
    }
    for (const auto& k : mem.map().keys) keys.push_back(k.frame_index);
    r.right = [frames, keys, s = same[si]](std::size_t q, std::uint32_t key) { return s(frames[q], keys[key]); };
    held.push_back(std::move(r));
  }
  std::vector<AnsweredRun> traverses;
  for (const std::size_t step : {std::size_t{1}, std::size_t{3}}) {
    const Sequence& s = small[0];
    vmap::OrbVisualMemory mem;
    for (std::size_t i = 0; i < 40; i += step) (void)mem.push(s.frames[i]);
    AnsweredRun r{"rtabmap_loop's laps at " + std::to_string(width) + " px, memory every " + std::to_string(step),
                  {}, mem.sessions(), mem.options().loops.decision, {}};
    for (std::size_t i = 40; i < s.frames.size(); ++i) r.singles.push_back(mem.localize(s.frames[i].image));
    std::vector<std::size_t> keys;
    for (const auto& k : mem.map().keys) keys.push_back(k.frame_index);
    r.right = [keys, gt = *s.gt](std::size_t q, std::uint32_t key) { return gt(40 + q, keys[key]); };
    traverses.push_back(std::move(r));
  }
  struct Rule {
    const char* name;
    double min_margin;
    std::size_t min_support;
  };
  const Rule rules[] = {{"defaults: min_margin 2, min_support 2", 2.0, 2}, {"min_margin 0", 0.0, 2}, {"min_margin 1", 1.0, 2},
                        {"min_margin 3", 3.0, 2}, {"min_support 1", 2.0, 1}};
  std::printf("Foreign: images accepted over every pair, windows 2-30, centred + trailing. Own: accepted, right at "
              "window 8 (centred / trailing).\n\n| rule | foreign, full size | foreign, %d px |", width);
  for (const auto& r : held) std::printf(" %s held out |", r.name.c_str());
  for (const auto& r : traverses) std::printf(" %s |", r.name.c_str());
  std::printf("\n|---|---|---|");
  for (std::size_t i = 0; i < held.size() + traverses.size(); ++i) std::printf("---|");
  std::printf("\n");
  for (const Rule& rule : rules) {
    const auto options = [&](std::size_t w) {
      return vmap::SequenceOptions{.window = w, .line = {}, .min_margin = rule.min_margin, .min_support = rule.min_support};
    };
    const auto foreign_count = [&](const std::vector<AnsweredRun>& runs) {
      std::size_t n = 0;
      for (const auto& r : runs)
        for (const std::size_t w : {std::size_t{2}, std::size_t{4}, std::size_t{8}, std::size_t{16}, std::size_t{30}})
          for (const auto placement : {vmap::SequencePlacement::centred, vmap::SequencePlacement::trailing})
            for (const auto& a : vmap::with_sequence_evidence(r.singles, r.sessions, options(w), r.decision, placement))
              n += a.ok() ? 1 : 0;
      return n;
    };
    std::printf("| %s | %zu | %zu |", rule.name, foreign_count(foreign), foreign_count(foreign_small));
    for (const auto* runs : {&held, &traverses})
      for (const auto& r : *runs) {
        std::printf(" ");
        for (const auto placement : {vmap::SequencePlacement::centred, vmap::SequencePlacement::trailing}) {
          std::size_t accepted = 0, right = 0;
          const auto answers = vmap::with_sequence_evidence(r.singles, r.sessions, options(8), r.decision, placement);
          for (std::size_t i = 0; i < answers.size(); ++i) {
            if (!answers[i].ok()) continue;
            ++accepted;
            right += r.right(i, answers[i].best()->key) ? 1 : 0;
          }
          std::printf("%zu, %zu%s", accepted, right, placement == vmap::SequencePlacement::centred ? " / " : " |");
        }
      }
    std::printf("\n");
    std::fflush(stdout);
  }
}

// ---- 7. the chance rate of each stack ------------------------------------------------

void calibration_section(const std::vector<Sequence>& sequences, const fs::path& shared, int small_width,
                         const std::string& which) {
  std::printf("\n## 7. The chance rate of each stack (200 foreign pairs, seed 1: rtabmap_loop, tum_fr3_cabinet_kf, "
              "every 10th frame of tum_fr1_rpy, every 3rd of kitti07_160), at full size and at %d pixels wide\n\n",
              small_width);
  std::printf("| stack | size | rate | pairs | weighed (>= 12 inliers) | strongest foreign significance at the rate | "
              "measured_chance_rate |\n|---|---|---|---|---|---|---|\n");
  std::fflush(stdout);
  const auto small = shrink(sequences, small_width);
  const std::size_t steps[4] = {1, 1, 10, 3};  // rtabmap_loop, cabinet, tum_fr1_rpy, kitti07_160
  for (const auto& stack : named_stacks(shared)) {
    if (which != "all" && which != std::string(vmap::to_string(stack.descriptor))) continue;
    for (const auto* at : {&sequences, &small}) {
      // The same function as `vmap calibrate`, on the frames already read.
      std::vector<vmap::SequenceFeatures> places;
      for (std::size_t p = 0; p < 4; ++p) {
        std::vector<cv::Mat> images;
        for (std::size_t i = 0; i < (*at)[p].frames.size(); i += steps[p]) images.push_back((*at)[p].frames[i].image);
        places.push_back(vmap::extract_features(images, stack));
      }
      const std::string size = at == &sequences ? "full" : std::to_string(small_width) + " px wide";
      try {
        const vmap::ChanceCalibration c = vmap::calibrate_chance_rate(stack, std::move(places));
        std::printf("| %s | %s | %.4f | %zu | %zu | %.1f | %.4f |\n", vmap::summary(stack).c_str(), size.c_str(), c.rate,
                    c.pairs, c.weighed, c.strongest, vmap::measured_chance_rate(stack));
      } catch (const vmap::Error& e) {  // e.g. no foreign pair makes a model the decision weighs
        std::printf("| %s | %s | %s | | | | %.4f |\n", vmap::summary(stack).c_str(), size.c_str(), e.what(),
                    vmap::measured_chance_rate(stack));
      }
      std::fflush(stdout);
    }
  }
}

// ---- 5. a camera that does not move -------------------------------------------------

std::vector<vmap::Frame> static_clip(const vmap::Frame& source, std::size_t n, std::uint64_t seed) {
  std::mt19937_64 rng(seed);
  std::uniform_real_distribution<double> jitter(-0.5, 0.5);
  std::vector<vmap::Frame> out;
  for (std::size_t i = 0; i < n; ++i) {
    const cv::Matx23d shift(1, 0, jitter(rng), 0, 1, jitter(rng));
    cv::Mat moved;
    cv::warpAffine(source.image, moved, shift, source.image.size(), cv::INTER_LINEAR, cv::BORDER_REFLECT);
    cv::Mat noise(moved.size(), CV_16SC1);
    cv::theRNG().state = seed * 1000003 + i;  // cv::randn draws from cv::theRNG(): seeded per frame
    cv::randn(noise, 0, 2.0);
    cv::Mat noisy;
    moved.convertTo(noisy, CV_16SC1);
    noisy += noise;
    noisy.convertTo(moved, CV_8UC1);
    out.push_back({moved, i, "static#" + std::to_string(i), static_cast<double>(i) / 30.0});
  }
  return out;
}

}  // namespace

int main(int argc, char** argv) {
  CLI::App app("The place decision on every shared sequence: loops, foreign and own places, a static camera");
  std::string shared = VMAP_SHARED_DIR;
  std::size_t static_frames = 120;
  std::uint64_t seed = 1;
  app.add_option("--shared", shared, "The shared folder (data/)");
  app.add_option("--static-frames", static_frames, "Frames of the static clip")->check(CLI::Range(11, 100000));
  app.add_option("--seed", seed, "Seed of the static clip's noise and jitter");
  double max_speed = vmap::SequenceLine{}.max_speed;
  app.add_option("--max-speed", max_speed, "Section 8: the fastest line, key images per query")->check(CLI::Range(0.0, 1000.0));
  int small_width = 160;
  app.add_option("--small-width", small_width, "Section 9: the width the sequences are resized to")
      ->check(CLI::Range(32, 4096));
  std::string part = "all";
  app.add_option("--part", part,
                 "all: sections 1-11; loops: section 1's tables; localize: section 6 only, calibrate: section 7 only (minutes each: XFeat* verifies "
                 "on the CPU), sequences: section 8 only, small: section 9 only, trust: section 10 only (tens of minutes: every "
                 "stack), small-sequences: section 11 only, rules: section 12 only")
      ->check(CLI::IsMember({"all", "loops", "localize", "calibrate", "sequences", "small", "trust", "small-sequences", "rules"}));
  std::string trust_stack = "all";
  app.add_option("--trust-stack", trust_stack, "Sections 7 and 10: one stack (orb, akaze, sift, xfeat, xfeat-dense, xfeat-star) or all");
  CLI11_PARSE(app, argc, argv);

  const auto sequences = load_sequences(shared);
  if (part == "localize") {
    localization_section(sequences, shared);
    return 0;
  }
  if (part == "calibrate") {
    calibration_section(sequences, shared, small_width, trust_stack);
    return 0;
  }
  if (part == "sequences") {
    sequence_section(sequences, shared, max_speed);
    return 0;
  }
  if (part == "small") {
    small_section(sequences, shared, small_width);
    return 0;
  }
  if (part == "trust") {
    trust_section(sequences, shared, trust_stack);
    return 0;
  }
  if (part == "small-sequences") {
    small_sequence_section(sequences, shared, small_width);
    return 0;
  }
  if (part == "rules") {
    rules_section(sequences, shared, small_width);
    return 0;
  }
  vmap::OrbDescriptor orb;

  std::printf("## 1. Loops with the defaults (bow, top 2, window 10, vocabulary learned on the sequence)\n\n");
  std::printf("| sequence | frames | loop queries | now: TP / FP, precision, recall | now: recall@100%%P | before "
              "(50 inliers): TP / FP, precision | before: recall@100%%P | verifications per query | stationary |\n");
  std::printf("|---|---|---|---|---|---|---|---|---|\n");
  std::vector<LoopRow> rows;
  for (const auto& s : sequences) {
    std::vector<vmap::Features> features;
    for (const auto& f : s.frames) features.push_back(orb.extract(f.image));
    const LoopRow r = run_loops(s, features);
    std::printf("| %s | %zu | %zu | %zu / %zu, %s, %.3f | %.3f | %zu / %zu, %s | %.3f | %.2f | %s |\n", r.name.c_str(),
                r.frames, r.loops_gt, r.tp, r.fp, fraction(r.tp, r.fp).c_str(),
                r.loops_gt ? static_cast<double>(r.tp) / static_cast<double>(r.loops_gt) : 0.0, r.recall_full,
                r.before_tp, r.before_fp, fraction(r.before_tp, r.before_fp).c_str(), r.before_recall_full,
                static_cast<double>(r.verifications) / static_cast<double>(r.frames), r.stationary ? "yes" : "no");
    std::fflush(stdout);
    rows.push_back(r);
  }
  std::printf("\nThe same streams decided by temporal consistency (a loop stands when the 2 queries before it were "
              "accepted within 3 frames of it) and by the sequence's evidence (lcd/sequence.hpp: the trailing 8 "
              "queries, lines of at most 5 frames per query), from the same verifications:\n\n");
  std::printf("| sequence | loop queries | alone: TP / FP, recall | temporal consistency 2: TP / FP, recall | sequence "
              "of 8: TP / FP, recall | alone: recall@100%%P | sequence of 8: recall@100%%P | sequence of 8, candidates "
              "older than its first query's window: TP / FP, recall |\n|---|---|---|---|---|---|---|---|\n");
  for (const auto& r : rows) {
    const auto recall = [&](std::size_t tp) { return r.loops_gt ? static_cast<double>(tp) / static_cast<double>(r.loops_gt) : 0.0; };
    std::printf("| %s | %zu | %zu / %zu, %.3f | %zu / %zu, %.3f | %zu / %zu, %.3f | %.3f | %.3f | %zu / %zu, %.3f |\n",
                r.name.c_str(), r.loops_gt, r.tp, r.fp, recall(r.tp), r.tc_tp, r.tc_fp, recall(r.tc_tp), r.seq_tp,
                r.seq_fp, recall(r.seq_tp), r.recall_full, r.seq_recall_full, r.beyond_tp, r.beyond_fp,
                recall(r.beyond_tp));
  }
  if (part == "loops") return 0;
  std::printf("\nEvidence of the best candidate of each query the threshold decides (accepted or unknown place):\n\n");
  std::printf("| sequence | true: n, min confidence, median inliers, median ratio, median spread | false: n, max "
              "confidence, max inliers, median ratio, median spread |\n|---|---|---|\n");
  for (const auto& r : rows) {
    const auto mn = [](const std::vector<double>& v) { return v.empty() ? 0.0 : *std::min_element(v.begin(), v.end()); };
    const auto mx = [](const std::vector<double>& v) { return v.empty() ? 0.0 : *std::max_element(v.begin(), v.end()); };
    std::printf("| %s | %zu, %.3f, %.0f, %.2f, %.2f | %zu, %.3f, %.0f, %.2f, %.2f |\n", r.name.c_str(),
                r.true_conf.size(), mn(r.true_conf), median(r.true_inliers), median(r.true_ratio),
                median(r.true_spread), r.false_conf.size(), mx(r.false_conf), mx(r.false_inliers),
                median(r.false_ratio), median(r.false_spread));
  }
  std::printf("\nStatuses and time per query (ms: ranking / verification / decision, and the whole add()):\n\n");
  for (const auto& r : rows) {
    std::printf("- %s: %.2f / %.2f / %.3f ms, %.2f ms;", r.name.c_str(), r.rank_ms / static_cast<double>(r.frames),
                r.verify_ms / static_cast<double>(r.frames), r.decide_ms / static_cast<double>(r.frames),
                r.total_ms / static_cast<double>(r.frames));
    for (const auto& [k, v] : r.statuses) std::printf(" %s %zu,", k.c_str(), v);
    std::printf("\n");
  }
  std::fflush(stdout);

  std::printf("\n## 2. Foreign places (memory of each sequence; every 5th frame of every other sequence)\n\n");
  std::printf("| memory | key images | queries | now: accepted | before (20 inliers): localized |\n|---|---|---|---|---|\n");
  std::map<std::string, vmap::OrbVisualMemory> memories;
  for (const auto& s : sequences) memories.emplace(s.name, build_memory(all_of(s)));
  std::size_t total_now = 0, total_before = 0, total_queries = 0;
  for (const auto& s : sequences) {
    auto& mem = memories.at(s.name);
    std::size_t queries = 0, now = 0, before = 0;
    for (const auto& t : sequences) {
      if (same_place(s.name, t.name)) continue;
      for (std::size_t i = 0; i < t.frames.size(); i += 5) {
        const auto a = mem.localize(t.frames[i].image);
        ++queries;
        now += a.ok() ? 1 : 0;
        before += before_localized(a) ? 1 : 0;
      }
    }
    std::printf("| %s | %zu | %zu | %zu | %zu |\n", s.name.c_str(), mem.key_images(), queries, now, before);
    total_now += now;
    total_before += before;
    total_queries += queries;
  }
  std::printf("| all | | %zu | **%zu** | %zu |\n", total_queries, total_now, total_before);
  std::fflush(stdout);

  std::printf("\n## 3. Own places (tum_fr1_rpy, every 10th frame held out)\n\n");
  {
    const Sequence& tum = sequences[2];
    std::vector<const vmap::Frame*> kept, held;
    for (std::size_t i = 0; i < tum.frames.size(); ++i) (i % 10 == 5 ? held : kept).push_back(&tum.frames[i]);
    vmap::OrbVisualMemory mem;
    for (const vmap::Frame* f : kept) mem.push(*f);
    std::size_t now = 0, now_near = 0, before = 0, before_near = 0;
    const auto near = [&](std::uint32_t key, std::size_t frame) {
      const std::size_t k = mem.map().keys[key].frame_index;
      return (k > frame ? k - frame : frame - k) <= 15;
    };
    for (const vmap::Frame* f : held) {
      const auto a = mem.localize(f->image);
      if (a.ok()) {
        ++now;
        now_near += near(a.best()->key, f->index) ? 1 : 0;
      }
      if (before_localized(a)) {
        ++before;
        before_near += near(a.matches.front().key, f->index) ? 1 : 0;
      }
    }
    std::printf("%zu held-out frames, %zu key images: now %zu accepted (%.1f %%), %zu within 15 frames (%.1f %%); "
                "before %zu localized, %zu within 15 frames (%.1f %%)\n",
                held.size(), mem.key_images(), now, 100.0 * static_cast<double>(now) / static_cast<double>(held.size()),
                now_near, 100.0 * static_cast<double>(now_near) / static_cast<double>(held.size()), before, before_near,
                100.0 * static_cast<double>(before_near) / static_cast<double>(held.size()));
  }
  std::fflush(stdout);

  std::printf("\n## 4. Memories: loop edges\n\n");
  {
    const Sequence& rt = sequences[0];
    const auto& mem = memories.at(rt.name);
    std::size_t tp = 0;
    for (const auto& e : mem.loops())
      tp += (*rt.gt)(mem.map().keys[e.from].frame_index, mem.map().keys[e.link.key].frame_index) ? 1 : 0;
    std::printf("- rtabmap_loop memory: %zu key images, %zu loop edges, %zu marked by the ground truth (precision %s)\n",
                mem.key_images(), mem.loops().size(), tp, fraction(tp, mem.loops().size() - tp).c_str());
    std::vector<const vmap::Frame*> stream = all_of(sequences[2]);
    const std::size_t first = stream.size();
    for (const auto& f : rt.frames) stream.push_back(&f);
    const auto both = build_memory(stream);
    std::size_t across = 0;
    for (const auto& e : both.loops())
      across += (both.map().keys[e.from].frame_index >= first) != (both.map().keys[e.link.key].frame_index >= first);
    std::printf("- tum_fr1_rpy then rtabmap_loop in one memory: %zu key images, %zu loop edges, **%zu between the two "
                "sequences**\n",
                both.key_images(), both.loops().size(), across);
  }
  std::fflush(stdout);

  std::printf("\n## 5. A camera that does not move (tum_fr1_rpy frame 0, %zu frames, noise sigma 2, jitter +-0.5 px, "
              "seed %llu)\n\n",
              static_frames, static_cast<unsigned long long>(seed));
  {
    const auto clip = static_clip(sequences[2].frames[0], static_frames, seed);
    Sequence s{"static", clip, vmap::LoopGroundTruth(clip.size())};
    std::vector<vmap::Features> features;
    for (const auto& f : clip) features.push_back(orb.extract(f.image));
    const LoopRow r = run_loops(s, features);
    std::printf("- loops (bow, defaults): now %zu, before %zu; reported stationary: %s;", r.tp + r.fp,
                r.before_tp + r.before_fp, r.stationary ? "yes" : "no");
    for (const auto& [k, v] : r.statuses) std::printf(" %s %zu,", k.c_str(), v);
    std::vector<const vmap::Frame*> frames;
    for (const auto& f : clip) frames.push_back(&f);
    const auto mem = build_memory(frames);
    std::printf("\n- memory: %zu key images, %zu loop edges\n", mem.key_images(), mem.loops().size());
  }
  localization_section(sequences, shared);
  calibration_section(sequences, shared, small_width, trust_stack);
  sequence_section(sequences, shared, max_speed);
  small_section(sequences, shared, small_width);
  trust_section(sequences, shared, trust_stack);
  small_sequence_section(sequences, shared, small_width);
  rules_section(sequences, shared, small_width);
  return 0;
}
