// The offline loop run (runtime/loops.hpp): the evaluation of scores and of runs (with
// distractor key frames), the key-image ground truth, the run over synthetic laps against
// the LoopDetector it wraps, and on the shared RTAB-Map sequence the figures the command
// line has always printed.

#include "support/errors.hpp"
#include "support/shared_data.hpp"
#include "support/two_laps.hpp"

#include <vmap/features/orb.hpp>
#include <vmap/lcd/loop_detector.hpp>
#include <vmap/runtime/loop_detector.hpp>
#include <vmap/runtime/loops.hpp>

#include <doctest/doctest.h>

#include <opencv2/core.hpp>

#include <filesystem>
#include <fstream>
#include <memory>
#include <string>
#include <vector>

using vmap::test::error_of;

namespace {

/// A key image of a memory at frame `frame`, taken at `time` seconds.
vmap::KeyImage key_at(std::size_t frame, double time) {
  vmap::KeyImage k;
  k.frame_index = frame;
  k.timestamp = time;
  k.name = std::to_string(frame) + ".png";
  return k;
}

/// A decision for frame `frame`: `status`, best `best` at `confidence`.
vmap::LoopResult decision(std::size_t frame, vmap::PlaceStatus status, std::optional<std::size_t> best,
                          double confidence) {
  vmap::LoopResult r;
  r.frame = frame;
  r.status = status;
  r.best = best;
  r.confidence = confidence;
  return r;
}

}  // namespace

TEST_CASE("evaluation of scores: a known answer counted by hand") {
  // 6 frames; queries 3, 4 and 5 have a true loop (positives = 3).
  vmap::LoopGroundTruth gt(6);
  gt.set(3, 0, true);
  gt.set(4, 1, true);
  gt.set(5, 2, true);
  const std::vector<vmap::LoopScore> scores{{0, std::nullopt, 0.0}, {1, std::nullopt, 0.0}, {2, 0, 0.2},
                                            {3, 0, 0.9},            {4, 2, 0.7},            {5, 2, 0.6}};
  const vmap::LoopEvaluation e = vmap::evaluate_loop_scores(scores, gt, 0.5);
  CHECK(e.frames == 6);
  CHECK(e.positives == 3);
  CHECK(e.threshold == 0.5);
  CHECK(e.at_threshold.true_positives == 2);
  CHECK(e.at_threshold.false_positives == 1);
  CHECK(e.at_threshold.precision == 2.0 / 3.0);
  CHECK(e.at_full_precision.recall == 1.0 / 3.0);
  CHECK(e.at_full_precision.threshold == 0.9);
  REQUIRE(e.curve.size() == 4);
  CHECK(e.curve[2].threshold == 0.6);
  CHECK(e.ground_truth(4, 1));
  CHECK(e.verifications == 0);
  CHECK(error_of([&] { (void)vmap::evaluate_loop_scores(scores, gt, std::nan("")); }) ==
        "evaluate_loop_scores: the threshold must be finite");
}

TEST_CASE("evaluation of a run: a loop with a distractor key frame is false, the scores are the sequence's") {
  // Two distractors come first (detector frames 0 and 1); the sequence's frames 0..4 are
  // detector frames 2..6. Frame 4 closes a true loop with frame 0; frame 3 an accepted
  // loop with a distractor; frame 2 an unknown place (scored by its confidence); frame 1
  // is not a revisit (scored 0 whatever its confidence).
  vmap::LoopRun run;
  run.distractors = 2;
  run.results = {decision(2, vmap::PlaceStatus::too_little_evidence, std::nullopt, 0.0),
                 decision(3, vmap::PlaceStatus::not_a_revisit, 2, 0.8),
                 decision(4, vmap::PlaceStatus::unknown_place, 2, 0.3),
                 decision(5, vmap::PlaceStatus::accepted, 1, 0.7),
                 decision(6, vmap::PlaceStatus::accepted, 2, 0.9)};
  const auto scores = run.scores(5);
  REQUIRE(scores.size() == 5);
  CHECK(scores[1].query == 1);
  CHECK(scores[1].match == 0u);
  CHECK(scores[1].score == 0.0);
  CHECK(scores[2].score == 0.3);
  CHECK(scores[3].match == 5u);  // the distractor stands for itself as frame 5
  CHECK(scores[4].match == 0u);
  CHECK(scores[4].score == 0.9);

  vmap::LoopGroundTruth gt(5);
  gt.set(4, 0, true);
  gt.set(3, 0, true);
  const vmap::LoopEvaluation e = vmap::evaluate_loop_run(run, gt, 0.5);
  CHECK(e.frames == 5);
  CHECK(e.positives == 2);
  CHECK(e.at_threshold.true_positives == 1);
  CHECK(e.at_threshold.false_positives == 1);
  CHECK(e.at_full_precision.recall == 0.5);
  CHECK(e.at_full_precision.threshold == 0.9);
  CHECK(e.ground_truth.frames() == 5);

  CHECK(error_of([&] { (void)vmap::evaluate_loop_run(run, vmap::LoopGroundTruth(3), 0.5, "ground_truth"); }) ==
        "ground_truth: covers 3 frames but the run has 5");
  run.skipped = 1;
  CHECK(error_of([&] { (void)vmap::evaluate_loop_run(run, gt, 0.5); }) ==
        "1 frame(s) of the run could not be read; the ground truth is per frame, so the evaluation would be shifted");
}

