// Benchmark of loop closure against ../shared/baselines/lcd_bruteforce.cpp (ORB 1000,
// cross-checked brute-force Hamming, USAC_MAGSAC F-matrix, every frame older than the
// window verified), all in one run:
//   - rtabmap_loop (84 frames, the ground-truth matrix, window 10);
//   - tum_fr3_cabinet_kf (58 key frames, ground truth from the poses: camera centres
//     within --gt-distance metres and optical axes within --gt-angle degrees), with ORB
//     and with SIFT (float descriptors, float vocabulary);
//   - scale: --distractors key frames (seeded crops, rotations and brightness changes of
//     the frames of tum_fr1_rpy, kitti07_160 and tum_fr3_cabinet_kf, 256x192) placed
//     before rtabmap_loop, ranked with a larger vocabulary learned on other data.
// Candidate sources: brute force through the library (`all`), the binary classified
// tree over precomputed labels (examples/data/*_yolox.txt at each --min-score; on
// rtabmap_loop also NanoDet-m, FastestDet and their unions with YOLOX-nano), and the
// ranked sources tree_ranked and bow at each --top-k, with a vocabulary learned on the
// sequence itself ("self") and one learned on other data ("other": tum_fr1_rpy +
// kitti07_160). Features are extracted once per sequence and descriptor; every row
// reuses them (ms per frame = that extraction + the row's detector time).
//
//   bench_loops [--shared DIR] [--window 10] [--min-score 0.5,0.3,0.2] [--min-candidates 5]
//               [--top-k 1,2,3,5] [--distractors 10000] [--label-sources]
//               [--datasets rtabmap_loop,tum_fr3_cabinet_kf] [--scale-words 10000 --scale-depth 4]
#include <vmap/core/names.hpp>
#include <vmap/io/atomic_file.hpp>
#include <vmap/runtime/distractors.hpp>
#include <vmap/runtime/loops.hpp>
#include <vmap/runtime/vocabulary.hpp>

#include <CLI/CLI.hpp>

#include <algorithm>
#include <array>
#include <chrono>
#include <ctime>
#include <cstdio>
#include <filesystem>
#include <map>
#include <memory>
#include <regex>
#include <string>
#include <vector>

namespace {

double seconds_since(std::chrono::steady_clock::time_point t0) {
  return std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
}

/// The default stack (ORB 1000, MAGSAC++) with another descriptor.
vmap::PolicyStack stack_with(const std::string& descriptor) {
  vmap::PolicyStack s;
  s.descriptor = vmap::parse<vmap::DescriptorKind>(descriptor, "descriptor");
  return s;
}

struct BaselineFigures {
  double recall = 0.0;
  std::size_t pairs = 0;
  double seconds = 0.0;
  std::string line;
};

BaselineFigures run_baseline(const std::filesystem::path& list, const std::filesystem::path& gt, std::size_t window) {
  const std::string cmd = std::string("'") + VMAP_BASELINE_LCD_BRUTEFORCE + "' '" + list.string() + "' '" +
                          gt.string() + "' " + std::to_string(window);
  std::unique_ptr<FILE, int (*)(FILE*)> pipe(popen(cmd.c_str(), "r"), pclose);
  vmap::detail::check(pipe != nullptr, "cannot run the baseline " + cmd);
  BaselineFigures b;
  std::array<char, 512> buf{};
  while (std::fgets(buf.data(), static_cast<int>(buf.size()), pipe.get())) b.line += buf.data();
  std::smatch m;
  const std::regex re(R"(pairs (\d+) time ([0-9.]+)s .*recall@100%P ([0-9.]+))");
  vmap::detail::check(std::regex_search(b.line, m, re), "unexpected baseline output: " + b.line);
  b.pairs = std::stoul(m[1].str());
  b.seconds = std::stod(m[2].str());
  b.recall = std::stod(m[3].str());
  return b;
}

// One tree run: a label source (one labels file or the union of several) and the
// parameters that differ from the defaults.
struct TreeRow {
  std::string source;                         // its name in the table
  std::vector<std::filesystem::path> labels;  // files pooled into one label source
  float min_score = 0.5f;
  double min_influence = vmap::InfluenceOptions{}.min_influence;
};

struct Dataset {
  std::string name;
  std::filesystem::path input;               // FrameSource input for vmap
  std::vector<std::filesystem::path> files;  // the same frames, for the baseline's list
  vmap::LoopGroundTruth gt;
  std::filesystem::path labels;              // YOLOX-nano: the --min-score rows
  std::vector<TreeRow> extra;                // other label sources and parameters
  std::vector<std::string> descriptors;      // orb first; the others get their own brute force
};

// What a row is compared with: the baseline program, or (other descriptors) vmap's
// brute force with the same descriptor.
struct Reference {
  std::string name;
  double recall = 0.0;
  std::size_t verifications = 0;
  double ms = 0.0;
};

void print_row(const std::string& method, const vmap::LoopEvaluation& s, const Reference& ref) {
  std::printf("  %-44s recall@100%%P %.3f (%+.3f)  verifications %5zu (%6.1fx fewer)  %7.1f ms/frame (%5.2fx faster)\n",
              method.c_str(), s.at_full_precision.recall, s.at_full_precision.recall - ref.recall, s.verifications,
              static_cast<double>(ref.verifications) / static_cast<double>(std::max<std::size_t>(1, s.verifications)),
              s.ms_per_frame, ref.ms / std::max(1e-9, s.ms_per_frame));
}

std::vector<vmap::Features> features_of(const std::vector<std::filesystem::path>& inputs, const vmap::PolicyStack& stack,
                                        double& seconds) {
  std::vector<vmap::Features> all;
  seconds = 0.0;
  for (const auto& in : inputs) {
    auto f = vmap::extract_features(in, stack);
    seconds += f.seconds;
    for (auto& x : f.frames) all.push_back(std::move(x));
  }
  return all;
}

}  // namespace

