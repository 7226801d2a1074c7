// `vmap loops`: loop closure over a sequence. Prints the loops found (query frame,
// matched frame, inliers, bag-of-words score); with ground truth, also the evaluation.
//
//   vmap loops ../shared/data/rtabmap_loop/images --labels examples/data/rtabmap_loop_yolox.txt
//   vmap loops ../shared/data/rtabmap_loop/images
//       --gt ../shared/data/rtabmap_loop/gt_loop_matrix_84x84.txt
//       --labels examples/data/rtabmap_loop_yolox.txt --out pr
//
// Candidates (--rank): tree (LFM-LCD: every frame of the label tree's leaf), tree_ranked
// (the leaf ranked by bag-of-words score, the top k verified; the default with labels),
// bow (every older frame ranked, no labels; the default without), brute_force (every frame
// older than the window). The ranked modes need a vocabulary: --vocabulary FILE
// (from `vmap vocabulary`), else one is learned on the sequence itself.
// Labels come from precomputed-detections files (--labels; several files, e.g. of
// different COCO detectors, are pooled into one label source) or from a cv::dnn detector
// run here (--detector yolox --model MODEL.onnx). Ground truth is a 0/1 matrix (--gt) or derived from
// TUM poses (--gt-poses, with --gt-distance / --gt-angle).
//
// With --memory M instead of INPUT it prints the loop edges a saved visual memory holds
// (`vmap build --memory`), evaluated over its key images with --gt / --gt-poses.
#include "common/cli_support.hpp"
#include "common/lcd_plot.hpp"
#include "common/memory_cli.hpp"
#include "common/policies.hpp"
#include "common/vocabulary_cli.hpp"
#include "vmap/cli.hpp"

#include <vmap/hooks/class_names.hpp>
#include <vmap/hooks/dnn_detectors.hpp>
#include <vmap/io/atomic_file.hpp>
#include <vmap/io/exports.hpp>
#include <vmap/io/frame_source.hpp>
#include <vmap/io/poses.hpp>
#include <vmap/lcd/evaluation.hpp>
#include <vmap/runtime/loop_detector.hpp>
#include <vmap/runtime/loops.hpp>
#include <vmap/runtime/option_names.hpp>

#include <nlohmann/json.hpp>

#include <algorithm>
#include <chrono>
#include <cstdio>
#include <memory>
#include <optional>
#include <string>
#include <vector>