TEST_CASE("the evaluation's score of a decision: the confidence where the threshold alone decides") {
  CHECK(vmap::evaluation_score(decision(0, vmap::PlaceStatus::accepted, 1, 0.7)) == 0.7);
  CHECK(vmap::evaluation_score(decision(0, vmap::PlaceStatus::unknown_place, 1, 0.2)) == 0.2);
  CHECK(vmap::evaluation_score(decision(0, vmap::PlaceStatus::ambiguous, 1, 0.9)) == 0.0);
  CHECK(vmap::evaluation_score(decision(0, vmap::PlaceStatus::not_a_revisit, 1, 0.9)) == 0.0);
}

TEST_CASE("key-image ground truth: the frames' marks between key images older than the window") {
  // Frames 0..7; the frames' ground truth marks (6, 0), (7, 2) and (5, 4).
  vmap::LoopGroundTruth frames(8);
  frames.set(6, 0, true);
  frames.set(7, 2, true);
  frames.set(5, 4, true);
  const std::vector<vmap::KeyImage> keys{key_at(0, 0.0), key_at(2, 0.2), key_at(4, 0.4), key_at(5, 0.5),
                                         key_at(7, 0.7)};
  const vmap::LoopGroundTruth w0 = vmap::key_image_ground_truth(frames, keys, 0, "--gt: 'gt.txt'");
  REQUIRE(w0.frames() == 5);
  CHECK(w0(4, 1));  // frames 7 -> 2
  CHECK(w0(3, 2));  // frames 5 -> 4: adjacent key images, kept without a window
  CHECK(w0.loop_frames() == 2);
  // Window 1: key images 3 and 2 are neighbours, so (5, 4) goes.
  const vmap::LoopGroundTruth w1 = vmap::key_image_ground_truth(frames, keys, 1, "--gt: 'gt.txt'");
  CHECK(w1(4, 1));
  CHECK_FALSE(w1(3, 2));
  CHECK(w1.loop_frames() == 1);
  // Frame 6 (a loop frame) is no key image: that loop is not the memory's to find.
  CHECK_FALSE(w0(4, 0));
  const std::vector<vmap::KeyImage> beyond{key_at(0, 0.0), key_at(9, 0.9)};
  CHECK(error_of([&] { (void)vmap::key_image_ground_truth(frames, beyond, 0, "--gt: 'gt.txt'"); }) ==
        "--gt: 'gt.txt' covers 8 frames, the memory has frame 9 (9.png)");
}

TEST_CASE("key-image ground truth from poses: each key image's pose by its time") {
  // TUM poses at 10 Hz along x, coming back to the start at t = 0.9; the key images'
  // times fall between poses (within 50 ms).
  const auto dir = vmap::test::scratch_dir("runtime_key_poses");
  const auto file = dir / "poses.txt";
  {
    std::ofstream out(file);
    for (int k = 0; k < 10; ++k) {
      const double x = k < 9 ? 0.5 * k : 0.1;
      out << 0.1 * k << " " << x << " 0 0 0 0 0 1\n";
    }
  }
  const std::vector<vmap::KeyImage> keys{key_at(0, 0.01), key_at(3, 0.31), key_at(6, 0.61), key_at(9, 0.89)};
  const vmap::LoopGroundTruth gt =
      vmap::key_image_ground_truth(file, keys, {.max_distance = 0.5, .max_angle_deg = 30.0, .window = 1});
  REQUIRE(gt.frames() == 4);
  CHECK(gt(3, 0));
  CHECK(gt.loop_frames() == 1);
  // A key image without a pose within 50 ms is an Error naming the file.
  const std::vector<vmap::KeyImage> late{key_at(0, 0.0), key_at(1, 5.0)};
  CHECK(error_of([&] { (void)vmap::key_image_ground_truth(file, late, {}); }).starts_with(file.string() + ": no pose"));
}

