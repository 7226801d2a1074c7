// `vmap calibrate PLACE PLACE ...`: the place decision's chance rate for a stack,
// measured on places that share nothing (runtime/calibration.hpp), to give to
// `vmap build --memory --chance-rate` and `vmap loops --chance-rate`.
#include "common/cli_support.hpp"
#include "common/keyframe_cli.hpp"
#include "common/policies.hpp"
#include "vmap/cli.hpp"

#include <vmap/runtime/calibration.hpp>
#include <vmap/runtime/loops.hpp>
#include <vmap/runtime/option_names.hpp>
#include <vmap/runtime/stack_choice.hpp>

#include <nlohmann/json.hpp>

#include <chrono>
#include <cstdint>
#include <cstdio>
#include <memory>
#include <string>
#include <vector>

namespace {

namespace ex = vmap::examples;

struct CalibrateArgs {
  std::vector<std::string> places;
  vmap::examples::DescriptorChoice descriptor;
  std::string estimator = "magsac";
  std::size_t pairs = vmap::ChancePairs{}.pairs;
  std::uint64_t seed = vmap::ChancePairs{}.seed;
  bool json = false;
};

int run(const CalibrateArgs& args, const CLI::App& app) {
  ex::current_inputs() = args.places;
  if (args.places.size() < 2) ex::usage_error("give at least two places (folders, lists or videos that share nothing)");
  const vmap::PolicyStack stack = ex::stack_of(args.descriptor, args.estimator, std::nullopt);
  const auto t0 = std::chrono::steady_clock::now();
  std::vector<vmap::SequenceFeatures> places;
  std::vector<std::size_t> frames;
  std::size_t skipped = 0;
  for (const std::string& place : args.places) {
    places.push_back(vmap::extract_features(place, stack, {}, ex::reporting_skips()));
    frames.push_back(places.back().frames.size());
    skipped += places.back().skipped;
    std::fprintf(stderr, "vmap calibrate: %zu frames of %s in %.1f s\n", frames.back(), place.c_str(),
                 places.back().seconds);
    if (frames.back() == 0) ex::usage_error(place + ": no frame could be read");
  }
  const vmap::ChanceCalibration c = vmap::calibrate_chance_rate(stack, std::move(places), {.pairs = args.pairs, .seed = args.seed});
  const double shipped = vmap::measured_chance_rate(stack);
  const double seconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
  if (args.json) {
    std::vector<std::string> inputs;
    for (const auto& p : args.places) inputs.push_back(ex::path_string(p));
    ex::print_json({{"command", "calibrate"},
                    {"inputs", inputs},
                    {"options", ex::options_json(app)},
                    {"stack", vmap::to_string(stack)},
                    {"frames", frames},
                    {"rate", c.rate},
                    {"pairs", c.pairs},
                    {"weighed", c.weighed},
                    {"strongest_significance", c.strongest},
                    {"measured_chance_rate", shipped},
                    {"seconds", seconds},
                    {"skipped_frames", skipped}});
    return 0;
  }
  std::printf("stack         %s\n", vmap::summary(stack).c_str());
  std::printf("pairs         %zu of %zu places, seed %llu; %zu with at least %d inliers\n", c.pairs, args.places.size(),
              static_cast<unsigned long long>(args.seed), c.weighed, vmap::ChanceCalibrationOptions{}.min_inliers);
  std::printf("chance rate   %.4f (the foreign pair at the 99th percentile reaches significance 5; the strongest %.1f)\n",
              c.rate, c.strongest);
  std::printf("shipped rate  %.4f (vmap::measured_chance_rate, the default of build --memory and loops)\n", shipped);
  std::printf("use           vmap build --memory M --chance-rate %.4f ...\n", c.rate);
  std::printf("time          %.1f s\n", seconds);
  return 0;
}

const bool registered = vmap::cli::add_command(
    {"calibrate", "Measure the place decision's chance rate for a stack on places that share nothing",
     [](CLI::App& app) -> std::function<int()> {
       auto args = std::make_shared<CalibrateArgs>();
       app.add_option("places", args->places,
                      "Two or more places (image folders, list files, videos, TUM rgb.txt) that share nothing")
           ->required();
       ex::add_feature_options(app, args->descriptor.name, args->descriptor.model, args->descriptor.features,
                              args->descriptor.refine_model);
       app.add_option("--estimator", args->estimator, "magsac, ransac, lmeds or 8point");
       app.add_option("--pairs", args->pairs, "Foreign pairs to verify (at least 100)")->check(ex::count_in(100, 1000000));
       app.add_option("--seed", args->seed, "Seed of the pairs drawn");
       app.add_flag("--json", args->json, "Print one JSON object on stdout");
       return [args, &app] { return run(*args, app); };
     }});

}  // namespace
