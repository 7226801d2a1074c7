// `vmap build INPUT`: key images of a video (García-Pintos et al. 2023, Algorithm 1 /
// eq. 6), the map's quality (eq. 7), and with --out the map file, a contact sheet of the
// key images and the verified matches of the first and of the weakest key-image pair.
#include "common/cli_support.hpp"
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
#include <cmath>
#include <cstdio>
#include <filesystem>
#include <optional>
#include <string>
#include <vector>

namespace {

namespace ex = vmap::examples;

struct BuildArgs {
  ex::KeyframeArgs common;
  double threshold = 0.3;
  bool single_thread = false;
};

std::optional<std::size_t> expected_frames(const vmap::FrameSource& src, const ex::KeyframeArgs& a) {
  const auto total = src.total();
  if (!total) return std::nullopt;
  const std::size_t end = a.end > 0 ? std::min(a.end, *total) : *total;
  return end > a.start ? (end - a.start + a.stride - 1) / a.stride : 0;
}

// The human table goes to stdout, or to stderr when --json owns stdout.
void print_table(std::FILE* out, const vmap::VisualMap& map) {
  const auto& keys = map.keys;
  std::fprintf(out, "  %4s  %6s  %-28s  %8s  %6s\n", "key", "frame", "name", "inliers", "S");
  const std::size_t m = keys.size();
  for (std::size_t k = 0; k < m; ++k) {
    if (m > 16 && k == 10) {
      std::fprintf(out, "  %4s\n", "...");
      k = m - 5;
    }
    const std::string name = keys[k].name.size() > 28 ? "..." + keys[k].name.substr(keys[k].name.size() - 25) : keys[k].name;
    if (k == 0)
      std::fprintf(out, "  %4zu  %6zu  %-28s  %8s  %6s\n", k + 1, keys[k].frame_index, name.c_str(), "-", "-");
    else
      std::fprintf(out, "  %4zu  %6zu  %-28s  %8d  %6.3f\n", k + 1, keys[k].frame_index, name.c_str(),
                  map.pairs[k - 1].inliers, map.pairs[k - 1].similarity);
  }
}

/// The key images in colour. Features come from frames decoded straight to grey
/// (libjpeg's grey decoding differs slightly from converting colour, and the key images
/// must not depend on --out), so image files are read again in colour here; video
/// frames were decoded in colour and converted exactly as the grey mode does.
void colour_key_images(vmap::VisualMap& map, const vmap::FrameSource& src) {
  if (src.kind() == vmap::SourceKind::video || src.kind() == vmap::SourceKind::live) return;
  const auto paths = src.paths();
  for (auto& k : map.keys) {
    cv::Mat colour = cv::imread(paths.at(k.frame_index).string(), cv::IMREAD_COLOR);
    if (!colour.empty()) k.image = colour;
  }
}

/// The lowest-S consecutive pair (the map's weakest link), index into map.pairs.
std::size_t weakest_pair(const vmap::VisualMap& map) {
  std::size_t w = 0;
  for (std::size_t k = 1; k < map.pairs.size(); ++k)
    if (map.pairs[k].similarity < map.pairs[w].similarity) w = k;
  return w;
}

/// Key images i and i+1 with their verified matches and a caption.
template <class Selector>
cv::Mat pair_picture(const vmap::VisualMap& map, std::size_t i, Selector& sel, const std::string& what) {
  // Matches and verification are deterministic, so these are the ones the map records.
  const auto& fe = sel.front_end();
  const auto& a = map.keys[i];
  const auto& b = map.keys[i + 1];
  const vmap::Matches matches = fe.match(a.features, b.features);
  vmap::PairScore s = fe.bound(a.features, b.features, matches);
  fe.verify(a.features, b.features, matches, s);
  char caption[256];
  std::snprintf(caption, sizeof caption, "%s: K%zu-K%zu, frames %zu-%zu: %zu matches, %d inliers, S = %.3f",
                what.c_str(), i + 1, i + 2, a.frame_index, b.frame_index, matches.size(), s.verification.inliers,
                map.pairs[i].similarity);
  return ex::captioned(ex::draw_verified_matches(a.image, a.features, b.image, b.features, matches, s.verification),
                       caption);
}

template <class Selector>
std::vector<std::string> write_outputs(const ex::OutputFolder& dir, const vmap::VisualMap& map, Selector& sel) {
  std::vector<std::string> written;
  vmap::save_map(map, dir / "map.vmap");
  written.push_back("map.vmap");
  std::string names;
  for (const auto& k : map.keys) names += std::to_string(k.frame_index) + " " + k.name + "\n";
  vmap::write_file_atomically(dir / "key_images.txt", names);
  written.push_back("key_images.txt");
  std::vector<cv::Mat> images;
  std::vector<std::string> captions;
  for (std::size_t k = 0; k < map.keys.size(); ++k) {
    images.push_back(map.keys[k].image);
    captions.push_back("K" + std::to_string(k + 1) + "  frame " + std::to_string(map.keys[k].frame_index));
  }
  vmap::write_image_atomically(dir / "contact_sheet.png", ex::contact_sheet(images, captions));
  written.push_back("contact_sheet.png");
  if (map.keys.size() >= 2) {
    std::vector<cv::Mat> panels{pair_picture(map, 0, sel, "first pair")};
    const std::size_t w = weakest_pair(map);
    if (w != 0) panels.push_back(pair_picture(map, w, sel, "weakest link (lowest S)"));
    vmap::write_image_atomically(dir / "matches.png", ex::stack_vertically(panels));
    written.push_back("matches.png");
  }
  return written;
}

std::function<int()> setup(CLI::App& app) {
  auto args = std::make_shared<BuildArgs>();
  ex::add_keyframe_options(app, args->common);
  app.add_option("--threshold,--tau", args->threshold, "Similarity threshold tau: a new key image when S < tau")
      ->check(ex::real_in(0.0, 1.0, true));
  app.add_option("--out", args->common.out,
                 "Folder for map.vmap, key_images.txt, contact_sheet.png and matches.png (created if missing)");
  app.add_flag("--single-thread", args->single_thread, "Decode and extract on the matching thread");
  return [args, &app]() -> int {
    const auto& a = args->common;
    ex::current_inputs() = {a.input};
    ex::check_range(a);
    const auto camera = ex::load_camera_option(a.camera);
    const bool pictures = !a.out.empty();
    // Everything the command line can get wrong is refused before the first frame.
    std::optional<ex::OutputFolder> out_dir;
    if (pictures) out_dir.emplace(a.out, "--out", std::vector<std::filesystem::path>{a.input},
                                  std::vector<std::string>{"map.vmap", "key_images.txt", "contact_sheet.png", "matches.png"});
    const vmap::SelectorOptions so{.tau = args->threshold, .rule = ex::parse_rule(a.rule), .keep_images = pictures};
    const auto estimator = ex::make_estimator(a.estimator, camera);
    auto src = vmap::FrameSource::open(a.input, ex::source_options(a, true));
    if (pictures && src.kind() == vmap::SourceKind::video)
      src = vmap::FrameSource::open(a.input, ex::source_options(a, false));
    const auto expected = expected_frames(src, a);
    return ex::with_descriptor(a.descriptor(), [&](auto descriptor) -> int {
      const auto matcher = ex::matcher_for(descriptor);
      vmap::KeyframeSelector sel(std::move(descriptor), matcher, estimator, vmap::InlierRatio{}, so);
      ex::Progress progress("vmap build", expected);
      vmap::run_selector(src, sel, {.pipelined = !args->single_thread}, [&](const vmap::FrameResult&) {
        progress.update(sel.map().frames, std::to_string(sel.map().keys.size()) + " key images");
      });
      const double seconds = progress.seconds();
      const vmap::VisualMap& map = sel.map();
      const std::size_t skipped = src.skipped().size();
      progress.done(std::to_string(map.keys.size()) + " key images, " + std::to_string(skipped) + " skipped");
      if (map.frames == 0) vmap::detail::fail("'" + a.input + "' gave no frame in the requested range");
      const auto st = map.stats();
      const double fps = seconds > 0 ? static_cast<double>(map.frames) / seconds : 0.0;
      std::vector<std::string> written;
      if (pictures) {
        vmap::VisualMap coloured = map;
        colour_key_images(coloured, src);
        written = write_outputs(*out_dir, coloured, sel);
        out_dir->commit();
      }
      if (a.json) {
        nlohmann::json j{{"command", "build"},
                         {"input", ex::path_string(a.input)},
                         {"options", ex::options_json(app)},
                         {"frames", st.frames},
                         {"skipped_frames", skipped},
                         {"key_images", st.key_images},
                         {"min_matches", st.min_matches},
                         {"max_matches", st.max_matches},
                         {"mean_matches", ex::finite_or_null(st.mean_matches)},
                         {"quality", ex::finite_or_null(st.quality)},
                         {"threshold", args->threshold},
                         {"seconds", seconds},
                         {"fps", fps},
                         {"key_frames", map.key_indices()},
                         {"out", a.out.empty() ? nlohmann::json(nullptr) : nlohmann::json(ex::path_string(a.out))},
                         {"files", written}};
        ex::print_json(j);
        return 0;
      }
      std::FILE* out = stdout;
      std::fprintf(out, "vmap build: %s (%s + mutual NN + %s, threshold %.2f, %s rule)%s\n\n", a.input.c_str(),
                   a.features.c_str(), a.estimator.c_str(), args->threshold,
                   a.rule == "previous" ? "eq. 6 previous-frame" : "Algorithm 1 current-frame",
                   camera ? (", camera " + camera->file.string()).c_str() : "");
      print_table(out, map);
      std::fprintf(out, "\n  frames            %zu\n", st.frames);
      if (skipped > 0) std::fprintf(out, "  skipped frames    %zu (unreadable, listed above)\n", skipped);
      std::fprintf(out, "  key images        %zu (%.1f %% of the frames)\n", st.key_images,
                   100.0 * static_cast<double>(st.key_images) / static_cast<double>(st.frames));
      if (st.key_images >= 2)
        std::fprintf(out, "  inliers K_i-K_i+1 min %d, max %d, mean %.1f\n", st.min_matches, st.max_matches,
                     st.mean_matches);
      if (std::isfinite(st.quality))
        std::fprintf(out, "  quality (eq. 7)   %.3f\n", st.quality);
      else
        std::fprintf(out, "  quality (eq. 7)   not a finite number\n");
      std::fprintf(out, "  time              %.2f s (%.1f frames/s)\n", seconds, fps);
      if (pictures) {
        std::string list;
        for (const auto& f : written) list += (list.empty() ? "" : ", ") + f;
        std::fprintf(out, "\n  wrote %s/{%s}\n", a.out.c_str(), list.c_str());
      }
      return 0;
    });
  };
}

[[maybe_unused]] const bool registered = vmap::cli::add_command({"build", "Select the key images of a video (visual map)", setup});

}  // namespace
