// `vmap loops`: LFM-LCD loop closure over a sequence, evaluated against ground truth.
//
//   vmap loops ../shared/data/rtabmap_loop/images
//       --gt ../shared/data/rtabmap_loop/gt_loop_matrix_84x84.txt
//       --labels examples/data/rtabmap_loop_yolox.txt --plot pr.png --csv pr.csv
//
// Labels come from precomputed-detections files (--labels; several files, e.g. of
// different COCO detectors, are pooled into one label source) or from a cv::dnn detector
// run here (--detector MODEL.onnx). Ground truth is a 0/1 matrix (--gt) or derived from
// TUM poses (--gt-poses, with --gt-distance / --gt-angle). `--index all` verifies every
// frame older than the window instead of asking the tree (the brute-force reference).
#include "common/lcd_plot.hpp"
#include "common/lcd_run.hpp"
#include "vmap/cli.hpp"

#include <vmap/hooks/dnn_detectors.hpp>
#include <vmap/io/atomic_file.hpp>
#include <vmap/io/frame_source.hpp>
#include <vmap/io/poses.hpp>

#include <nlohmann/json.hpp>

#include <algorithm>
#include <cctype>
#include <chrono>
#include <cstdio>
#include <memory>
#include <string>
#include <vector>

namespace {

struct LoopsArgs {
  std::string input;
  std::string gt;
  std::string gt_poses;
  double gt_distance = 0.5;
  double gt_angle = 30.0;
  std::vector<std::string> labels;
  std::string detector;
  std::string detector_format;
  std::string index = "tree";
  std::vector<int> label_order;
  bool json = false;
  bool verbose = false;
  std::string csv;
  std::string plot;
  vmap::examples::LoopRunConfig config;
};

std::string lower(std::string s) {
  std::transform(s.begin(), s.end(), s.begin(), [](unsigned char c) { return static_cast<char>(std::tolower(c)); });
  return s;
}

/// Runs the cv::dnn detector over every frame once; its detections feed both the eq. 5
/// sample and the loop detector (the schema needs the sample before the first query).
vmap::PrecomputedDetections detect_all(const LoopsArgs& a, double& ms_per_frame) {
  std::string format = a.detector_format;
  if (format.empty()) {
    const std::string name = lower(std::filesystem::path(a.detector).filename().string());
    for (const char* f : {"yolox", "nanodet", "fastestdet"})
      if (name.find(f) != std::string::npos) format = f;
    vmap::detail::check(!format.empty(), "--detector: cannot tell the format of '" + a.detector +
                                             "' from its name; give --detector-format yolox|nanodet|fastestdet");
  }
  auto detector = vmap::make_dnn_detector(vmap::parse_detector_format(format),
                                          {.model = a.detector, .score_threshold = a.config.detector.labels.min_score});
  auto source = vmap::FrameSource::open(a.input);
  std::vector<std::vector<vmap::Detection>> per_frame;
  const auto t0 = std::chrono::steady_clock::now();
  while (auto f = source.next()) per_frame.push_back(detector.detect(f->image));
  const double s = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
  ms_per_frame = per_frame.empty() ? 0.0 : 1e3 * s / static_cast<double>(per_frame.size());
  return vmap::PrecomputedDetections(per_frame);
}

int run(LoopsArgs& a) {
  auto& c = a.config;
  c.input = a.input;
  c.label_order = a.label_order;
  if (a.index == "tree")
    c.detector.index = vmap::CandidateIndex::tree;
  else if (a.index == "all")
    c.detector.index = vmap::CandidateIndex::brute_force;
  else
    vmap::detail::fail("--index: unknown '" + a.index + "' (choose tree or all)");
  vmap::detail::check(a.gt.empty() != a.gt_poses.empty(), "give exactly one of --gt MATRIX and --gt-poses POSES");
  vmap::detail::check(a.labels.empty() || a.detector.empty(), "give --labels or --detector, not both");

  // The ground truth is checked against the sequence before any frame is processed.
  const auto sequence = vmap::FrameSource::open(a.input);
  const std::size_t total = sequence.total().value_or(0);
  vmap::LoopGroundTruth gt;
  if (a.gt.empty()) {
    // One pose per frame: by order when the counts agree, else the nearest in time
    // (TUM's 100 Hz groundtruth.txt against rgb.txt at 30 Hz). 50 ms rather than
    // associate.py's 20 ms: fr1's ground truth has gaps of up to 49 ms (tum_fr1_rpy).
    const auto poses = vmap::poses_for_frames(vmap::load_tum_poses(a.gt_poses), sequence.timestamps(), a.gt_poses, 0.05);
    gt = vmap::ground_truth_from_poses(
        poses, {.max_distance = a.gt_distance, .max_angle_deg = a.gt_angle, .window = c.detector.window});
  } else {
    gt = vmap::LoopGroundTruth::load(a.gt, total);
  }

  vmap::PrecomputedDetections labels;
  double detect_ms = 0.0;
  if (!a.labels.empty()) {
    labels = vmap::examples::load_labels({a.labels.begin(), a.labels.end()});
  } else if (!a.detector.empty()) {
    labels = detect_all(a, detect_ms);
  } else {
    vmap::detail::check(c.detector.index == vmap::CandidateIndex::brute_force,
                        "the tree needs labels: give --labels FILE or --detector MODEL (or --index all)");
  }

  vmap::examples::LoopRun result = vmap::examples::run_loops(c, labels, [&](const vmap::LoopResult& r) {
    if (!a.verbose) return;
    std::fprintf(stderr, "frame %3zu  candidates %3zu  best %4s  inliers %4d  %s\n", r.frame, r.candidates,
                 r.best ? std::to_string(*r.best).c_str() : "-", r.inliers, std::string(vmap::to_string(r.status)).c_str());
  });
  const std::size_t frames = result.results.size();
  const auto s = vmap::examples::summarize(result, gt, c.detector.min_inliers);
  const auto agree = result.agreement(gt, c.detector.window);

  if (!a.csv.empty()) {
    std::string csv = "threshold,true_positives,false_positives,precision,recall\n";
    char buf[160];
    for (const auto& p : s.curve) {
      std::snprintf(buf, sizeof buf, "%g,%zu,%zu,%.6f,%.6f\n", p.threshold, p.true_positives, p.false_positives,
                    p.precision, p.recall);
      csv += buf;
    }
    vmap::write_file_atomically(a.csv, csv);
  }
  if (!a.plot.empty()) {
    const std::filesystem::path p = std::filesystem::path(a.input).lexically_normal();
    char title[200];
    std::snprintf(title, sizeof title, "%s, %s index: recall@100%%P %.3f, %zu verifications",
                  (p.parent_path().filename() / p.filename()).string().c_str(), a.index.c_str(),
                  s.at_full_precision.recall, s.verifications);
    vmap::write_image_atomically(a.plot, vmap::examples::draw_pr_curves({{s.curve, "vmap " + a.index}}, title));
  }

  if (a.json) {
    nlohmann::json j = {{"frames", s.frames},
                        {"loops_gt", s.loops_gt},
                        {"true_positives", s.at_decision.true_positives},
                        {"false_positives", s.at_decision.false_positives},
                        {"precision", s.at_decision.precision},
                        {"recall", s.at_decision.recall},
                        {"recall_at_100_precision", s.at_full_precision.recall},
                        {"verifications", s.verifications},
                        {"ms_per_frame", s.ms_per_frame},
                        {"index", a.index},
                        {"min_inliers", c.detector.min_inliers},
                        {"threshold_at_100_precision", s.at_full_precision.true_positives > 0
                                                           ? nlohmann::json(s.at_full_precision.threshold)
                                                           : nlohmann::json(nullptr)},
                        {"labels_kept", result.schema.labels()},
                        {"detector_ms_per_frame", detect_ms},
                        {"distinct_label_vectors", agree.distinct_vectors},
                        {"equal_vector_pairs", agree.leaf_pairs},
                        {"loop_queries", agree.loop_queries},
                        {"loop_queries_with_equal_vector", agree.reachable_queries}};
    std::printf("%s\n", j.dump(2).c_str());
    return 0;
  }
  std::printf("frames %zu, query frames with a ground-truth loop %zu\n", s.frames, s.loops_gt);
  if (c.detector.index == vmap::CandidateIndex::tree) {
    std::printf("labels (score >= %.2f, eq. 5 influence in [%.2f, %.2f]), large to small:\n",
                static_cast<double>(c.detector.labels.min_score), c.influence.min_influence, c.influence.max_influence);
    for (const auto& l : result.influence)
      std::printf("  label %3d  E = %.3f  mean area %8.0f px^2  %s\n", l.label, l.influence, l.mean_area,
                  l.kept ? "kept" : "dropped");
    std::printf("tree depth %zu, window %zu, m = %zu\n", result.schema.size(), c.detector.window,
                c.detector.min_candidates);
    std::printf("label vectors: %zu distinct; %zu of %zu pairs have equal vectors (the tree verifies at least these, "
                "<= %.1fx fewer than brute force); %zu of %zu query frames with a loop have a true loop frame of "
                "their own vector\n",
                agree.distinct_vectors, agree.leaf_pairs, agree.pairs, agree.max_reduction(), agree.reachable_queries,
                agree.loop_queries);
  }
  std::printf("index %s: %zu verifications (%.1f per frame), %.1f ms per frame%s\n", a.index.c_str(), s.verifications,
              static_cast<double>(s.verifications) / static_cast<double>(std::max<std::size_t>(1, frames)),
              s.ms_per_frame, detect_ms > 0 ? "" : " (detections precomputed)");
  if (detect_ms > 0) std::printf("detector: %.1f ms per frame\n", detect_ms);
  std::printf("at inliers >= %d: TP %zu, FP %zu, precision %.3f, recall %.3f\n", c.detector.min_inliers,
              s.at_decision.true_positives, s.at_decision.false_positives, s.at_decision.precision,
              s.at_decision.recall);
  if (s.at_full_precision.true_positives > 0)
    std::printf("recall@100%%P %.3f (at inliers >= %g)\n", s.at_full_precision.recall, s.at_full_precision.threshold);
  else
    std::printf("recall@100%%P 0.000 (no threshold without a false positive)\n");
  return 0;
}

std::function<int()> setup(CLI::App& app) {
  auto a = std::make_shared<LoopsArgs>();
  auto& d = a->config.detector;
  app.add_option("INPUT", a->input, "Frames: image folder, list file, video or TUM rgb.txt")->required();
  app.add_option("--gt", a->gt, "Ground-truth loop matrix (rows of 0/1, row = query frame)");
  app.add_option("--gt-poses", a->gt_poses, "Derive the ground truth from TUM poses (timestamp tx ty tz qx qy qz qw; one a frame, or associated to rgb.txt times within 50 ms)");
  app.add_option("--gt-distance", a->gt_distance, "With --gt-poses: max. camera-centre distance, metres")
      ->capture_default_str();
  app.add_option("--gt-angle", a->gt_angle, "With --gt-poses: max. angle between viewing directions, degrees")
      ->capture_default_str();
  app.add_option("--labels", a->labels,
                 "Precomputed detections (frame label score x y w h), e.g. from vmap detect; several files "
                 "(comma-separated) are pooled, a label being present when any file has it")
      ->delimiter(',');
  app.add_option("--detector", a->detector, "Run this ONNX detector (cv::dnn) over the frames instead of --labels");
  app.add_option("--detector-format", a->detector_format,
                 "yolox, nanodet or fastestdet (default: guessed from the model's file name)");
  app.add_option("--index", a->index, "Candidates: tree (LFM-LCD) or all (every frame older than the window)")
      ->capture_default_str();
  app.add_option("--window", d.window, "Frames this recent are never candidates")->capture_default_str();
  app.add_option("--min-candidates", d.min_candidates, "m: backtrack up the tree until this many candidates")
      ->capture_default_str();
  app.add_option("--min-inliers", d.min_inliers, "Decision threshold: F-matrix inliers of a loop")->capture_default_str();
  app.add_option("--min-score", d.labels.min_score, "Detections below this score are ignored")->capture_default_str();
  app.add_option("--min-influence", a->config.influence.min_influence, "Drop labels present in fewer frames (eq. 5)")
      ->capture_default_str();
  app.add_option("--max-influence", a->config.influence.max_influence, "Drop labels present in more frames (eq. 5)")
      ->capture_default_str();
  app.add_option("--label-order", a->label_order, "Label ids from large to small objects (default: by mean box area)")
      ->delimiter(',');
  app.add_option("--sample", a->config.sample, "Frames whose labels form the eq. 5 sample (0: all)")
      ->capture_default_str();
  app.add_option("--features", a->config.descriptor.name, "orb, akaze or sift")->capture_default_str();
  app.add_option("--nfeatures", a->config.descriptor.features, "Keypoint budget per image (ORB, SIFT; top-k for XFeat)")->capture_default_str();
  app.add_option("--csv", a->csv, "Write the PR curve (threshold, TP, FP, precision, recall) as CSV");
  app.add_option("--plot", a->plot, "Write the PR curve as a PNG plot");
  app.add_flag("--json", a->json, "Print the figures as JSON");
  app.add_flag("--verbose", a->verbose, "Print one line per frame to stderr (candidates, best, inliers, status)");
  return [a] {
    a->config.colour = !a->detector.empty();
    return run(*a);
  };
}

const bool registered = vmap::cli::add_command({"loops", "Loop closure (LFM-LCD) evaluated against ground truth", setup});

}  // namespace