TEST_CASE("run_loops: the LoopDetector of the stack over every frame, and the loops it accepted") {
  // Two laps over 6 textured places: frame k of the second lap closes a loop with k - 6.
  constexpr int places = 6;
  std::vector<cv::Mat> images;
  for (int k = 0; k < 2 * places; ++k) images.push_back(vmap::test::lap_frame(k, places, 500));
  vmap::LoopRunOptions o;
  o.detector = {.window = 2, .index = vmap::CandidateIndex::brute_force};
  o.stack.features = 500;
  o.validate();
  std::vector<std::size_t> progress;
  const vmap::SequenceFeatures features =
      vmap::extract_features(images, o.stack, [&](std::size_t done, std::size_t total) {
        CHECK(total == images.size());
        progress.push_back(done);
      });
  CHECK(progress.size() == images.size());
  CHECK(features.names[3] == "3");
  CHECK(features.times[3] == 3.0);
  std::vector<std::size_t> seen;
  const vmap::LoopRun run =
      vmap::run_loops(o, features, {}, nullptr,
                      {.progress = {}, .on_result = [&](const vmap::LoopResult& r) { seen.push_back(r.frame); }});
  REQUIRE(run.results.size() == images.size());
  CHECK(seen.size() == images.size());
  CHECK(seen.back() == images.size() - 1);

  // The same frames through the library's LoopDetector of the same policies.
  vmap::LoopDetector direct(vmap::LabelSchema{}, vmap::OrbDescriptor({.features = 500}),
                            vmap::BruteForceMatcher({.mode = vmap::MatchMode::mutual}),
                            vmap::Calibrated<vmap::FundamentalEstimator>(
                                std::nullopt, vmap::FundamentalEstimator({.check_degeneracy = false})),
                            o.detector);
  std::size_t loops = 0;
  for (std::size_t k = 0; k < images.size(); ++k) {
    const vmap::LoopResult d = direct.add(features.frames[k], {});
    CHECK(run.results[k].status == d.status);
    CHECK(run.results[k].best == d.best);
    CHECK(run.results[k].confidence == d.confidence);
    CHECK(run.results[k].evidence.inliers == d.evidence.inliers);
    if (d.loop()) {
      REQUIRE(loops < run.loops.size());
      const vmap::DetectedLoop& l = run.loops[loops++];
      CHECK(l.query == k);
      CHECK(l.match == *d.best);
      CHECK(l.match_name == std::to_string(*d.best));
      CHECK(l.confidence == d.confidence);
      CHECK(l.pair().inliers == d.evidence.inliers);
    }
  }
  CHECK(loops == run.loops.size());
  CHECK(loops >= places / 2);
  for (const auto& l : run.loops) CHECK(l.query - l.match == places);
  CHECK(run.verifications == direct.verifications());
  CHECK(run.options.index == vmap::CandidateIndex::brute_force);
  CHECK(run.vocabulary == nullptr);

  // The whole run, learning its vocabulary on the frames, for a ranked source.
  o.detector.index = vmap::CandidateIndex::bow;
  o.vocabulary.learning = {.words = 64, .depth = 2, .seed = 1};
  std::vector<vmap::LoopStage> stages;
  const vmap::LoopRun ranked = vmap::detect_loops(
      features, o, nullptr, {.progress = [&](vmap::LoopStage s, std::size_t, std::size_t) { stages.push_back(s); }});
  CHECK(ranked.vocabulary_learned);
  REQUIRE(ranked.vocabulary != nullptr);
  CHECK(ranked.vocabulary->branching() == 8);
  CHECK(stages.front() == vmap::LoopStage::vocabulary);
  CHECK(stages.back() == vmap::LoopStage::loops);
  CHECK(vmap::to_string(vmap::LoopStage::vocabulary) == "vocabulary");

  // Labels for another number of frames, and a ranked source without a vocabulary.
  const vmap::PrecomputedDetections three(std::vector<std::vector<vmap::Detection>>(3));
  CHECK(error_of([&] { (void)vmap::run_loops(o, features, three, ranked.vocabulary); }) ==
        "the labels cover 3 frames but '<list of 12 frames>' has 12");
  CHECK(error_of([&] { (void)vmap::run_loops(o, features, {}, nullptr); }) ==
        "the bow candidate source needs a vocabulary");
  CHECK(error_of([&] { (void)vmap::detect_loops(vmap::SequenceFeatures::of({}, "none"), o, nullptr); }) ==
        "no frames to detect loops in ('none')");
}

