// Camera models on real images: tum_fr1_rpy with TUM's published fr1 calibration
// (examples/data/tum_fr1_camera.yaml), the relative rotation of E checked against the
// ground truth associated by timestamp.
#include <vmap/features/orb.hpp>
#include <vmap/geometry/calibrated.hpp>
#include <vmap/geometry/essential.hpp>
#include <vmap/io/calibration.hpp>
#include <vmap/io/frame_source.hpp>
#include <vmap/io/poses.hpp>
#include <vmap/matching/brute_force.hpp>

#include "support/lens_scene.hpp"
#include "support/shared_data.hpp"

#include <doctest/doctest.h>

#include <algorithm>
#include <vector>

TEST_SUITE("data") {
  TEST_CASE("tum_fr1_rpy pairs (i, i+5): calibrated F keeps its inliers, E's rotation matches the ground truth") {
    const auto cam = vmap::read_camera(vmap::test::source_dir() / "examples/data/tum_fr1_camera.yaml");
    const auto list = vmap::test::data_path("tum_fr1_rpy/rgb.txt");
    const auto gt = vmap::load_tum_poses(vmap::test::data_path("tum_fr1_rpy/groundtruth.txt"));
    constexpr int pairs = 20, gap = 5;
    auto src = vmap::FrameSource::open(list, {.end = pairs + gap, .grey = true});
    const std::vector<double> all_times = src.timestamps();  // the whole list, before start/end
    const std::vector<double> times(all_times.begin(), all_times.begin() + pairs + gap);
    const auto truth = vmap::poses_for_frames(gt, times, "groundtruth.txt", 0.02, false);
    vmap::OrbDescriptor orb({.features = 1000});
    std::vector<vmap::Features> feats;
    while (auto f = src.next()) feats.push_back(orb.extract(f->image));
    REQUIRE(feats.size() == pairs + gap);
    const vmap::BruteForceMatcher matcher;
    const vmap::FundamentalEstimator f({.check_degeneracy = false});
    const vmap::Calibrated<vmap::FundamentalEstimator> cf(cam, f);
    const vmap::EssentialEstimator ee(cam);
    long raw = 0, cal = 0;
    std::vector<double> errors, confident;  // rotation errors of E, degrees
    for (int i = 0; i < pairs; ++i) {
      const auto& a = feats[static_cast<std::size_t>(i)];
      const auto& b = feats[static_cast<std::size_t>(i + gap)];
      const auto m = matcher.match(a, b);
      const auto vr = f.verify(a, b, m);
      const auto vc = cf.verify(a, b, m);
      REQUIRE(vr.ok());
      REQUIRE(vc.ok());
      raw += vr.inliers;
      cal += vc.inliers;
      const auto ve = ee.verify(a, b, m);
      REQUIRE(ve.ok());
      REQUIRE(ve.relative_pose.has_value());
      // Ground truth: camera-to-world rotations, so x_b = R_b^T R_a x_a + ...
      const cv::Matx33d R_true =
          truth[static_cast<std::size_t>(i + gap)].rotation.t() * truth[static_cast<std::size_t>(i)].rotation;
      const double err = vmap::test::rotation_error_deg(ve.relative_pose->rotation, R_true);
      errors.push_back(err);
      if (2 * ve.relative_pose->points_in_front >= ve.inliers) confident.push_back(err);
    }
    // Measured (20 pairs): raw F 5722 inliers, calibrated F 5736; E's rotation error has
    // a median of 0.9 deg against the ~10 deg true rotations. fr1_rpy barely translates
    // (1.5 cm over 5 frames): with so little parallax the cheirality test of
    // recoverPose is weak (half the pairs have 0-6 of 100-480 inliers in front) and one
    // pair takes the twisted solution (180 deg). Pairs whose inliers are mostly in front
    // (5 of 20) are within 3.4 deg.
    CHECK(cal >= 0.99 * static_cast<double>(raw));
    std::sort(errors.begin(), errors.end());
    CHECK(errors[errors.size() / 2] < 1.5);
    CHECK(confident.size() >= 4);
    for (double e : confident) CHECK(e < 5.0);
  }
}
