// `vmap sweep INPUT`: the visual-map paper's threshold table (García-Pintos et al. 2023):
// for each tau the number of key images, min / max / mean verified matches between
// consecutive key images, and the quality (eq. 7); the best-quality row is marked.
#include "common/cli_support.hpp"
#include "common/keyframe_cli.hpp"
#include "vmap/cli.hpp"

#include <vmap/io/atomic_file.hpp>
#include <vmap/io/frame_source.hpp>
#include <vmap/keyframe/sweep.hpp>
#include <vmap/runtime/option_names.hpp>
#include <vmap/runtime/selector.hpp>
#include <vmap/runtime/stack_choice.hpp>

#include <nlohmann/json.hpp>

#include <chrono>
#include <cstdio>
#include <filesystem>
#include <memory>
#include <string>
#include <vector>

namespace {

namespace ex = vmap::examples;

struct SweepArgs {
  ex::KeyframeArgs common;
  std::vector<double> thresholds = {0.1, 0.2, 0.3, 0.4, 0.5, 0.6, 0.7, 0.8, 0.9};
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
  app.add_option("--thresholds,--taus", args->thresholds, "Thresholds tau, comma-separated, each in (0, 1]")
      ->delimiter(',')
      ->check(ex::real_in(0.0, 1.0, true));
  app.add_option("--out", args->common.out, "Folder for sweep.csv, the table as CSV (created if missing)");
  app.add_flag("--single-thread", args->single_thread, "Decode and extract on the matching thread");
  return [args, &app]() -> int {
    const auto& a = args->common;
    ex::current_inputs() = {a.input};
    ex::check_range(a);
    const auto camera = ex::camera_option(a.camera, a.input);
    if (!a.out.empty()) ex::prepare_output_dir(a.out, "--out", {a.input}, {"sweep.csv"});
    auto src = ex::open_frames(a.input, ex::source_options(a, true));
    const vmap::PolicyStack stack = a.stack(camera);
    ex::Progress progress("vmap sweep", src.total());
    const vmap::SweepOptions so{.taus = args->thresholds,
                                .rule = ex::parse_rule(a.rule),
                                .pipelined = !args->single_thread,
                                .on_frame = [&progress](std::size_t done) { progress.update(done); }};
    const vmap::SweepResult r =
        vmap::sweep_thresholds(src, stack, so, vmap::camera_name(stack, vmap::OptionNames::command_line()));
    const double seconds = progress.seconds();
    const std::size_t skipped = src.skipped().size();
    progress.done(std::to_string(r.rows.size()) + " thresholds, " + std::to_string(skipped) + " skipped");
    if (r.frames == 0) vmap::detail::fail("'" + a.input + "' gave no frame in the requested range");
    const double fps = seconds > 0 ? static_cast<double>(r.frames) / seconds : 0.0;
    std::vector<std::string> written;
    if (!a.out.empty()) {
      vmap::write_file_atomically(std::filesystem::path(a.out) / "sweep.csv", csv_table(r));
      written.push_back("sweep.csv");
    }
    if (a.json) {
      nlohmann::json rows = nlohmann::json::array();
      for (const auto& row : r.rows)
        rows.push_back({{"threshold", row.threshold},
                        {"frames", row.stats.frames},
                        {"key_images", row.stats.key_images},
                        {"min_matches", row.stats.min_matches},
                        {"max_matches", row.stats.max_matches},
                        {"mean_matches", ex::finite_or_null(row.stats.mean_matches)},
                        {"quality", ex::finite_or_null(row.stats.quality)},
                        {"key_frames", row.key_frames}});
      nlohmann::json j{{"command", "sweep"},
                       {"input", ex::path_string(a.input)},
                       {"options", ex::options_json(app)},
                       {"rows", rows},
                       {"best_threshold", r.best_threshold()},
                       {"frames", r.frames},
                       {"skipped_frames", skipped},
                       {"seconds", seconds},
                       {"fps", fps},
                       {"out", a.out.empty() ? nlohmann::json(nullptr) : nlohmann::json(ex::path_string(a.out))},
                       {"files", written}};
      ex::print_json(j);
      return 0;
    }
    std::printf("vmap sweep: %s (%s + mutual NN + %s, %zu frames%s)%s\n\n", a.input.c_str(), a.features.c_str(),
                a.estimator.c_str(), r.frames, skipped > 0 ? (", " + std::to_string(skipped) + " skipped").c_str() : "",
                camera ? (", camera " + camera->file.string()).c_str() : "");
    std::printf("  %9s  %10s  %7s  %7s  %8s  %7s\n", "threshold", "key images", "min", "max", "mean", "quality");
    for (std::size_t k = 0; k < r.rows.size(); ++k) {
      const auto& s = r.rows[k].stats;
      std::printf("  %9.2f  %10zu  %7d  %7d  %8.1f  %7.3f%s\n", r.rows[k].threshold, s.key_images, s.min_matches,
                  s.max_matches, s.mean_matches, s.quality, k == r.best ? "  <- best" : "");
    }
    std::printf("\n  min / max / mean: verified matches between consecutive key images\n");
    std::printf("  %zu thresholds in %.2f s (%.1f frames/s); %zu of %zu pair scores from the cache\n", r.rows.size(),
                seconds, fps, r.pair_requests - r.pairs_scored, r.pair_requests);
    if (!written.empty()) std::printf("  wrote %s/sweep.csv\n", a.out.c_str());
    return 0;
  };
}

[[maybe_unused]] const bool registered =
    vmap::cli::add_command({"sweep", "Threshold sweep: the key-image table for several tau", setup});

}  // namespace