namespace {

namespace ex = vmap::examples;

struct LoopsArgs {
  std::string input;
  std::string gt;
  std::string gt_poses;
  double gt_distance = 0.5;
  double gt_angle = 30.0;
  std::vector<std::string> labels;
  std::string detector;
  std::string model;
  std::string names;
  std::string rank;  // empty: tree_ranked with labels, bow without (vmap::default_candidate_index)
  bool json = false;
  bool verbose = false;
  std::string out;
  std::string memory;  // --memory M: the loop edges of a saved visual memory
  std::string robot;   // --robot NAME: the robot of a fleet's memory (M a postgresql:// URI)
  double time_offset = 0.0;
  bool edges = false;  // --memory: every loop edge instead of a summary
  ex::DescriptorChoice descriptor;  // --features, --nfeatures, --features-model, --refine-model
  vmap::LoopRunOptions options;
  std::optional<double> chance_rate;  // --chance-rate: unset, the rate measured for the stack
};

/// The names of `vmap loops`'s options in the library's messages: the descriptor's model
/// is --features-model (--model is the detector's), and labels come from either source.
vmap::OptionNames option_names() {
  return vmap::OptionNames::command_line(
      {{"model", "--features-model"}, {"labels", "--labels FILE or --detector NAME --model PATH"}});
}

/// `vmap loops --memory M [--gt MATRIX | --gt-poses POSES] [--json]`.
int run_memory(const LoopsArgs& a, const CLI::App& app) {
  ex::refuse_other_options(app, {"--memory", "--robot", "--gt", "--gt-poses", "--gt-distance", "--gt-angle", "--json", "--edges"},
                           "--memory");
  if (!a.gt.empty() && !a.gt_poses.empty()) ex::usage_error("give at most one of --gt MATRIX and --gt-poses POSES");
  const auto file = vmap::memory_path(a.memory);
  ex::current_inputs() = {file.string()};
  for (const auto& [path, option] : {std::pair{a.gt, "--gt"}, std::pair{a.gt_poses, "--gt-poses"}})
    if (!path.empty()) ex::check_input_file(path, option);
  const auto mem = ex::open_memory_input(file, "--memory", false, a.robot);
  {
    const double min_confidence = mem.options().loops.decision.min_confidence;
    nlohmann::json loops = nlohmann::json::array();
    for (const auto& e : mem.loops()) loops.push_back(ex::loop_json(mem, e));
    nlohmann::json j{{"command", "loops"},
                     {"memory", ex::path_string(file)},
                     {"frames", mem.frames()},
                     {"key_images", mem.key_images()},
                     {"min_confidence", min_confidence},
                     {"stationary", mem.stationary()},
                     {"loops", loops}};
    if (a.gt.empty() && a.gt_poses.empty()) {
      if (a.json) {
        ex::print_json(j);
        return 0;
      }
      std::printf("memory %s: %zu frames, %zu key images\n", ex::path_string(file).c_str(), mem.frames(), mem.key_images());
      if (mem.stationary()) std::printf("the camera never left its place: no key image is a revisit\n");
      std::printf("%zu loop edges (confidence >= %.2f):\n", mem.loops().size(), min_confidence);
      ex::print_loop_edges(mem, a.edges);
      return 0;
    }
    // Each key image proposes its most confident edge, as each query frame proposes its
    // best candidate in the frame-level evaluation (lcd/evaluation.hpp).
    const auto& keys = mem.map().keys;
    const std::size_t window = mem.options().loops.window;
    const auto gt = a.gt_poses.empty()
                        ? vmap::key_image_ground_truth(vmap::LoopGroundTruth::load(a.gt), keys, window, "--gt: '" + a.gt + "'")
                        : vmap::key_image_ground_truth(
                              a.gt_poses, keys, {.max_distance = a.gt_distance, .max_angle_deg = a.gt_angle, .window = window});
    std::vector<vmap::LoopScore> scores(mem.key_images());
    for (std::size_t k = 0; k < scores.size(); ++k) scores[k].query = k;
    std::size_t true_edges = 0;
    for (const auto& e : mem.loops()) {
      auto& s = scores[e.from];
      if (!s.match || e.link.confidence > s.score) {
        s.match = e.link.key;
        s.score = e.link.confidence;
      }
      true_edges += gt(e.from, e.link.key) ? 1 : 0;
    }
    const auto pr = vmap::evaluate_loops(scores, gt, min_confidence);
    const auto full = vmap::recall_at_full_precision(vmap::precision_recall_curve(scores, gt));
    for (auto& l : loops) l["true"] = gt(l["from"].get<std::size_t>(), l["to"].get<std::size_t>());
    if (a.json) {
      j["loops"] = loops;
      j["loops_gt"] = pr.positives;
      j["true_positives"] = pr.true_positives;
      j["false_positives"] = pr.false_positives;
      j["precision"] = ex::finite_or_null(pr.precision);
      j["recall"] = ex::finite_or_null(pr.recall);
      j["recall_at_100_precision"] = ex::finite_or_null(full.recall);
      j["true_edges"] = true_edges;
      ex::print_json(j);
      return 0;
    }
    std::printf("memory %s: %zu frames, %zu key images, %zu with a ground-truth loop to a key image %zu or more before\n",
                ex::path_string(file).c_str(), mem.frames(), mem.key_images(), pr.positives, mem.options().loops.window + 1);
    std::printf("%zu loop edges (confidence >= %.2f), %zu true:\n", mem.loops().size(), min_confidence, true_edges);
    ex::print_loop_edges(mem, a.edges);
    std::printf("key images (best edge each): TP %zu, FP %zu, precision %.3f, recall %.3f; recall@100%%P %.3f\n",
                pr.true_positives, pr.false_positives, pr.precision, pr.recall, full.recall);
    return 0;
  }
}

int run(LoopsArgs& a, const CLI::App& app) {
  auto& o = a.options;
  const vmap::OptionNames cli = option_names();
  ex::current_inputs() = {a.input};
  const bool have_labels = !a.labels.empty() || !a.detector.empty();
  o.detector.index = a.rank.empty() ? vmap::default_candidate_index(have_labels, true)
                                    : *vmap::from_string<vmap::CandidateIndex>(a.rank);
  const std::string rank(vmap::to_string(o.detector.index));
  if (!a.gt.empty() && !a.gt_poses.empty()) ex::usage_error("give at most one of --gt MATRIX and --gt-poses POSES");
  if (!a.labels.empty() && !a.detector.empty()) ex::usage_error("give --labels or --detector, not both");
  ex::as_usage([&] { vmap::check_candidate_source(o.detector.index, have_labels, true, cli); });
  const bool uses_tree = vmap::uses_labels(o.detector.index);
  if (!a.detector.empty() && a.model.empty()) ex::usage_error("--detector " + a.detector + " needs --model PATH");
  if (a.detector.empty() && !a.model.empty())
    ex::usage_error("--model is the detector's model: give --detector yolox|nanodet|fastestdet (the descriptor's "
                    "model is --features-model)");
  o.stack = ex::stack_of(a.descriptor, "magsac", std::nullopt, cli);
  o.detector.decision.chance_inlier_rate = a.chance_rate.value_or(vmap::measured_chance_rate(o.stack));
  ex::as_usage([&] { o.validate(cli); });
  // Every input, and every output checked against them, before any frame is read.
  std::vector<std::filesystem::path> inputs{a.input};
  for (const auto& [file, option] : {std::pair{a.gt, "--gt"}, std::pair{a.gt_poses, "--gt-poses"},
                                     std::pair{a.model, "--model"}, std::pair{a.names, "--names"},
                                     std::pair{a.descriptor.model, "--features-model"},
                                     std::pair{a.descriptor.refine_model, "--refine-model"},
                                     std::pair{o.vocabulary.file.string(), "--vocabulary"}})
    if (!file.empty()) {
      ex::check_input_file(file, option);
      inputs.push_back(file);
    }
  for (const auto& l : a.labels) {
    ex::check_input_file(l, "--labels");
    inputs.push_back(l);
  }
  std::optional<ex::OutputFolder> out_dir;
  if (!a.out.empty())
    out_dir.emplace(a.out, "--out", inputs, std::vector<std::string>{"pr.csv", "pr.png", "loops.txt", "loops.g2o"});
  const std::vector<std::string> names = a.names.empty() ? std::vector<std::string>{} : vmap::read_class_names(a.names);

  // The ground truth is checked against the sequence before any frame is processed.
  const auto sequence = ex::open_frames(a.input, {.time_offset = a.time_offset});
  const std::size_t total = sequence.total().value_or(0);
  std::optional<vmap::LoopGroundTruth> gt;
  std::vector<vmap::CameraPose> frame_poses;  // with --gt-poses: one per frame, for loops.g2o
  if (!a.gt_poses.empty()) {
    frame_poses = vmap::frame_poses(a.gt_poses, sequence.timestamps());
    gt = vmap::ground_truth_from_poses(
        frame_poses, {.max_distance = a.gt_distance, .max_angle_deg = a.gt_angle, .window = o.detector.window});
  } else if (!a.gt.empty()) {
    gt = vmap::LoopGroundTruth::load(a.gt, total);
  }
  o.every_frame = gt.has_value();

  std::optional<vmap::PrecomputedDetections> labels;
  double detect_seconds = 0.0;
  if (!a.labels.empty()) {
    labels = vmap::load_labels({a.labels.begin(), a.labels.end()});
  } else if (!a.detector.empty()) {
    auto detector = vmap::make_dnn_detector(vmap::parse_detector_format(a.detector),
                                            {.model = a.model, .score_threshold = o.detector.labels.min_score});
    auto source = ex::open_frames(a.input);
    ex::Progress progress("vmap loops: detector", source.total());
    labels = vmap::detect_labels(source, detector, [&](std::size_t done, std::size_t) { progress.update(done); });
    detect_seconds = progress.seconds();
    progress.done();
  }
  auto label_name = [&](int label) {
    return names.empty() ? std::to_string(label) : vmap::class_name(names, label);
  };

  // Progress on stderr, one meter per stage; the skipped frames are listed as they come.
  std::optional<ex::Progress> extracting;
  extracting.emplace("vmap loops: features", total);
  std::optional<ex::Progress> looping;
  std::size_t frames_read = 0, skipped = 0;
  const auto end_extraction = [&] {
    if (extracting) extracting->done(std::to_string(skipped) + " skipped");
    extracting.reset();
  };
  vmap::LoopRunCallbacks callbacks;
  callbacks.progress = [&](vmap::LoopStage stage, std::size_t done, std::size_t n) {
    if (stage == vmap::LoopStage::features) {
      frames_read = done;
      extracting->update(done);
    } else if (stage == vmap::LoopStage::vocabulary && done == 0) {
      end_extraction();
      std::fprintf(stderr, "no --vocabulary: learning one on the sequence itself (%zu frames, branching %d, depth %d)\n",
                   frames_read, o.vocabulary.learning.branching(), o.vocabulary.learning.depth);
    } else if (stage == vmap::LoopStage::loops) {
      end_extraction();
      if (!looping) looping.emplace("vmap loops", n);
      looping->update(done);
    }
  };
  if (a.verbose)
    callbacks.on_result = [](const vmap::LoopResult& r) {
      std::fprintf(stderr, "frame %3zu  candidates %3zu  verified %3zu  best %4s  inliers %4d  confidence %.2f  %s: %s (%s)\n",
                   r.frame, r.candidates, r.verifications, r.best ? std::to_string(*r.best).c_str() : "-",
                   r.evidence.inliers, r.confidence, std::string(vmap::to_string(r.status)).c_str(),
                   std::string(vmap::to_string(r.reason_code)).c_str(), r.reason.c_str());
    };
  vmap::FrameSourceOptions frame_options = ex::with_bag_options(a.input, ex::reporting_skips({.time_offset = a.time_offset}));
  frame_options.on_skip = [&, report = frame_options.on_skip](const vmap::SkippedFrame& sk) {
    ++skipped;
    report(sk);
  };
  const vmap::LoopRun result = vmap::detect_loops(a.input, o, labels ? &*labels : nullptr, callbacks, frame_options);
  end_extraction();
  if (looping) looping->done();
  std::string vocabulary_note;
  if (result.vocabulary) {
    char buf[120];
    std::snprintf(buf, sizeof buf, " (%zu words, %.2f s)", result.vocabulary->size(), result.vocabulary_seconds);
    vocabulary_note = (result.vocabulary_learned ? std::string("vocabulary learned on the sequence itself")
                                                 : "vocabulary " + o.vocabulary.file.string()) +
                      buf;
  }
  const std::size_t frames = result.results.size();
  const double fps = result.seconds > 0 ? static_cast<double>(frames) / result.seconds : 0.0;

  nlohmann::json loops = nlohmann::json::array();
  std::vector<vmap::LoopPair> pairs;
  std::string g2o_edges;
  std::vector<bool> g2o_vertex(frame_poses.size(), false);
  for (const vmap::DetectedLoop& l : result.loops) {
    pairs.push_back(l.pair());
    if (l.query < frame_poses.size() && l.match < frame_poses.size()) {
      g2o_edges += vmap::g2o_edge_line(l.query, l.match, frame_poses[l.query], frame_poses[l.match]);
      g2o_vertex[l.query] = g2o_vertex[l.match] = true;
    }
    loops.push_back({{"query", l.query},
                     {"match", l.match},
                     {"query_name", l.query_name},
                     {"match_name", l.match_name},
                     {"query_time", l.query_time},
                     {"match_time", l.match_time},
                     {"confidence", l.confidence},
                     {"inliers", l.evidence.inliers},
                     {"matches", l.evidence.matches},
                     {"inlier_ratio", l.evidence.inlier_ratio},
                     {"significance", l.evidence.significance},
                     {"spread", l.evidence.spread},
                     {"bow_score", l.evidence.bow_score}});
  }
  const bool stationary = result.stationary;

  // --out: the loops as a timestamp-pair list, and with --gt-poses as g2o edges between
  // the frames' ground-truth poses; pr.csv and pr.png below when there is a ground truth.
  std::vector<std::string> written;
  if (out_dir) {
    vmap::write_file_atomically(out_dir->operator/("loops.txt"), vmap::loop_pairs_text(pairs));
    written.push_back("loops.txt");
    if (!frame_poses.empty()) {
      std::string g2o;
      for (std::size_t k = 0; k < frame_poses.size(); ++k)
        if (g2o_vertex[k]) g2o += vmap::g2o_vertex_line(k, frame_poses[k]);
      vmap::write_file_atomically(out_dir->operator/("loops.g2o"), g2o + g2o_edges);
      written.push_back("loops.g2o");
    }
  }
  if (!gt) {
    if (out_dir) out_dir->commit();
    if (a.json) {
      nlohmann::json j = {{"command", "loops"},
                          {"input", ex::path_string(a.input)},
                          {"options", ex::options_json(app)},
                          {"frames", frames},
                          {"skipped_frames", result.skipped},
                          {"rank", rank},
                          {"verifications", result.verifications},
                          {"seconds", result.seconds},
                          {"fps", fps},
                          {"min_confidence", o.detector.decision.min_confidence},
                          {"stationary", stationary},
                          {"out", a.out.empty() ? nlohmann::json(nullptr) : nlohmann::json(ex::path_string(a.out))},
                          {"files", written},
                          {"loops", loops}};
      ex::print_json(j);
      return 0;
    }
    std::printf("frames %zu (%zu skipped), candidates %s%s%s; %zu verifications (%.1f per frame), %.2f s (%.1f frames/s)\n",
                frames, result.skipped, rank.c_str(), vocabulary_note.empty() ? "" : ", ", vocabulary_note.c_str(),
                result.verifications,
                static_cast<double>(result.verifications) / static_cast<double>(std::max<std::size_t>(1, frames)),
                result.seconds, fps);
    if (stationary) std::printf("the camera never left its place: no frame is a revisit\n");
    std::printf("%zu loops (confidence >= %.2f):\n", loops.size(), o.detector.decision.min_confidence);
    for (const vmap::DetectedLoop& l : result.loops)
      std::printf("  frame %4zu (%s) -> frame %4zu (%s)  confidence %.2f  inliers %4d of %4d  bow score %.3f\n", l.query,
                  l.query_name.c_str(), l.match, l.match_name.c_str(), l.confidence, l.evidence.inliers,
                  l.evidence.matches, l.evidence.bow_score);
    if (!written.empty()) std::printf("wrote %s\n", ex::written_files(a.out, written).c_str());
    return 0;
  }

  const vmap::LoopEvaluation s = vmap::evaluate_loop_run(result, *gt, o.detector.decision.min_confidence);
  const auto agree = result.agreement(*gt, o.detector.window);

  if (out_dir) {
    std::string csv = "threshold,true_positives,false_positives,precision,recall\n";
    char buf[160];
    for (const auto& p : s.curve) {
      std::snprintf(buf, sizeof buf, "%g,%zu,%zu,%.6f,%.6f\n", p.threshold, p.true_positives, p.false_positives,
                    p.precision, p.recall);
      csv += buf;
    }
    vmap::write_file_atomically(out_dir->operator/("pr.csv"), csv);
    const std::filesystem::path p = std::filesystem::path(a.input).lexically_normal();
    char title[200];
    std::snprintf(title, sizeof title, "%s, %s: recall@100%%P %.3f, %zu verifications",
                  (p.parent_path().filename() / p.filename()).string().c_str(), rank.c_str(),
                  s.at_full_precision.recall, s.verifications);
    vmap::write_image_atomically(out_dir->operator/("pr.png"),
                                 vmap::examples::draw_pr_curves({{s.curve, "vmap " + rank}}, title));
    out_dir->commit();
    written.push_back("pr.csv");
    written.push_back("pr.png");
  }

  if (a.json) {
    nlohmann::json kept = nlohmann::json::array();
    for (int l : result.schema.labels()) kept.push_back(label_name(l));
    nlohmann::json j = {{"command", "loops"},
                        {"input", ex::path_string(a.input)},
                        {"options", ex::options_json(app)},
                        {"frames", s.frames},
                        {"skipped_frames", result.skipped},
                        {"loops_gt", s.positives},
                        {"true_positives", s.at_threshold.true_positives},
                        {"false_positives", s.at_threshold.false_positives},
                        {"precision", ex::finite_or_null(s.at_threshold.precision)},
                        {"recall", ex::finite_or_null(s.at_threshold.recall)},
                        {"recall_at_100_precision", ex::finite_or_null(s.at_full_precision.recall)},
                        {"verifications", s.verifications},
                        {"seconds", result.seconds},
                        {"fps", fps},
                        {"rank", rank},
                        {"top_k", o.detector.top_k},
                        {"min_confidence", o.detector.decision.min_confidence},
                        {"stationary", stationary},
                        {"threshold_at_100_precision", s.at_full_precision.true_positives > 0
                                                           ? nlohmann::json(s.at_full_precision.threshold)
                                                           : nlohmann::json(nullptr)},
                        {"labels_kept", result.schema.labels()},
                        {"labels_kept_names", kept},
                        {"detector_seconds", detect_seconds},
                        {"distinct_label_vectors", agree.distinct_vectors},
                        {"equal_vector_pairs", agree.leaf_pairs},
                        {"loop_queries", agree.loop_queries},
                        {"loop_queries_with_equal_vector", agree.reachable_queries},
                        {"out", a.out.empty() ? nlohmann::json(nullptr) : nlohmann::json(ex::path_string(a.out))},
                        {"files", written},
                        {"loops", loops}};
    ex::print_json(j);
    return 0;
  }
  std::printf("frames %zu, query frames with a ground-truth loop %zu\n", s.frames, s.positives);
  if (uses_tree) {
    std::printf("labels (score >= %.2f, eq. 5 influence in [%.2f, %.2f]), large to small:\n",
                static_cast<double>(o.detector.labels.min_score), o.influence.min_influence, o.influence.max_influence);
    for (const auto& l : result.influence)
      std::printf("  %-14s  E = %.3f  mean area %8.0f px^2  %s\n", label_name(l.label).c_str(), l.influence,
                  l.mean_area, l.kept ? "kept" : "dropped");
    std::printf("tree depth %zu, window %zu, m = %zu\n", result.schema.size(), o.detector.window,
                o.detector.min_candidates);
    std::printf("label vectors: %zu distinct; %zu of %zu pairs have equal vectors (the tree verifies at least these, "
                "<= %.1fx fewer than brute force); %zu of %zu query frames with a loop have a true loop frame of "
                "their own vector\n",
                agree.distinct_vectors, agree.leaf_pairs, agree.pairs, agree.max_reduction(), agree.reachable_queries,
                agree.loop_queries);
  }
  if (!vocabulary_note.empty()) std::printf("%s, top k %zu\n", vocabulary_note.c_str(), o.detector.top_k);
  std::printf("candidates %s: %zu verifications (%.1f per frame), %.2f s (%.1f frames/s)%s\n", rank.c_str(),
              s.verifications,
              static_cast<double>(s.verifications) / static_cast<double>(std::max<std::size_t>(1, frames)),
              result.seconds, result.seconds > 0 ? static_cast<double>(frames) / result.seconds : 0.0,
              detect_seconds > 0 ? "" : " (detections precomputed)");
  if (detect_seconds > 0) std::printf("detector: %.2f s\n", detect_seconds);
  if (stationary) std::printf("the camera never left its place: no frame is a revisit\n");
  std::printf("at confidence >= %.2f: TP %zu, FP %zu, precision %.3f, recall %.3f\n", o.detector.decision.min_confidence,
              s.at_threshold.true_positives, s.at_threshold.false_positives, s.at_threshold.precision,
              s.at_threshold.recall);
  if (!written.empty()) std::printf("wrote %s\n", ex::written_files(a.out, written).c_str());
  if (s.at_full_precision.true_positives > 0)
    std::printf("recall@100%%P %.3f (at confidence >= %.3f)\n", s.at_full_precision.recall, s.at_full_precision.threshold);
  else
    std::printf("recall@100%%P 0.000 (no threshold without a false positive)\n");
  return 0;
}

/// The one-line note of an old spelling that still works for one release, on stderr so
/// that --json output stays parseable: "vmap loops: note: --index is now --rank; --index
/// will be removed in the next release".
void old_spelling(const char* old, const char* now, const char* removed) {
  std::fprintf(stderr, "vmap loops: note: %s is now %s; %s will be removed in the next release\n", old, now, removed);
}

std::function<int()> setup(CLI::App& app) {
  auto a = std::make_shared<LoopsArgs>();
  auto& d = a->options.detector;
  app.add_option("input", a->input, "Frames: image folder, list file, video, TUM rgb.txt or a bag (or --memory M)");
  ex::add_bag_options(app);
  app.add_option("--gt", a->gt, "Ground-truth loop matrix (rows of 0/1, row = query frame)");
  app.add_option("--gt-poses", a->gt_poses, "Derive the ground truth from poses (TUM, KITTI or EuRoC data.csv; one a frame, or associated to the frames' times within 50 ms)");
  ex::add_time_offset_option(app, a->time_offset);
  app.add_option("--gt-distance", a->gt_distance, "With --gt-poses: max. camera-centre distance, metres")
      ->check(ex::real_in(0.0, 1e6, true));
  app.add_option("--gt-angle", a->gt_angle, "With --gt-poses: max. angle between viewing directions, degrees")
      ->check(ex::real_in(0.0, 180.0, true));
  app.add_option("--labels", a->labels,
                 "Precomputed detections (frame label score x y w h), e.g. detections.txt of vmap detect --out; "
                 "several files (comma-separated) are pooled, a label being present when any file has it")
      ->delimiter(',');
  app.add_option("--detector", a->detector, "Run a cv::dnn detector over the frames instead of --labels: "
                 "yolox, nanodet or fastestdet (with --model)")
      ->check(CLI::IsMember({"yolox", "nanodet", "fastestdet"}));
  app.add_option("--model", a->model, "ONNX model file of --detector");
  app.add_option("--names", a->names, "Class names, one a line (e.g. coco80.names): printed instead of label ids");
  // The library's names (from_string), which also read `all`, brute_force's old spelling;
  // the help and the message offer only the current ones. --index is --rank's old spelling.
  const std::string offered = "{tree,tree_ranked,bow,brute_force}";
  const CLI::Validator sources(
      [offered](std::string& v) {
        return vmap::from_string<vmap::CandidateIndex>(v) ? std::string() : v + " not in " + offered;
      },
      offered);
  app.add_option("--rank", a->rank,
                 "Candidates: tree (LFM-LCD), tree_ranked (the tree's leaf ranked by bag of words, top k verified), "
                 "bow (every older frame ranked, no labels) or brute_force (every frame older than the window). "
                 "Default: tree_ranked with labels, bow without")
      ->check(sources);
  app.add_option("--index", a->rank, "Old spelling of --rank")->check(sources)->group("");
  app.add_option("--top-k", d.top_k, "tree_ranked / bow: verify this many best-ranked candidates")
      ->check(ex::count_in(1, 1000000));
  app.add_option("--min-bow-score", d.min_bow_score, "tree_ranked / bow: do not verify candidates scoring below this")
      ->check(ex::real_in(0.0, 1.0));
  app.add_option("--temporal", d.temporal_consistency,
                 "Accept a loop only when this many previous frames matched a nearby place (0: off)")
      ->check(ex::count_in(0, 1000));
  app.add_option("--vocabulary", a->options.vocabulary.file,
                 "tree_ranked / bow: a vocabulary from `vmap vocabulary` (default: learn one on the sequence)");
  ex::add_vocabulary_options(app, a->options.vocabulary.learning, "Vocabulary learned here: ");
  app.add_option("--window", d.window, "Frames this recent are never candidates")->check(ex::count_in(0, 1000000));
  app.add_option("--left-ratio", d.left_ratio,
                 "Revisit rule: a candidate's place was left when a view in between began with a frame whose "
                 "similarity to it (eq. 5) is below this fraction of the query's")
      ->check(ex::real_in(0.0, 1.0));
  app.add_option("--min-candidates", d.min_candidates, "m: backtrack up the tree until this many candidates")
      ->check(ex::count_in(1, 1000000));
  app.add_option("--min-confidence", d.decision.min_confidence,
                 "Decision threshold: a loop's confidence in [0, 1] (0.5: inliers a chance alignment gives 1 in 10^12)")
      ->check(ex::real_in(0.0, 1.0));
  app.add_option("--chance-rate", a->chance_rate,
                 "The place decision's chance-inlier rate (default: the rate measured for the descriptor, "
                 "vmap::measured_chance_rate)")
      ->check(ex::real_in(0.0001, 0.9));
  app.add_option("--min-inliers", d.decision.min_inliers, "Below this many inliers a candidate is not weighed")
      ->check(ex::count_in(0, 1000000));
  app.add_option("--score", d.labels.min_score, "Detections below this score are ignored")->check(ex::real_in(0.0, 1.0));
  app.add_option("--min-influence", a->options.influence.min_influence, "Drop labels present in fewer frames (eq. 5)")
      ->check(ex::real_in(0.0, 1.0));
  app.add_option("--max-influence", a->options.influence.max_influence, "Drop labels present in more frames (eq. 5)")
      ->check(ex::real_in(0.0, 1.0));
  app.add_option("--label-order", a->options.label_order, "Label ids from large to small objects (default: by mean box area)")
      ->delimiter(',');
  app.add_option("--sample", a->options.sample, "Frames whose labels form the eq. 5 sample (0: all)")
      ->check(ex::count_in(0, ex::max_frame_index));
  app.add_option("--features", a->descriptor.name,
                 "orb, akaze, sift, xfeat, xfeat-dense or xfeat-star (the last three need --features-model; xfeat-star "
                 "also --refine-model)");
  app.add_option("--features-model", a->descriptor.model, "Model file of a learned descriptor (xfeat, xfeat-dense, xfeat-star)");
  app.add_option("--refine-model", a->descriptor.refine_model,
                 "xfeat-star: XFeat*'s refinement network (xfeat_fine.onnx), run once per verified pair");
  app.add_option("--nfeatures", a->descriptor.features,
                 "Keypoint budget per image (ORB, SIFT; top-k for XFeat), at most " + std::to_string(ex::max_nfeatures))
      ->check(ex::count_in(1, ex::max_nfeatures));
  app.add_option("--out", a->out,
                 "Folder (created if missing) for loops.txt (each loop as query_time match_time query_name match_name "
                 "inliers), with --gt-poses loops.g2o (the loops as g2o edges between the frames' ground-truth poses), "
                 "and with a ground truth pr.csv (threshold, TP, FP, precision, recall) and pr.png");
  app.add_flag("--json", a->json, "Print the figures as one JSON object on stdout");
  app.add_flag("--verbose", a->verbose,
               "Print one line per frame to stderr (candidates, best, inliers, confidence, status and reason)");
  app.add_option("--memory", a->memory,
                 "Instead of INPUT: the loop edges of a saved visual memory (vmap build --memory; a folder means "
                 "DIR/memory.vmdb), evaluated over its key images with --gt / --gt-poses");
  app.add_flag("--edges", a->edges, "With --memory: list every loop edge (default: a summary and the 5 strongest)");
  ex::add_robot_option(app, a->robot);
  return [a, &app] {
    if (app.count("--index") > 0) {
      old_spelling("--index", "--rank", "--index");
      if (app.count("--rank") > 0) ex::usage_error("give --rank only (--index is its old spelling)");
      // The JSON's options name the value by its new spelling, as if --rank had been given.
      app.get_option("--rank")->add_result(a->rank);
    }
    if (a->rank == "all") old_spelling("--rank all", "--rank brute_force", "all");
    if (!a->memory.empty()) return run_memory(*a, app);
    if (a->input.empty()) ex::usage_error("give INPUT (the frames) or --memory M (a saved visual memory)");
    return run(*a, app);
  };
}

const bool registered = vmap::cli::add_command({"loops", "Loop closure: the loops of a sequence, evaluated with --gt", setup});

}  // namespace