int main(int argc, char** argv) {
  CLI::App app{"Loop closure (tree, ranked, bag of words) vs. the brute-force OpenCV baseline"};
  std::string shared = VMAP_SHARED_DIR;
  std::size_t window = 10;
  std::vector<float> min_scores = {0.5f, 0.3f, 0.2f};
  std::size_t min_candidates = 5;
  std::vector<std::size_t> top_ks = {1, 2, 3, 5};
  std::vector<std::size_t> distractor_counts = {10000};
  bool label_sources = false;
  std::vector<std::string> datasets = {"rtabmap_loop", "tum_fr3_cabinet_kf"};
  // The scale runs' vocabulary: posting lists shrink with more words, and a query's cost
  // is the sum of its words' lists (10^4 words: 10x shorter lists than 10^3).
  vmap::VocabularyLearning scale_vocabulary{.words = 10000, .depth = 4, .seed = 1};
  double gt_distance = 0.5, gt_angle = 30.0;
  vmap::VocabularyLearning vocabulary;
  app.add_option("--shared", shared, "The shared data folder")->capture_default_str();
  app.add_option("--window", window, "Frames this recent are never candidates")->capture_default_str();
  app.add_option("--min-score", min_scores, "Label score thresholds (eq. 3), one tree run each; the first is LFM-LCD's")
      ->delimiter(',')
      ->capture_default_str();
  app.add_option("--min-candidates", min_candidates, "m of the tree's backtracking")->capture_default_str();
  app.add_option("--top-k", top_ks, "Ranked sources: one run per top k")->delimiter(',')->capture_default_str();
  app.add_option("--distractors", distractor_counts,
                 "Scale runs: distractor key frames before rtabmap_loop, one run per count (0: none)")
      ->delimiter(',')
      ->capture_default_str();
  app.add_option("--datasets", datasets, "Sequences to evaluate (rtabmap_loop, tum_fr3_cabinet_kf; none: only scale)")
      ->delimiter(',')
      ->capture_default_str();
  app.add_option("--scale-words", scale_vocabulary.words, "Scale runs: words of the vocabulary learned on other data")
      ->capture_default_str();
  app.add_option("--scale-depth", scale_vocabulary.depth, "Scale runs: its depth")->capture_default_str();
  app.add_flag("--label-sources", label_sources,
               "Also the tree rows of the other detectors (NanoDet-m, FastestDet, unions) on rtabmap_loop");
  app.add_option("--words", vocabulary.words, "Vocabularies: at most this many words")->capture_default_str();
  app.add_option("--depth", vocabulary.depth, "Vocabularies: depth of the tree")->capture_default_str();
  app.add_option("--gt-distance", gt_distance, "tum_fr3_cabinet_kf: max. camera distance, m")->capture_default_str();
  app.add_option("--gt-angle", gt_angle, "tum_fr3_cabinet_kf: max. viewing angle, degrees")->capture_default_str();
  CLI11_PARSE(app, argc, argv);
  try {
    const std::filesystem::path data = std::filesystem::path(shared) / "data";
    const std::filesystem::path src = VMAP_SOURCE_DIR;
    const auto tmp = std::filesystem::temp_directory_path() / "vmap_bench_loops";
    std::filesystem::create_directories(tmp);
    const std::vector<std::filesystem::path> other_inputs = {data / "tum_fr1_rpy/rgb.txt", data / "kitti07_160/image_0"};

    std::vector<Dataset> sets;
    {
      Dataset d{"rtabmap_loop", data / "rtabmap_loop/images", {}, {}, src / "examples/data/rtabmap_loop_yolox.txt",
                {}, {"orb"}};
      for (int k = 1; k <= 84; ++k) d.files.push_back(d.input / (std::to_string(k) + ".jpg"));
      d.gt = vmap::LoopGroundTruth::load(data / "rtabmap_loop/gt_loop_matrix_84x84.txt", 84);
      const auto yolox = src / "examples/data/rtabmap_loop_yolox.txt";
      const auto nanodet = src / "examples/data/rtabmap_loop_nanodet.txt";
      const auto fastestdet = src / "examples/data/rtabmap_loop_fastestdet.txt";
      if (label_sources)
        d.extra = {{"NanoDet-m", {nanodet}},
                   {"FastestDet", {fastestdet}},
                   {"YOLOX+NanoDet", {yolox, nanodet}},
                   {"YOLOX+FastestDet", {yolox, fastestdet}},
                   {"YOLOX+NanoDet+FastestDet", {yolox, nanodet, fastestdet}},
                   // The best setting within 0.02 of brute force's recall found by a sweep
                   // over detectors, scores, band and m (examples/results/loops.md): tuned on this
                   // very sequence, so an optimistic figure.
                   {"FastestDet (tuned band)", {fastestdet}, 0.5f, 0.10}};
      sets.push_back(std::move(d));
    }
    {
      Dataset d{"tum_fr3_cabinet_kf", data / "tum_fr3_cabinet_kf/rgb", {}, {},
                src / "examples/data/tum_fr3_cabinet_kf_yolox.txt", {}, {"orb", "sift"}};
      for (const auto& p : vmap::FrameSource::open(d.input).paths()) d.files.push_back(p);
      d.gt = vmap::ground_truth_from_poses(vmap::load_tum_poses(data / "tum_fr3_cabinet_kf/truth_cam_poses.txt"),
                                           {.max_distance = gt_distance, .max_angle_deg = gt_angle, .window = window});
      sets.push_back(std::move(d));
    }

    // The "other" vocabularies, one per descriptor, learned on frames of other sequences;
    // saved and loaded again to time the load.
    std::map<std::string, std::shared_ptr<const vmap::AnyVocabulary>> other;
    std::vector<std::string> other_names = {"orb"};
    if (std::find(datasets.begin(), datasets.end(), "tum_fr3_cabinet_kf") != datasets.end()) other_names.push_back("sift");
    std::vector<vmap::Features> other_orb;  // kept for the scale runs' vocabulary
    for (const std::string& name : other_names) {
      double extract_s = 0.0;
      const auto frames = features_of(other_inputs, stack_with(name), extract_s);
      if (name == "orb") other_orb = frames;
      const auto t0 = std::chrono::steady_clock::now();
      const vmap::AnyVocabulary v = vmap::learn_vocabulary(frames, vocabulary);
      const double learn_s = seconds_since(t0);
      const auto path = tmp / ("other_" + name + ".voc");
      v.save(path);
      const auto t1 = std::chrono::steady_clock::now();
      other[name] = std::make_shared<const vmap::AnyVocabulary>(vmap::AnyVocabulary::load(path));
      const double load_ms = 1e3 * seconds_since(t1);
      std::printf("vocabulary 'other' (%s): tum_fr1_rpy + kitti07_160, %zu frames (features %.1f s): %zu words "
                  "(branching %d, depth %d), learned in %.1f s, %zu bytes on disk, loaded in %.1f ms\n",
                  name.c_str(), frames.size(), extract_s, other[name]->size(), other[name]->branching(),
                  other[name]->depth(), learn_s, static_cast<std::size_t>(std::filesystem::file_size(path)), load_ms);
    }
    std::printf("\n");

    vmap::SequenceFeatures rtabmap_orb;
    for (const Dataset& d : sets) {
      if (std::find(datasets.begin(), datasets.end(), d.name) == datasets.end()) continue;
      std::string list;
      for (const auto& f : d.files) list += f.string() + "\n";
      const auto list_path = tmp / (d.name + "_list.txt");
      const auto gt_path = tmp / (d.name + "_gt.txt");
      vmap::write_file_atomically(list_path, list);
      d.gt.save(gt_path);
      const std::size_t frames = d.files.size();
      std::printf("%s: %zu frames, %zu query frames with a ground-truth loop, window %zu\n", d.name.c_str(), frames,
                  d.gt.loop_frames(), window);

      const BaselineFigures b = run_baseline(list_path, gt_path, window);
      std::printf("  baseline lcd_bruteforce: %s", b.line.c_str());
      const Reference baseline{"baseline", b.recall, b.pairs, 1e3 * b.seconds / static_cast<double>(frames)};
      std::printf("  %-44s recall@100%%P %.3f          verifications %5zu                 %7.1f ms/frame\n",
                  "baseline (brute force, ORB)", b.recall, b.pairs, baseline.ms);
      const auto labels = vmap::PrecomputedDetections::load(d.labels);

      for (const std::string& desc : d.descriptors) {
        vmap::LoopRunOptions config;
        config.stack = stack_with(desc);
        config.detector.window = window;
        config.detector.min_candidates = min_candidates;
        const auto features = vmap::extract_features(d.input, config.stack);
        if (d.name == "rtabmap_loop" && desc == "orb") rtabmap_orb = features;
        const auto run = [&](vmap::CandidateIndex index, const vmap::PrecomputedDetections& l,
                             std::shared_ptr<const vmap::AnyVocabulary> v) {
          config.detector.index = index;
          const auto r = vmap::run_loops(config, features, l, std::move(v));
          return std::make_pair(r, vmap::evaluate_loop_run(r, d.gt, config.detector.decision.min_confidence));
        };

        const auto all = run(vmap::CandidateIndex::brute_force, labels, nullptr).second;
        print_row(desc + ": all (brute force)", all, baseline);
        // Non-ORB rows compare with the library's brute force of the same descriptor.
        const Reference ref = desc == "orb" ? baseline : Reference{desc + " all", all.at_full_precision.recall,
                                                                   all.verifications, all.ms_per_frame};
        if (desc != "orb") std::printf("  (%s rows below: ratios against %s: all)\n", desc.c_str(), desc.c_str());

        std::vector<TreeRow> rows;
        for (float min_score : min_scores) rows.push_back({"YOLOX-nano", {d.labels}, min_score});
        if (desc == "orb") rows.insert(rows.end(), d.extra.begin(), d.extra.end());
        for (const TreeRow& row : rows) {
          config.detector.labels.min_score = row.min_score;
          config.influence.min_influence = row.min_influence;
          const auto [tree_run, st] = run(vmap::CandidateIndex::tree, vmap::load_labels(row.labels), nullptr);
          std::string kept;
          for (int l : tree_run.schema.labels()) {  // piecewise: GCC 12 -O3 warns falsely on "," + to_string
            if (!kept.empty()) kept += ',';
            kept += std::to_string(l);
          }
          char name[160];
          std::snprintf(name, sizeof name, "%s: tree, %s >= %.2f", desc.c_str(), row.source.c_str(),
                        static_cast<double>(row.min_score));
          print_row(name, st, ref);
          const auto agree = tree_run.agreement(d.gt, window);
          std::printf("  %-44s labels %s, influence [%.2f, %.2f]; %zu distinct label vectors; pairs with equal "
                      "vectors %zu of %zu (bound: <= %.1fx fewer)\n",
                      "", kept.empty() ? "none" : kept.c_str(), config.influence.min_influence,
                      config.influence.max_influence, agree.distinct_vectors, agree.leaf_pairs, agree.pairs,
                      agree.max_reduction());
        }
        config.influence = {};
        config.detector.labels = {};

        // The vocabulary learned on this sequence's own frames, with this descriptor.
        const auto t0 = std::chrono::steady_clock::now();
        const auto self =
            std::make_shared<const vmap::AnyVocabulary>(vmap::learn_vocabulary(features.frames, vocabulary));
        std::printf("  vocabulary 'self' (%s): %zu words learned on the sequence in %.2f s\n", desc.c_str(),
                    self->size(), seconds_since(t0));
        for (const auto& [vname, voc] : {std::pair{std::string("self"), self}, std::pair{std::string("other"), other.at(desc)}}) {
          for (std::size_t k : top_ks) {
            config.detector.top_k = k;
            for (vmap::CandidateIndex index : {vmap::CandidateIndex::tree_ranked, vmap::CandidateIndex::bow}) {
              const auto sr = run(index, labels, voc).second;
              char name[160];
              std::snprintf(name, sizeof name, "%s: %s, top %zu, voc %s", desc.c_str(),
                            std::string(vmap::to_string(index)).c_str(), k, vname.c_str());
              print_row(name, sr, ref);
            }
          }
        }
        config.detector.top_k = vmap::LoopDetectorOptions{}.top_k;
      }
      std::printf("\n");
    }

    // Scale: distractor key frames before rtabmap_loop, ORB, a vocabulary learned on the
    // other sequences' frames.
    const Dataset& rt = sets.front();
    std::vector<cv::Mat> sources;
    std::shared_ptr<const vmap::AnyVocabulary> scale_voc;
    for (std::size_t n : distractor_counts) {
      if (n == 0) continue;
      if (!scale_voc) {
        if (rtabmap_orb.frames.empty()) rtabmap_orb = vmap::extract_features(rt.input, vmap::PolicyStack{});
        const auto t0 = std::chrono::steady_clock::now();
        const vmap::AnyVocabulary v = vmap::learn_vocabulary(other_orb, scale_vocabulary);
        const double learn_s = seconds_since(t0);
        const auto path = tmp / "scale_orb.voc";
        v.save(path);
        const auto t1 = std::chrono::steady_clock::now();
        scale_voc = std::make_shared<const vmap::AnyVocabulary>(vmap::AnyVocabulary::load(path));
        std::printf("scale vocabulary (orb): tum_fr1_rpy + kitti07_160, %zu words (branching %d, depth %d), learned in "
                    "%.1f s, %zu bytes on disk, loaded in %.1f ms\n",
                    scale_voc->size(), scale_voc->branching(), scale_voc->depth(), learn_s,
                    static_cast<std::size_t>(std::filesystem::file_size(path)), 1e3 * seconds_since(t1));
      }
      if (sources.empty())
        sources = vmap::load_distractor_sources(
            {data / "tum_fr1_rpy/rgb.txt", data / "kitti07_160/image_0", data / "tum_fr3_cabinet_kf/rgb"});
      std::printf("scale: %zu distractor key frames (256x192 seeded crops/rotations/brightness of %zu frames of "
                  "tum_fr1_rpy, kitti07_160, tum_fr3_cabinet_kf) before rtabmap_loop, ORB 1000, the scale vocabulary\n",
                  n, sources.size());
      std::vector<vmap::Features> distractors;
      distractors.reserve(n);
      std::size_t keypoints = 0;
      const auto t0 = std::chrono::steady_clock::now();
      {
        vmap::OrbDescriptor orb({.features = 1000});
        for (std::size_t i = 0; i < n; ++i) {
          distractors.push_back(orb.extract(vmap::make_distractor(sources, i)));
          keypoints += distractors.back().size();
          if ((i + 1) % 1000 == 0) std::fprintf(stderr, "\rdistractors %zu/%zu", i + 1, n);
        }
        std::fprintf(stderr, "\n");
      }
      std::printf("  distractors made and extracted in %.1f s (%.1f keypoints each)\n", seconds_since(t0),
                  static_cast<double>(keypoints) / static_cast<double>(n));

      // The bare database: transform, add, save, load, query.
      {
        const auto& voc = *scale_voc;
        vmap::PlaceDatabase<std::size_t> db(voc.size());
        std::vector<vmap::BowVector> queries;
        const auto t1 = std::chrono::steady_clock::now();
        for (std::size_t i = 0; i < n; ++i) db.add(i, voc.transform(distractors[i].descriptors));
        const double add_s = seconds_since(t1);
        for (const auto& f : rtabmap_orb.frames) queries.push_back(voc.transform(f.descriptors));
        const auto path = tmp / "distractors.db";
        db.save(path);
        const auto t2 = std::chrono::steady_clock::now();
        const auto loaded = vmap::PlaceDatabase<std::size_t>::load(path);
        const double load_ms = 1e3 * seconds_since(t2);
        // Wall time and this process's CPU time (one thread): the machine is shared, so
        // the CPU time is the one-core cost.
        const auto t3 = std::chrono::steady_clock::now();
        const std::clock_t c3 = std::clock();
        std::size_t hits = 0;
        for (const auto& q : queries) hits += loaded.query(q, 3).size();
        const double nq = static_cast<double>(queries.size());
        const double query_cpu_ms = 1e3 * static_cast<double>(std::clock() - c3) / CLOCKS_PER_SEC / nq;
        const double query_ms = 1e3 * seconds_since(t3) / nq;
        std::printf("  database of %zu: transform + add %.2f ms per key frame, %.0f bytes per key frame, file %zu "
                    "bytes loaded in %.1f ms; query (top 3) %.2f ms wall, %.2f ms CPU (%zu hits)\n",
                    n, 1e3 * add_s / static_cast<double>(n), static_cast<double>(db.memory_bytes()) / static_cast<double>(n),
                    static_cast<std::size_t>(std::filesystem::file_size(path)), load_ms, query_ms, query_cpu_ms, hits);
      }

      vmap::LoopRunOptions config;
      config.detector.window = window;
      config.detector.min_candidates = min_candidates;
      const auto labels = vmap::PrecomputedDetections::load(rt.labels);
      for (vmap::CandidateIndex index : {vmap::CandidateIndex::bow, vmap::CandidateIndex::tree_ranked}) {
        config.detector.index = index;
        const std::clock_t c0 = std::clock();
        const auto r = vmap::run_loops(config, rtabmap_orb, labels, scale_voc, {}, &distractors);
        const double run_cpu_s = static_cast<double>(std::clock() - c0) / CLOCKS_PER_SEC;
        const auto s = vmap::evaluate_loop_run(r, rt.gt, config.detector.decision.min_confidence);
        const double frames = static_cast<double>(r.results.size());
        std::printf("  %-44s recall@100%%P %.3f  verifications %4zu  ranking %.2f ms per query (wall), whole key frame "
                    "%.1f ms wall (detector %.1f + features %.1f); the run (%zu distractors + %zu frames) %.1f s CPU; "
                    "%.0f bytes per key frame in memory\n",
                    (std::string(vmap::to_string(index)) + ", top " + std::to_string(config.detector.top_k)).c_str(),
                    s.at_full_precision.recall, s.verifications, 1e3 * r.rank_seconds / frames, s.ms_per_frame,
                    1e3 * r.detector_seconds / frames, 1e3 * rtabmap_orb.seconds / frames, n, r.results.size(),
                    run_cpu_s, static_cast<double>(r.memory_bytes) / static_cast<double>(n + r.results.size()));
      }
      std::printf("\n");
    }
  } catch (const vmap::Error& e) {
    std::fprintf(stderr, "bench_loops: %s\n", e.what());
    return 1;
  }
  return 0;
}
