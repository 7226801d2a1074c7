// Inliers with and without the camera model (the figures of examples/results/camera.md):
//  1. synthetic two-view scenes through a 160-degree equidistant fisheye and a strong
//     radial-tangential lens (tests/support/lens_scene.hpp, the unit tests' scenes):
//     inliers of the ideal pinhole with the same K (the reference), of F on raw pixels,
//     of Calibrated<FundamentalEstimator> and of EssentialEstimator, and the pose errors;
//  2. tum_fr1_rpy consecutive pairs (i, i+5), ORB 1000 + mutual NN + MAGSAC 1 px, with
//     TUM's published fr1 calibration (examples/data/tum_fr1_camera.yaml): inliers of F
//     on raw pixels, of Calibrated F and of E, and the time per verification.
//
// usage: bench_camera [RGB_TXT] [PAIRS] [CAMERA_YAML]
#include "../../tests/support/lens_scene.hpp"

#include <vmap/features/orb.hpp>
#include <vmap/geometry/calibrated.hpp>
#include <vmap/geometry/essential.hpp>
#include <vmap/geometry/fundamental.hpp>
#include <vmap/io/calibration.hpp>
#include <vmap/io/frame_source.hpp>
#include <vmap/matching/brute_force.hpp>

#include <chrono>
#include <cstdio>
#include <string>
#include <vector>

namespace {

using clock_type = std::chrono::steady_clock;
double ms_since(clock_type::time_point t) {
  return std::chrono::duration<double, std::milli>(clock_type::now() - t).count();
}


struct Column {
  double inliers = 0, wrong = 0, rot = 0, dir = 0;
  void add(const vmap::test::LensScene& s, const vmap::Verification& v, const vmap::RelativePose* p) {
    inliers += v.inliers;
    for (std::size_t k = 0; k < s.matches.size(); ++k)
      if (v.inlier_mask.size() == s.matches.size() && v.inlier_mask[k] && !s.is_inlier[k]) wrong += 1;
    if (p) {
      rot += vmap::test::rotation_error_deg(p->rotation, s.R);
      dir += vmap::test::direction_error_deg(p->translation, s.t);
    }
  }
};

void synthetic(const vmap::Camera& cam, int seeds) {
  Column ideal, raw, cal, ess;
  double truth = 0;
  const vmap::FundamentalEstimator f({.check_degeneracy = false});
  const vmap::Calibrated<vmap::FundamentalEstimator> cf(cam, f);
  const vmap::EssentialEstimator ee(cam);
  for (int seed = 1; seed <= seeds; ++seed) {
    const vmap::test::LensSceneOptions o{.seed = static_cast<std::uint64_t>(seed)};
    const auto real = vmap::test::make_lens_scene(cam, o);
    const auto ref = vmap::test::make_lens_scene(cam, o, true);
    truth += real.true_inliers;
    const auto vi = f.verify(ref.a, ref.b, ref.matches);
    const auto pi = vmap::test::pose_from_f(ref, cam, vi, true);
    ideal.add(ref, vi, &pi);
    raw.add(real, f.verify(real.a, real.b, real.matches), nullptr);
    const auto vc = cf.verify(real.a, real.b, real.matches);
    const auto pc = vmap::test::pose_from_f(real, cam, vc, false);
    cal.add(real, vc, &pc);
    const auto ve = ee.verify(real.a, real.b, real.matches);
    ess.add(real, ve, ve.relative_pose ? &*ve.relative_pose : nullptr);
  }
  const double n = seeds;
  std::printf("  %-38s  true inliers %.1f (mean of %d scenes)\n", std::string(vmap::to_string(cam.lens)).c_str(),
              truth / n, seeds);
  auto row = [&](const char* name, const Column& c, bool pose) {
    std::printf("    %-34s %8.1f  %6.1f %%  %6.2f", name, c.inliers / n, 100.0 * c.inliers / ideal.inliers, c.wrong / n);
    if (pose)
      std::printf("  %8.3f  %8.3f\n", c.rot / n, c.dir / n);
    else
      std::printf("  %8s  %8s\n", "-", "-");
  };
  std::printf("    %-34s %8s  %8s  %6s  %8s  %8s\n", "", "inliers", "of ideal", "wrong", "rot deg", "dir deg");
  row("ideal pinhole, F (reference)", ideal, true);
  row("raw pixels, F", raw, false);
  row("Calibrated<FundamentalEstimator>", cal, true);
  row("EssentialEstimator", ess, true);
}

}  // namespace

