// Benchmark of the GCS map and localization (Trujillo-Romero 2024;
// examples/methods.md, sec. 3):
//  1. training time of 100, 200, 300-neuron maps on the 164 images of the virtual room,
//     against the paper's reported 4,063 s, 14,287 s and 33,347 s (its figures: the
//     paper's code is not available, so they are the baseline);
//  2. localization error in the room (one and two images per test position), and the
//     same for a brute-force baseline run in the same process: the pose of the nearest
//     training image by histogram distance;
//  3. the same on ../shared/data/tum_fr3_cabinet_kf (train on even frames, localize the
//     odd ones against their ground-truth poses projected to the floor (x, y)).
//
//   bench_localize [--shared DIR] [--posters DIR] [--repeat N]
#include "common/error_stats.hpp"
#include <vmap/features/akaze.hpp>
#include <vmap/io/frame_source.hpp>
#include <vmap/som/gcs.hpp>
#include <vmap/som/histogram.hpp>
#include <vmap/som/pose_io.hpp>
#include <vmap/som/pose_map.hpp>
#include <vmap/som/virtual_room.hpp>

#include <CLI/CLI.hpp>

#include <algorithm>
#include <chrono>
#include <cstdio>
#include <filesystem>
#include <numbers>
#include <numeric>
#include <optional>
#include <limits>
#include <string>
#include <vector>

namespace {

using vmap::Pose2;
using clock_type = std::chrono::steady_clock;

double seconds_since(clock_type::time_point t0) {
  return std::chrono::duration<double>(clock_type::now() - t0).count();
}


// A query group (one or two images) and its true position.
struct Group {
  std::vector<Eigen::VectorXf> vectors;
  Pose2 truth;
};

struct Errors {
  std::vector<double> gcs, nearest;
};

// GCS estimate (Algorithm 5) and the brute-force nearest-training-image estimate
// (mean of the nearest training pose of each query vector).
Errors evaluate(const vmap::PoseMap<vmap::GcsXf>& map, const std::vector<Eigen::VectorXf>& train,
                const std::vector<Pose2>& train_poses, const std::vector<Group>& groups) {
  Errors e;
  for (const auto& g : groups) {
    e.gcs.push_back(map.localize(g.vectors).pose.distance(g.truth));
    std::vector<Pose2> nn;
    for (const auto& q : g.vectors) {
      std::size_t best = 0;
      float bd = std::numeric_limits<float>::infinity();
      for (std::size_t i = 0; i < train.size(); ++i) {
        const float d = (train[i] - q).norm();
        if (d < bd) bd = d, best = i;
      }
      nn.push_back(train_poses[best]);
    }
    e.nearest.push_back(vmap::mean_pose(nn).distance(g.truth));
  }
  return e;
}

void print_errors(const char* label, std::size_t images, const Errors& e) {
  const vmap::examples::ErrorStats g = vmap::examples::error_stats(e.gcs), n = vmap::examples::error_stats(e.nearest);
  std::printf("  %-22s %zu image(s): GCS median %.3f m  mean %.3f m  max %.3f m | nearest-image baseline median %.3f m"
              "  max %.3f m  (%zu queries)\n",
              label, images, g.median, g.mean, g.max, n.median, n.max, e.gcs.size());
}

vmap::GcsOptions gcs_options(std::size_t neurons, std::size_t lambda) {
  return {.lambda = lambda, .max_cells = neurons, .seed = 1};
}

/// The bag-of-words histogram's defaults (a flat vocabulary, seed 1) with 128 words.
vmap::BowHistogramOptions bow_options() {
  vmap::BowHistogramOptions o;
  o.vocabulary.branching = 128;
  return o;
}

}  // namespace

