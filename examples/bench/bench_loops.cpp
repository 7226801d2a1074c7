// Benchmark of LFM-LCD loop closure against ../shared/baselines/lcd_bruteforce.cpp (ORB
// 1000, cross-checked brute-force Hamming, USAC_MAGSAC F-matrix, every frame older than
// the window verified), all in one run:
//   - rtabmap_loop (84 frames, the ground-truth matrix, window 10);
//   - tum_fr3_cabinet_kf (58 key frames, ground truth from the poses: camera centres
//     within --gt-distance metres and optical axes within --gt-angle degrees).
// For each: the baseline program, vmap with `--index all` (brute force through the
// library) and vmap with the binary classified tree over precomputed labels
// (examples/data/*_yolox.txt at each --min-score; on rtabmap_loop also NanoDet-m,
// FastestDet and their unions with YOLOX-nano; all made by `vmap detect`). Prints
// recall@100%P, verifications, ms per frame and the ratios against the baseline, and
// per tree row what its label vectors allow (lcd/label_sources.hpp).
//
//   bench_loops [--shared DIR] [--window 10] [--min-score 0.5,0.3,0.2] [--min-candidates 5]
#include "common/lcd_run.hpp"

#include <vmap/io/atomic_file.hpp>

#include <CLI/CLI.hpp>

#include <array>
#include <cstdio>
#include <filesystem>
#include <memory>
#include <regex>
#include <string>
#include <vector>

namespace {

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
  std::filesystem::path input;             // FrameSource input for vmap
  std::vector<std::filesystem::path> files;  // the same frames, for the baseline's list
  vmap::LoopGroundTruth gt;
  std::filesystem::path labels;            // YOLOX-nano: the --min-score rows
  std::vector<TreeRow> extra;              // other label sources and parameters
};

void print_row(const char* method, double recall, std::size_t verifications, double ms, const BaselineFigures& b,
               std::size_t frames) {
  const double base_ms = 1e3 * b.seconds / static_cast<double>(frames);
  std::printf("  %-34s recall@100%%P %.3f (%+.3f)  verifications %5zu (%5.1fx fewer)  %7.1f ms/frame (%.2fx faster)\n",
              method, recall, recall - b.recall, verifications,
              static_cast<double>(b.pairs) / static_cast<double>(std::max<std::size_t>(1, verifications)), ms,
              base_ms / ms);
}

}  // namespace

