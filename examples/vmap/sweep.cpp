// `vmap sweep INPUT`: the visual-map paper's threshold table (García-Pintos et al. 2023):
// for each tau the number of key images, min / max / mean verified matches between
// consecutive key images, and the quality (eq. 7); the best-quality row is marked.
#include "common/keyframe_cli.hpp"
#include "common/policies.hpp"
#include "vmap/cli.hpp"

#include <vmap/io/atomic_file.hpp>
#include <vmap/io/frame_source.hpp>
#include <vmap/keyframe/sweep.hpp>
#include <vmap/matching/brute_force.hpp>

#include <nlohmann/json.hpp>

#include <chrono>
#include <cstdio>
#include <memory>
#include <string>
#include <vector>

namespace {

namespace ex = vmap::examples;

struct SweepArgs {
  ex::KeyframeArgs common;
  std::vector<double> taus = {0.1, 0.2, 0.3, 0.4, 0.5, 0.6, 0.7, 0.8, 0.9};
  std::string csv;
  bool single_thread = false;
};

std::string csv_table(const vmap::SweepResult& r) {
  std::string out = "threshold,key_images,min_matches,max_matches,mean_matches,quality,best\n";
  char line[160];
  for (std::size_t k = 0; k < r.rows.size(); ++k) {
    const auto& s = r.rows[k].stats;
    std::snprintf(line, sizeof line, "%.3f,%zu,%d,%d,%.2f,%.4f,%d\n", r.rows[k].threshold, s.key_images,
                  s.min_matches, s.max_matches, s.mean_matches, s.quality, k == r.best ? 1 : 0);
    out += line;
  }
  return out;
}

std::function<int()> setup(CLI::App& app) {
  auto args = std::make_shared<SweepArgs>();
  ex::add_keyframe_options(app, args->common);
  app.add_option("--taus", args->taus, "Thresholds, comma-separated, each in (0, 1]")
      ->delimiter(',')
      ->capture_default_str();
  app.add_option("--csv", args->csv, "Also write the table to this CSV file");
  app.add_flag("--single-thread", args->single_thread, "Decode and extract on the matching thread");
  return [args]() -> int {
    const auto& a = args->common;
    for (double t : args->taus)
      if (!(t > 0.0 && t <= 1.0)) vmap::detail::fail("--taus: every threshold must be in (0, 1], got " + std::to_string(t));
    auto src = vmap::FrameSource::open(a.input, ex::source_options(a, true));
    const auto estimator = ex::make_estimator(a.estimator);
    const vmap::SweepOptions so{.taus = args->taus, .rule = ex::parse_rule(a.rule), .pipelined = !args->single_thread};
    const auto t0 = std::chrono::steady_clock::now();
    const vmap::SweepResult r = ex::with_descriptor(a.descriptor(), [&](auto descriptor) {
      const auto matcher = ex::matcher_for(descriptor);
      return vmap::sweep_thresholds(src, std::move(descriptor), matcher, estimator,
                                    vmap::InlierRatio{}, so);
    });
    const double seconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
    if (r.frames == 0) vmap::detail::fail("'" + a.input + "' gave no frame in the requested range");
    const double fps = seconds > 0 ? static_cast<double>(r.frames) / seconds : 0.0;
    if (!args->csv.empty()) vmap::write_file_atomically(args->csv, csv_table(r));
    if (a.json) {
      nlohmann::json rows = nlohmann::json::array();
      for (const auto& row : r.rows)
        rows.push_back({{"threshold", row.threshold},
                        {"frames", row.stats.frames},
                        {"key_images", row.stats.key_images},
                        {"min_matches", row.stats.min_matches},
                        {"max_matches", row.stats.max_matches},
                        {"mean_matches", row.stats.mean_matches},
                        {"quality", row.stats.quality},
                        {"key_frames", row.key_frames}});
      nlohmann::json j{{"rows", rows},
                       {"best_threshold", r.best_threshold()},
                       {"frames", r.frames},
                       {"seconds", seconds},
                       {"fps", fps},
                       {"features", a.features},
                       {"estimator", a.estimator},
                       {"rule", a.rule}};
      std::printf("%s\n", j.dump().c_str());
      return 0;
    }
    std::printf("vmap sweep: %s (%s + mutual NN + %s, %zu frames)\n\n", a.input.c_str(), a.features.c_str(),
                a.estimator.c_str(), r.frames);
    std::printf("  %9s  %10s  %7s  %7s  %8s  %7s\n", "threshold", "key images", "min", "max", "mean", "quality");
    for (std::size_t k = 0; k < r.rows.size(); ++k) {
      const auto& s = r.rows[k].stats;
      std::printf("  %9.2f  %10zu  %7d  %7d  %8.1f  %7.3f%s\n", r.rows[k].threshold, s.key_images, s.min_matches,
                  s.max_matches, s.mean_matches, s.quality, k == r.best ? "  <- best" : "");
    }
    std::printf("\n  min / max / mean: verified matches between consecutive key images\n");
    std::printf("  %zu thresholds in %.2f s (%.1f frames/s); %zu of %zu pair scores from the cache\n", r.rows.size(),
                seconds, fps, r.pair_requests - r.pairs_scored, r.pair_requests);
    return 0;
  };
}

[[maybe_unused]] const bool registered =
    vmap::cli::add_command({"sweep", "Threshold sweep: the key-image table for several tau", setup});

}  // namespace
