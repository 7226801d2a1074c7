// `vmap build INPUT`: key images of a video (García-Pintos et al. 2023, Algorithm 1 /
// eq. 6), the map's quality (eq. 7), and with --out the map file, a contact sheet of the
// key images and the verified matches between the first two key images.
#include "common/draw.hpp"
#include "common/keyframe_cli.hpp"
#include "common/policies.hpp"
#include "vmap/cli.hpp"

#include <vmap/io/atomic_file.hpp>
#include <vmap/io/frame_source.hpp>
#include <vmap/keyframe/map_io.hpp>
#include <vmap/keyframe/pipeline.hpp>
#include <vmap/keyframe/selector.hpp>
#include <vmap/matching/brute_force.hpp>

#include <nlohmann/json.hpp>

#include <opencv2/imgcodecs.hpp>

#include <algorithm>
#include <chrono>
#include <cstdio>
#include <filesystem>
#include <string>
#include <vector>

namespace {

namespace ex = vmap::examples;

struct BuildArgs {
  ex::KeyframeArgs common;
  double tau = 0.3;
  std::string out;
  bool single_thread = false;
};

std::optional<std::size_t> expected_frames(const vmap::FrameSource& src, const ex::KeyframeArgs& a) {
  const auto total = src.total();
  if (!total) return std::nullopt;
  const std::size_t end = a.end > 0 ? std::min(a.end, *total) : *total;
  return end > a.start ? (end - a.start + a.stride - 1) / a.stride : 0;
}

void print_table(const vmap::VisualMap& map) {
  const auto& keys = map.keys;
  std::printf("  %4s  %6s  %-28s  %8s  %6s\n", "key", "frame", "name", "inliers", "S");
  const std::size_t m = keys.size();
  for (std::size_t k = 0; k < m; ++k) {
    if (m > 16 && k == 10) {
      std::printf("  %4s\n", "...");
      k = m - 5;
    }
    const std::string name = keys[k].name.size() > 28 ? "..." + keys[k].name.substr(keys[k].name.size() - 25) : keys[k].name;
    if (k == 0)
      std::printf("  %4zu  %6zu  %-28s  %8s  %6s\n", k + 1, keys[k].frame_index, name.c_str(), "-", "-");
    else
      std::printf("  %4zu  %6zu  %-28s  %8d  %6.3f\n", k + 1, keys[k].frame_index, name.c_str(),
                  map.pairs[k - 1].inliers, map.pairs[k - 1].similarity);
  }
}

/// The key images in colour. Features come from frames decoded straight to grey
/// (libjpeg's grey decoding differs slightly from converting colour, and the key images
/// must not depend on --out), so image files are read again in colour here; video
/// frames were decoded in colour and converted exactly as the grey mode does.
void colour_key_images(vmap::VisualMap& map, const vmap::FrameSource& src) {
  if (src.kind() == vmap::SourceKind::video) return;
  const auto paths = src.paths();
  for (auto& k : map.keys) {
    cv::Mat colour = cv::imread(paths.at(k.frame_index).string(), cv::IMREAD_COLOR);
    if (!colour.empty()) k.image = colour;
  }
}

template <class Selector>
void write_outputs(const std::filesystem::path& dir, const vmap::VisualMap& map, Selector& sel) {
  std::filesystem::create_directories(dir);
  vmap::save_map(map, dir / "map.vmap");
  std::string names;
  for (const auto& k : map.keys) names += std::to_string(k.frame_index) + " " + k.name + "\n";
  vmap::write_file_atomically(dir / "key_images.txt", names);
  std::vector<cv::Mat> images;
  std::vector<std::string> captions;
  for (std::size_t k = 0; k < map.keys.size(); ++k) {
    images.push_back(map.keys[k].image);
    captions.push_back("K" + std::to_string(k + 1) + "  frame " + std::to_string(map.keys[k].frame_index));
  }
  vmap::write_image_atomically(dir / "contact_sheet.png", ex::contact_sheet(images, captions));
  if (map.keys.size() >= 2) {
    // Matches and verification are deterministic, so these are the ones the map records.
    const auto& fe = sel.front_end();
    const auto& a = map.keys[0];
    const auto& b = map.keys[1];
    const vmap::Matches matches = fe.match(a.features, b.features);
    vmap::PairScore s = fe.bound(a.features, b.features, matches);
    fe.verify(a.features, b.features, matches, s);
    vmap::write_image_atomically(
        dir / "matches.png", ex::draw_verified_matches(a.image, a.features, b.image, b.features, matches, s.verification));
  }
}

std::function<int()> setup(CLI::App& app) {
  auto args = std::make_shared<BuildArgs>();
  ex::add_keyframe_options(app, args->common);
  app.add_option("--tau", args->tau, "Similarity threshold: a new key image when S < tau, in (0, 1]")
      ->capture_default_str();
  app.add_option("--out", args->out,
                 "Folder for map.vmap, key_images.txt, contact_sheet.png and matches.png (K1-K2)");
  app.add_flag("--single-thread", args->single_thread, "Decode and extract on the matching thread");
  return [args]() -> int {
    const auto& a = args->common;
    if (!(args->tau > 0.0 && args->tau <= 1.0))
      vmap::detail::fail("--tau must be in (0, 1], got " + std::to_string(args->tau));
    const bool pictures = !args->out.empty();
    auto src = vmap::FrameSource::open(a.input, ex::source_options(a, true));
    if (pictures && src.kind() == vmap::SourceKind::video)
      src = vmap::FrameSource::open(a.input, ex::source_options(a, false));
    const auto expected = expected_frames(src, a);
    const vmap::SelectorOptions so{.tau = args->tau, .rule = ex::parse_rule(a.rule), .keep_images = pictures};
    const auto estimator = ex::make_estimator(a.estimator);
    return ex::with_descriptor(a.descriptor(), [&](auto descriptor) -> int {
      const auto matcher = ex::matcher_for(descriptor);
      vmap::KeyframeSelector sel(std::move(descriptor), matcher, estimator, vmap::InlierRatio{}, so);
      ex::Progress progress(expected);
      const auto t0 = std::chrono::steady_clock::now();
      vmap::run_selector(src, sel, {.pipelined = !args->single_thread},
                         [&](const vmap::FrameResult&) { progress.update(sel.map().frames, sel.map().keys.size()); });
      const double seconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
      progress.done();
      const vmap::VisualMap& map = sel.map();
      if (map.frames == 0) vmap::detail::fail("'" + a.input + "' gave no frame in the requested range");
      const auto st = map.stats();
      const double fps = seconds > 0 ? static_cast<double>(map.frames) / seconds : 0.0;
      if (pictures) {
        vmap::VisualMap coloured = map;
        colour_key_images(coloured, src);
        write_outputs(args->out, coloured, sel);
      }
      if (a.json) {
        nlohmann::json j{{"frames", st.frames},
                         {"key_images", st.key_images},
                         {"min_matches", st.min_matches},
                         {"max_matches", st.max_matches},
                         {"mean_matches", st.mean_matches},
                         {"quality", st.quality},
                         {"seconds", seconds},
                         {"fps", fps},
                         {"tau", args->tau},
                         {"features", a.features},
                         {"estimator", a.estimator},
                         {"rule", a.rule},
                         {"key_frames", map.key_indices()}};
        std::printf("%s\n", j.dump().c_str());
        return 0;
      }
      std::printf("vmap build: %s (%s + mutual NN + %s, tau %.2f, %s rule)\n\n", a.input.c_str(), a.features.c_str(),
                  a.estimator.c_str(), args->tau, a.rule == "previous" ? "eq. 6 previous-frame" : "Algorithm 1 current-frame");
      print_table(map);
      std::printf("\n  frames            %zu\n", st.frames);
      std::printf("  key images        %zu (%.1f %% of the frames)\n", st.key_images,
                  100.0 * static_cast<double>(st.key_images) / static_cast<double>(st.frames));
      if (st.key_images >= 2)
        std::printf("  inliers K_i-K_i+1 min %d, max %d, mean %.1f\n", st.min_matches, st.max_matches, st.mean_matches);
      std::printf("  quality (eq. 7)   %.3f\n", st.quality);
      std::printf("  time              %.2f s (%.1f frames/s)\n", seconds, fps);
      if (pictures)
        std::printf("\n  wrote %s/{map.vmap, key_images.txt, contact_sheet.png%s}\n", args->out.c_str(),
                    st.key_images >= 2 ? ", matches.png" : "");
      return 0;
    });
  };
}

[[maybe_unused]] const bool registered = vmap::cli::add_command({"build", "Select the key images of a video (visual map)", setup});

}  // namespace
