// `vmap match A B`: extract, match and verify one image pair and say what came out:
// the quickest way to see whether two views share enough for a fundamental matrix.
#include "common/cli_support.hpp"
#include "common/draw.hpp"
#include "common/keyframe_cli.hpp"
#include "common/policies.hpp"
#include "vmap/cli.hpp"

#include <vmap/io/atomic_file.hpp>
#include <vmap/io/image.hpp>
#include <vmap/runtime/option_names.hpp>
#include <vmap/runtime/pair.hpp>
#include <vmap/runtime/stack_choice.hpp>

#include <nlohmann/json.hpp>
#include <opencv2/imgcodecs.hpp>

#include <cstdio>
#include <filesystem>
#include <memory>
#include <string>
#include <vector>

namespace {

namespace ex = vmap::examples;

struct MatchArgs {
  std::string image_a, image_b;
  vmap::examples::DescriptorChoice descriptor;
  std::string estimator = "magsac";
  double epipolar_px = 1.0;
  std::string camera;
  std::string out;
  bool json = false;
};

int run(const MatchArgs& args, const CLI::App& app) {
  ex::current_inputs() = {args.image_a, args.image_b};
  const auto camera = ex::load_camera_option(args.camera);
  const vmap::PolicyStack stack = ex::stack_of(args.descriptor, args.estimator, camera);
  if (!args.out.empty()) ex::prepare_output_dir(args.out, "--out", {args.image_a, args.image_b}, {"matches.png"});
  const cv::Mat a_img = vmap::read_image(args.image_a);
  const cv::Mat b_img = vmap::read_image(args.image_b);
  const vmap::PairCheck c = vmap::check_pair(stack, a_img, b_img, {.epipolar_px = args.epipolar_px},
                                             vmap::camera_name(stack, vmap::OptionNames::command_line()));
  const vmap::Verification& v = c.verification;
  std::vector<std::string> written;
  if (!args.out.empty()) {
    char caption[200];
    std::snprintf(caption, sizeof caption, "%zu | %zu features, %zu matches, %d inliers, S = %.3f", c.a.size(),
                  c.b.size(), c.matches.size(), v.inliers, c.similarity);
    vmap::write_image_atomically(std::filesystem::path(args.out) / "matches.png",
                                 ex::captioned(ex::draw_verified_matches(a_img, c.a, b_img, c.b, c.matches, v), caption));
    written.push_back("matches.png");
  }
  if (args.json) {
    nlohmann::json j = {{"command", "match"},
                        {"inputs", {ex::path_string(args.image_a), ex::path_string(args.image_b)}},
                        {"options", ex::options_json(app)},
                        {"features_a", c.a.size()},
                        {"features_b", c.b.size()},
                        {"matches", c.matches.size()},
                        {"status", std::string(vmap::to_string(v.status))},
                        {"inliers", v.inliers},
                        {"similarity", ex::finite_or_null(c.similarity)},
                        {"degenerate", v.degeneracy != vmap::Degeneracy::none},
                        {"homography_inliers", v.homography_inliers},
                        {"seconds", c.seconds()},
                        {"extract_seconds", c.extract_seconds},
                        {"match_seconds", c.match_seconds},
                        {"verify_seconds", c.verify_seconds},
                        {"out", args.out.empty() ? nlohmann::json(nullptr) : nlohmann::json(ex::path_string(args.out))},
                        {"files", written}};
    ex::print_json(j);
  } else {
    if (camera) std::printf("camera        %s\n", camera->file.string().c_str());
    std::printf("features      %zu | %zu (%s)\n", c.a.size(), c.b.size(), args.descriptor.name.c_str());
    std::printf("matches       %zu (mutual nearest neighbours)\n", c.matches.size());
    std::printf("verification  %s (%s, %.2f px)\n", std::string(vmap::to_string(v.status)).c_str(),
                args.estimator.c_str(), args.epipolar_px);
    std::printf("inliers       %d\n", v.inliers);
    std::printf("similarity    %.3f  (eq. 5: inliers / max(|D_a|, |D_b|))\n", c.similarity);
    if (v.ok())
      std::printf("degeneracy    %s (%d of the inliers fit one homography)\n",
                  std::string(vmap::to_string(v.degeneracy)).c_str(), v.homography_inliers);
    std::printf("time          extract %.1f ms, match %.1f ms, verify %.1f ms\n", 1e3 * c.extract_seconds,
                1e3 * c.match_seconds, 1e3 * c.verify_seconds);
  }
  if (!args.out.empty() && !args.json)
    std::printf("wrote         %s/matches.png (inliers green, outliers blue)\n", args.out.c_str());
  return 0;
}

const bool registered = vmap::cli::add_command(
    {"match", "Extract, match and verify one image pair", [](CLI::App& app) -> std::function<int()> {
       auto args = std::make_shared<MatchArgs>();
       app.add_option("image_a", args->image_a, "First image")->required();
       app.add_option("image_b", args->image_b, "Second image")->required();
       ex::add_feature_options(app, args->descriptor.name, args->descriptor.model, args->descriptor.features,
                              args->descriptor.refine_model);
       app.add_option("--estimator", args->estimator, "magsac, ransac, lmeds or 8point");
       app.add_option("--epipolar-px", args->epipolar_px, "Epipolar distance threshold in pixels")
           ->check(ex::real_in(0.0, 1000.0, true));
       app.add_option("--camera", args->camera, "Calibration (ORB-SLAM YAML, ROS camera_info, KITTI calib.txt): undistort keypoints first");
       app.add_option("--out", args->out, "Folder for matches.png, the verified matches (created if missing)");
       app.add_flag("--json", args->json, "Print one JSON object on stdout");
       return [args, &app] { return run(*args, app); };
     }});

}  // namespace