TEST_CASE("AnyLoopDetector: one type for every stack, the decisions of the typed detector") {
  constexpr int places = 5;
  vmap::LoopOptions o{.window = 1, .index = vmap::CandidateIndex::brute_force};
  vmap::AnyLoopDetector any(vmap::PolicyStack{}, vmap::LabelSchema{}, o);
  vmap::LoopDetector typed(vmap::LabelSchema{}, vmap::OrbDescriptor{}, vmap::BruteForceMatcher({.mode = vmap::MatchMode::mutual}),
                           vmap::Calibrated<vmap::FundamentalEstimator>(
                               std::nullopt, vmap::FundamentalEstimator({.check_degeneracy = false})),
                           o);
  for (int k = 0; k < 2 * places; ++k) {
    const cv::Mat image = vmap::test::lap_frame(k, places, 700);
    const vmap::LoopResult a = any.push(image, {});
    const vmap::LoopResult t = typed.push(image, {});
    CHECK(a.frame == t.frame);
    CHECK(a.status == t.status);
    CHECK(a.best == t.best);
    CHECK(a.confidence == t.confidence);
  }
  CHECK(any.frames() == typed.frames());
  CHECK(any.verifications() == typed.verifications());
  CHECK(any.memory_bytes() == typed.memory_bytes());
  CHECK(any.options().window == 1);
  CHECK(any.stack() == vmap::PolicyStack{});
  // A ranked source without a vocabulary, bad options: the engine's errors.
  CHECK(error_of([] { vmap::AnyLoopDetector(vmap::PolicyStack{}, {}, {.index = vmap::CandidateIndex::bow}); })
            .starts_with("LoopOptions.index bow ranks by bag of words and needs a vocabulary"));
  CHECK(error_of([] {
          vmap::AnyLoopDetector(vmap::PolicyStack{}, {},
                                {.index = vmap::CandidateIndex::brute_force, .decision = {.min_confidence = 2.0}});
        }) == "LoopOptions.decision.min_confidence must be in [0, 1], got 2.000000");
}

TEST_SUITE("data") {
  TEST_CASE("the RTAB-Map loop sequence: the figures `vmap loops` has always printed") {
    const auto images = vmap::test::data_path("rtabmap_loop/images");
    const auto gt = vmap::LoopGroundTruth::load(vmap::test::data_path("rtabmap_loop/gt_loop_matrix_84x84.txt"), 84);
    const auto labels = vmap::load_labels({vmap::test::source_dir() / "examples/data/rtabmap_loop_yolox.txt"});
    vmap::LoopRunOptions o;
    o.detector.index = vmap::CandidateIndex::tree;
    o.every_frame = true;
    std::size_t extracted = 0;
    const vmap::LoopRun tree = vmap::detect_loops(images, o, &labels, {.progress = [&](vmap::LoopStage s, std::size_t d, std::size_t n) {
      if (s != vmap::LoopStage::features) return;
      extracted = d;
      CHECK(n == 84);
    }});
    CHECK(extracted == 84);
    CHECK(tree.names[0] == "1.jpg");
    CHECK(tree.schema.labels() == std::vector<int>{72});
    const vmap::LoopEvaluation e = vmap::evaluate_loop_run(tree, gt, o.detector.decision.min_confidence);
    CHECK(e.positives == 44);
    CHECK(e.verifications == 1785);
    // The revisit rule drops candidates in the query's own view (35 true loops and a
    // recall@100%P of 37 / 44 without it).
    CHECK(e.at_threshold.true_positives == 38);
    CHECK(e.at_threshold.false_positives == 0);
    CHECK(e.at_full_precision.recall == 40.0 / 44.0);
    CHECK(tree.loops.size() == 38);

    // bow with the vocabulary learned on the sequence (1000 words, k = 10, L = 3).
    o.detector.index = vmap::CandidateIndex::bow;
    const vmap::LoopRun bow = vmap::detect_loops(images, o, nullptr);
    REQUIRE(bow.vocabulary_learned);
    const vmap::LoopEvaluation b = vmap::evaluate_loop_run(bow, gt, o.detector.decision.min_confidence);
    CHECK(b.verifications == 141);
    CHECK(b.at_threshold.true_positives == 39);
    CHECK(b.at_threshold.false_positives == 0);
    CHECK(b.at_full_precision.recall == 42.0 / 44.0);

    // The same frames fed one by one to the type-erased detector with that vocabulary.
    vmap::AnyLoopDetector detector(o.stack, vmap::LabelSchema{}, o.detector, bow.vocabulary);
    auto frames = vmap::FrameSource::open(images, {.grey = true});
    std::size_t k = 0;
    while (auto f = frames.next()) {
      const vmap::LoopResult r = detector.push(f->image, {});
      CHECK(r.status == bow.results[k].status);
      CHECK(r.best == bow.results[k].best);
      CHECK(r.confidence == bow.results[k].confidence);
      ++k;
    }
    CHECK(detector.verifications() == bow.verifications);
  }
}
