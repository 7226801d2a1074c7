// `vmap match A B`: extract, match and verify one image pair and say what came out:
// the quickest way to see whether two views share enough for a fundamental matrix.
#include "common/draw.hpp"
#include "common/policies.hpp"
#include "vmap/cli.hpp"

#include <vmap/geometry/calibrated.hpp>
#include <vmap/geometry/fundamental.hpp>
#include <vmap/io/calibration.hpp>
#include <vmap/geometry/similarity.hpp>
#include <vmap/io/atomic_file.hpp>
#include <vmap/matching/brute_force.hpp>

#include <nlohmann/json.hpp>
#include <opencv2/imgcodecs.hpp>

#include <chrono>
#include <cstdio>
#include <filesystem>
#include <memory>
#include <optional>
#include <string>

namespace {

struct MatchArgs {
  std::string image_a, image_b;
  vmap::examples::DescriptorChoice descriptor;
  std::string estimator = "magsac";
  double threshold = 1.0;
  std::string out;
  bool json = false;
  std::string camera;  // calibration file; empty: raw pixels
};

cv::Mat read_image(const std::string& path) {
  if (!std::filesystem::exists(path)) vmap::detail::fail("image '" + path + "' does not exist");
  cv::Mat img = cv::imread(path, cv::IMREAD_UNCHANGED);
  if (img.empty()) vmap::detail::fail("image '" + path + "' cannot be decoded");
  return img;
}

int run(const MatchArgs& args) {
  using clock = std::chrono::steady_clock;
  const cv::Mat a_img = read_image(args.image_a);
  const cv::Mat b_img = read_image(args.image_b);
  const vmap::Calibrated<vmap::FundamentalEstimator> estimator(
      args.camera.empty() ? std::nullopt : std::optional<vmap::Camera>(vmap::read_camera(args.camera)),
      vmap::FundamentalEstimator({.method = vmap::examples::parse_method(args.estimator), .threshold_px = args.threshold}));
  const vmap::BruteForceMatcher matcher;
  return vmap::examples::with_descriptor(args.descriptor, [&](auto descriptor) {
    const auto t0 = clock::now();
    const vmap::Features a = descriptor.extract(a_img);
    const vmap::Features b = descriptor.extract(b_img);
    const auto t1 = clock::now();
    const vmap::Matches m = matcher.match(a, b);
    const auto t2 = clock::now();
    const vmap::Verification v = estimator.verify(a, b, m);
    const auto t3 = clock::now();
    const double s = vmap::InlierRatio{}(a, b, v);
    auto ms = [](auto d) { return std::chrono::duration<double, std::milli>(d).count(); };
    if (args.json) {
      nlohmann::json j = {{"image_a", args.image_a},
                          {"image_b", args.image_b},
                          {"features_a", a.size()},
                          {"features_b", b.size()},
                          {"matches", m.size()},
                          {"status", std::string(vmap::to_string(v.status))},
                          {"inliers", v.inliers},
                          {"similarity", s},
                          {"degenerate", v.degeneracy != vmap::Degeneracy::none},
                          {"homography_inliers", v.homography_inliers},
                          {"ms_extract", ms(t1 - t0)},
                          {"ms_match", ms(t2 - t1)},
                          {"ms_verify", ms(t3 - t2)},
                          {"camera", args.camera}};
      std::printf("%s\n", j.dump(2).c_str());
    } else {
      std::printf("features      %zu | %zu (%s)\n", a.size(), b.size(), args.descriptor.name.c_str());
      std::printf("matches       %zu (mutual nearest neighbours)\n", m.size());
      std::printf("verification  %s (%s, %.2f px)\n", std::string(vmap::to_string(v.status)).c_str(),
                  args.estimator.c_str(), args.threshold);
      if (!args.camera.empty()) std::printf("camera        %s (keypoints undistorted)\n", args.camera.c_str());
      std::printf("inliers       %d\n", v.inliers);
      std::printf("similarity    %.3f  (eq. 5: inliers / max(|D_a|, |D_b|))\n", s);
      if (v.ok())
        std::printf("degeneracy    %s (%d of the inliers fit one homography)\n",
                    std::string(vmap::to_string(v.degeneracy)).c_str(), v.homography_inliers);
      std::printf("time          extract %.1f ms, match %.1f ms, verify %.1f ms\n", ms(t1 - t0), ms(t2 - t1),
                  ms(t3 - t2));
    }
    if (!args.out.empty()) {
      vmap::write_image_atomically(args.out, vmap::examples::draw_verified_matches(a_img, a, b_img, b, m, v));
      if (!args.json) std::printf("wrote         %s (inliers green, outliers blue)\n", args.out.c_str());
    }
    return 0;
  });
}

const bool registered = vmap::cli::add_command(
    {"match", "Extract, match and verify one image pair", [](CLI::App& app) -> std::function<int()> {
       auto args = std::make_shared<MatchArgs>();
       app.add_option("image_a", args->image_a, "First image")->required();
       app.add_option("image_b", args->image_b, "Second image")->required();
       app.add_option("--features", args->descriptor.name, "orb, akaze, sift or xfeat")->capture_default_str();
       app.add_option("--model", args->descriptor.model, "Model file of a learned descriptor (xfeat)");
       app.add_option("--nfeatures", args->descriptor.features, "Keypoint budget per image (ORB, SIFT; top-k for XFeat)")
           ->capture_default_str()
           ->check(CLI::PositiveNumber);
       app.add_option("--estimator", args->estimator, "magsac, ransac, lmeds or 8point")->capture_default_str();
       app.add_option("--threshold", args->threshold, "Epipolar distance threshold in pixels")
           ->capture_default_str()
           ->check(CLI::PositiveNumber);
       app.add_option("--out", args->out, "Write a PNG of the verified matches here");
       app.add_flag("--json", args->json, "Print one JSON object");
       app.add_option("--camera", args->camera,
                      "Calibration (ORB-SLAM YAML, ROS camera_info, KITTI calib.txt): undistort keypoints first");
       return [args] { return run(*args); };
     }});

}  // namespace