int main(int argc, char** argv) {
  const std::string list = argc > 1 ? argv[1] : std::string(VMAP_SHARED_DIR) + "/data/tum_fr1_rpy/rgb.txt";
  const int pairs = argc > 2 ? std::stoi(argv[2]) : 200;
  const std::string yaml = argc > 3 ? argv[3] : std::string(VMAP_SOURCE_DIR) + "/examples/data/tum_fr1_camera.yaml";
  constexpr int gap = 5;

  std::printf("bench_camera 1: synthetic scenes (MAGSAC 1 px, 25 %% outliers, 0.3 px noise)\n");
  synthetic(vmap::test::wide_fisheye_camera(), 10);
  synthetic(vmap::test::wide_radtan_camera(), 10);

  const vmap::Camera cam = vmap::read_camera(yaml);
  std::vector<cv::Mat> frames;
  auto source = vmap::FrameSource::open(list, {.end = static_cast<std::size_t>(pairs + gap), .grey = true});
  while (auto f = source.next()) frames.push_back(f->image);
  if (static_cast<int>(frames.size()) < gap + 1) {
    std::fprintf(stderr, "bench_camera: need at least %d frames in %s\n", gap + 1, list.c_str());
    return 1;
  }
  vmap::OrbDescriptor orb({.features = 1000});
  const vmap::BruteForceMatcher matcher;
  std::vector<vmap::Features> feats;
  for (const auto& img : frames) feats.push_back(orb.extract(img));

  const vmap::FundamentalEstimator f({.check_degeneracy = false});
  const vmap::Calibrated<vmap::FundamentalEstimator> cf(cam, f);
  const vmap::EssentialEstimator ee(cam, {.recover_pose = false});
  struct Acc {
    long inliers = 0;
    int verified = 0;
    double ms = 0;
  } raw, cal, ess;
  long matches = 0;
  int more_cal = 0;
  const int n = static_cast<int>(frames.size()) - gap;
  for (int i = 0; i < n; ++i) {
    const auto& a = feats[static_cast<std::size_t>(i)];
    const auto& b = feats[static_cast<std::size_t>(i + gap)];
    const vmap::Matches m = matcher.match(a, b);
    matches += static_cast<long>(m.size());
    auto run = [&](const auto& est, Acc& acc) {
      const auto t0 = clock_type::now();
      const vmap::Verification v = est.verify(a, b, m);
      acc.ms += ms_since(t0);
      acc.inliers += v.ok() ? v.inliers : 0;
      acc.verified += v.ok() ? 1 : 0;
      return v.ok() ? v.inliers : 0;
    };
    const int r = run(f, raw);
    const int c = run(cf, cal);
    run(ee, ess);
    more_cal += c > r ? 1 : 0;
  }
  std::printf("\nbench_camera 2: %s, %d pairs (i, i+%d), ORB 1000 + mutual NN, MAGSAC 1 px, camera %s\n", list.c_str(),
              n, gap, yaml.c_str());
  std::printf("  mean matches per pair %.1f\n", static_cast<double>(matches) / n);
  std::printf("  %-34s %12s  %10s  %8s  %12s\n", "", "mean inliers", "vs raw", "verified", "ms / verify");
  auto row = [&](const char* name, const Acc& acc) {
    std::printf("  %-34s %12.1f  %9.3fx  %8d  %12.3f\n", name, static_cast<double>(acc.inliers) / n,
                static_cast<double>(acc.inliers) / static_cast<double>(raw.inliers), acc.verified, acc.ms / n);
  };
  row("raw pixels, F", raw);
  row("Calibrated<FundamentalEstimator>", cal);
  row("EssentialEstimator", ess);
  std::printf("  pairs where Calibrated F has more inliers than raw F: %d of %d\n", more_cal, n);
  return 0;
}