int main(int argc, char** argv) {
  CLI::App app{"LFM-LCD loop closure vs. the brute-force OpenCV baseline"};
  std::string shared = VMAP_SHARED_DIR;
  std::size_t window = 10;
  std::vector<float> min_scores = {0.5f, 0.3f, 0.2f};
  std::size_t min_candidates = 5;
  double gt_distance = 0.5, gt_angle = 30.0;
  app.add_option("--shared", shared, "The shared data folder")->capture_default_str();
  app.add_option("--window", window, "Frames this recent are never candidates")->capture_default_str();
  app.add_option("--min-score", min_scores, "Label score thresholds (eq. 3), one tree run each; the first is LFM-LCD's")
      ->delimiter(',')
      ->capture_default_str();
  app.add_option("--min-candidates", min_candidates, "m of the tree's backtracking")->capture_default_str();
  app.add_option("--gt-distance", gt_distance, "tum_fr3_cabinet_kf: max. camera distance, m")->capture_default_str();
  app.add_option("--gt-angle", gt_angle, "tum_fr3_cabinet_kf: max. viewing angle, degrees")->capture_default_str();
  CLI11_PARSE(app, argc, argv);
  try {
    const std::filesystem::path data = std::filesystem::path(shared) / "data";
    const std::filesystem::path src = VMAP_SOURCE_DIR;
    const auto tmp = std::filesystem::temp_directory_path() / "vmap_bench_loops";
    std::filesystem::create_directories(tmp);

    std::vector<Dataset> sets;
    {
      Dataset d{"rtabmap_loop", data / "rtabmap_loop/images", {}, {}, src / "examples/data/rtabmap_loop_yolox.txt", {}};
      for (int k = 1; k <= 84; ++k) d.files.push_back(d.input / (std::to_string(k) + ".jpg"));
      d.gt = vmap::LoopGroundTruth::load(data / "rtabmap_loop/gt_loop_matrix_84x84.txt", 84);
      const auto yolox = src / "examples/data/rtabmap_loop_yolox.txt";
      const auto nanodet = src / "examples/data/rtabmap_loop_nanodet.txt";
      const auto fastestdet = src / "examples/data/rtabmap_loop_fastestdet.txt";
      d.extra = {{"NanoDet-m", {nanodet}},
                 {"FastestDet", {fastestdet}},
                 {"YOLOX+NanoDet", {yolox, nanodet}},
                 {"YOLOX+FastestDet", {yolox, fastestdet}},
                 {"YOLOX+NanoDet+FastestDet", {yolox, nanodet, fastestdet}},
                 // The best setting within 0.02 of brute force's recall found by a sweep
                 // over detectors, scores, band and m (examples/loops.md): tuned on this
                 // very sequence, so an optimistic figure.
                 {"FastestDet (tuned band)", {fastestdet}, 0.5f, 0.10}};
      sets.push_back(std::move(d));
    }
    {
      Dataset d{"tum_fr3_cabinet_kf", data / "tum_fr3_cabinet_kf/rgb", {}, {},
                src / "examples/data/tum_fr3_cabinet_kf_yolox.txt", {}};
      for (const auto& p : vmap::FrameSource::open(d.input).paths()) d.files.push_back(p);
      d.gt = vmap::ground_truth_from_poses(vmap::load_tum_poses(data / "tum_fr3_cabinet_kf/truth_cam_poses.txt"),
                                           {.max_distance = gt_distance, .max_angle_deg = gt_angle, .window = window});
      sets.push_back(std::move(d));
    }

    for (const Dataset& d : sets) {
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

      vmap::examples::LoopRunConfig config;
      config.input = d.input;
      config.detector.window = window;
      config.detector.min_candidates = min_candidates;
      config.detector.index = vmap::CandidateIndex::brute_force;
      const auto all = vmap::examples::run_loops(config, vmap::PrecomputedDetections::load(d.labels));
      const auto sa = vmap::examples::summarize(all, d.gt, config.detector.min_inliers);
      std::printf("  %-34s recall@100%%P %.3f          verifications %5zu                %7.1f ms/frame\n",
                  "baseline (brute force)", b.recall, b.pairs, 1e3 * b.seconds / static_cast<double>(frames));
      print_row("vmap --index all", sa.at_full_precision.recall, sa.verifications, sa.ms_per_frame, b, frames);

      std::vector<TreeRow> rows;
      for (float min_score : min_scores) rows.push_back({"YOLOX-nano", {d.labels}, min_score});
      rows.insert(rows.end(), d.extra.begin(), d.extra.end());
      for (const TreeRow& row : rows) {
        config.detector.index = vmap::CandidateIndex::tree;
        config.detector.labels.min_score = row.min_score;
        config.influence.min_influence = row.min_influence;
        const auto tree = vmap::examples::run_loops(config, vmap::examples::load_labels(row.labels));
        const auto st = vmap::examples::summarize(tree, d.gt, config.detector.min_inliers);
        const auto agree = tree.agreement(d.gt, window);
        std::string kept;
        for (int l : tree.schema.labels()) kept += (kept.empty() ? "" : ",") + std::to_string(l);
        std::printf("  tree: %s, score>=%.2f, influence [%.2f, %.2f], m %zu: labels %s\n", row.source.c_str(),
                    static_cast<double>(row.min_score), config.influence.min_influence, config.influence.max_influence,
                    min_candidates, kept.empty() ? "none" : kept.c_str());
        print_row("vmap tree", st.at_full_precision.recall, st.verifications, st.ms_per_frame, b, frames);
        std::printf("  %-34s recall %+.3f, %.1fx fewer verifications than vmap --index all (target: within 0.02, >= 10x)\n",
                    "", st.at_full_precision.recall - sa.at_full_precision.recall,
                    static_cast<double>(sa.verifications) / static_cast<double>(std::max<std::size_t>(1, st.verifications)));
        std::printf("  %-34s %zu distinct label vectors; pairs with equal vectors %zu of %zu (bound: <= %.1fx fewer); "
                    "loop queries with a true loop frame of their own vector %zu of %zu\n",
                    "", agree.distinct_vectors, agree.leaf_pairs, agree.pairs, agree.max_reduction(),
                    agree.reachable_queries, agree.loop_queries);
      }
      config.influence = {};
      std::printf("\n");
    }
  } catch (const vmap::Error& e) {
    std::fprintf(stderr, "bench_loops: %s\n", e.what());
    return 1;
  }
  return 0;
}