int main(int argc, char** argv) {
  CLI::App app{"GCS map and localization benchmark"};
  std::string shared = VMAP_SHARED_DIR;
  std::string posters = std::string(VMAP_SOURCE_DIR) + "/examples/data/tum_fr1_rpy_60/rgb";
  int repeat = 3;
  app.add_option("--shared", shared, "The shared data folder")->default_str(shared);
  app.add_option("--posters", posters, "Photos for the room's posters")->default_str(posters);
  app.add_option("--repeat", repeat, "Timing runs (the fastest is reported)")->default_val(3)->check(CLI::Range(1, 100));
  CLI11_PARSE(app, argc, argv);

  try {
    // ---- 1. the virtual room (the paper's setting) ---------------------------------
    const vmap::VirtualRoomOptions ro;
    const vmap::VirtualRoom room(vmap::load_posters(posters, 16), ro);
    vmap::AkazeDescriptor akaze;
    const vmap::CircuitOptions co{.margin_m = 1.5, .laps = 2, .images_per_lap = 82, .seed = 1};
    auto t0 = clock_type::now();
    const auto rec = vmap::record_circuit(room, akaze, vmap::square_circuit(ro, co));
    std::printf("virtual room %.0f x %.0f m, %zu training images %dx%d (2 laps), rendered + nearest wall in %.2f s\n",
                ro.size_m, ro.size_m, rec.images.size(), ro.image_size.width, ro.image_size.height, seconds_since(t0));
    const auto outer = std::count_if(rec.choices.begin(), rec.choices.end(),
                                     [](const vmap::NearestWall& w) { return w.side == vmap::WallSide::right; });
    std::printf("nearest-wall choice picked the truly nearer (outer) wall for %ld of %zu images\n", static_cast<long>(outer),
                rec.choices.size());
    t0 = clock_type::now();
    std::vector<vmap::Features> feats;
    for (const auto& im : rec.images) feats.push_back(akaze.extract(im));
    const double t_feat = seconds_since(t0);
    t0 = clock_type::now();
    vmap::BowHistogram bow(bow_options());
    bow.fit(feats);
    std::vector<Eigen::VectorXf> train;
    for (const auto& f : feats) train.push_back(bow(f));
    const double t_hist = seconds_since(t0);
    std::printf("A-KAZE on 164 images %.2f s; vocabulary (128 words) + histograms %.2f s\n", t_feat, t_hist);

    // Test positions: half a step off the training samples, another noise draw; the
    // second image of a position is panned by 6 degrees.
    vmap::CircuitOptions qo = co;
    qo.laps = 1;
    qo.phase = 0.5;
    qo.seed = 1001;
    const auto qc = vmap::square_circuit(ro, qo);
    // 20 test positions as one-image and two-image queries, under a histogram policy.
    auto query_groups = [&](auto& histogram) {
      std::pair<std::vector<Group>, std::vector<Group>> groups;
      for (std::size_t k = 0; k < 20; ++k) {
        const Pose2 truth = qc[k * qc.size() / 20].truth;
        const auto a = histogram(akaze.extract(vmap::capture_view(room, akaze, truth).image));
        const auto b =
            histogram(akaze.extract(vmap::capture_view(room, akaze, truth, 6.0 * std::numbers::pi / 180.0).image));
        groups.first.push_back({{a}, truth});
        groups.second.push_back({{a, b}, truth});
      }
      return groups;
    };
    const auto [one, two] = query_groups(bow);

    const double paper[3] = {4063.0, 14287.0, 33347.0};
    const std::size_t sizes[3] = {100, 200, 300};
    std::printf("\nGCS training on 164 room histograms (lambda 50; fastest of %d runs) vs the paper's reported times\n", repeat);
    std::printf("  %7s %10s %12s %12s %14s %14s\n", "neurons", "epochs", "vmap [s]", "paper [s]", "paper / vmap",
                "with posed");
    std::vector<vmap::PoseMap<vmap::GcsXf>> maps;
    double train_seconds[3] = {0, 0, 0};
    for (int i = 0; i < 3; ++i) {
      double best = 1e300;
      vmap::GcsTrainStats st;
      std::optional<vmap::GcsXf> net;
      for (int r = 0; r < repeat; ++r) {
        vmap::GcsXf g(gcs_options(sizes[i], 50));
        t0 = clock_type::now();
        st = g.train(train);
        best = std::min(best, seconds_since(t0));
        net.emplace(std::move(g));
      }
      train_seconds[i] = best;
      maps.emplace_back(std::move(*net), train, rec.odometry);
      std::printf("  %7zu %10zu %12.4f %12.0f %14.0f %14zu\n", sizes[i], st.epochs, best, paper[i], paper[i] / best,
                  maps.back().neurons_with_pose());
    }
    const double total = t_feat + t_hist + train_seconds[2];
    std::printf("  whole pipeline for 300 neurons (A-KAZE + vocabulary + histograms + GCS): %.2f s, paper / vmap = %.0f\n",
                total, paper[2] / total);

    std::printf("\nroom localization at 20 test positions (training poses = odometry, truth = true poses; paper: "
                "+-(0.06, 0.1) m)\n");
    for (int i = 0; i < 3; ++i) {
      const std::string label = std::to_string(sizes[i]) + " neurons";
      print_errors(label.c_str(), 1, evaluate(maps[static_cast<std::size_t>(i)], train, rec.odometry, one));
      print_errors(label.c_str(), 2, evaluate(maps[static_cast<std::size_t>(i)], train, rec.odometry, two));
    }
    {
      vmap::GridHistogram grid;
      std::vector<Eigen::VectorXf> gt;
      for (const auto& f : feats) gt.push_back(grid(f));
      vmap::GcsXf g(gcs_options(100, 50));
      g.train(gt);
      const vmap::PoseMap<vmap::GcsXf> gm(std::move(g), gt, rec.odometry);
      const auto [g1, g2] = query_groups(grid);
      print_errors("grid histogram, 100 n.", 1, evaluate(gm, gt, rec.odometry, g1));
      print_errors("grid histogram, 100 n.", 2, evaluate(gm, gt, rec.odometry, g2));
    }

    // ---- 2. TUM fr3 cabinet ---------------------------------------------------------
    const auto dir = std::filesystem::path(shared) / "data/tum_fr3_cabinet_kf";
    if (!std::filesystem::exists(dir)) {
      std::printf("\n%s not found: TUM part skipped\n", dir.string().c_str());
      return 0;
    }
    auto src = vmap::FrameSource::open(dir / "rgb");
    std::vector<vmap::Features> cf;
    t0 = clock_type::now();
    while (auto f = src.next()) cf.push_back(akaze.extract(f->image));
    const double t_cab = seconds_since(t0);
    const auto poses = vmap::read_tum_poses(dir / "truth_cam_poses.txt");
    if (poses.size() != cf.size()) {
      std::fprintf(stderr, "pose count %zu differs from image count %zu\n", poses.size(), cf.size());
      return 1;
    }
    std::vector<vmap::Features> even;
    std::vector<Pose2> even_poses;
    for (std::size_t i = 0; i < cf.size(); i += 2) {
      even.push_back(cf[i]);
      even_poses.push_back(poses[i].pose);
    }
    vmap::BowHistogram cbow(bow_options());
    cbow.fit(even);
    std::vector<Eigen::VectorXf> ctrain;
    for (const auto& f : even) ctrain.push_back(cbow(f));
    std::vector<Group> c1, c2;
    for (std::size_t i = 1; i < cf.size(); i += 2) {
      c1.push_back({{cbow(cf[i])}, poses[i].pose});
      if (i + 2 < cf.size())
        c2.push_back({{cbow(cf[i]), cbow(cf[i + 2])}, vmap::mean_pose({poses[i].pose, poses[i + 2].pose})});
    }
    std::printf("\nTUM fr3 cabinet: %zu key frames 640x480 (A-KAZE %.2f s); train on %zu even frames, localize the odd"
                " ones; floor = TUM (x, y), z up\n",
                cf.size(), t_cab, even.size());
    for (std::size_t n : {20u, 40u}) {
      vmap::GcsXf g(gcs_options(n, 20));
      t0 = clock_type::now();
      g.train(ctrain);
      const double tt = seconds_since(t0);
      const vmap::PoseMap<vmap::GcsXf> m(std::move(g), ctrain, even_poses);
      const std::string label = std::to_string(n) + " neurons (" + std::to_string(tt).substr(0, 6) + " s)";
      print_errors(label.c_str(), 1, evaluate(m, ctrain, even_poses, c1));
      print_errors(label.c_str(), 2, evaluate(m, ctrain, even_poses, c2));
    }
  } catch (const vmap::Error& e) {
    std::fprintf(stderr, "bench_localize: %s\n", e.what());
    return 1;
  }
  return 0;
}
