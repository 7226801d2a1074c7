// Camera models on synthetic two-view scenes seen through strong lenses: with the camera
// given, the F- and E-matrix estimates recover the true relative pose and keep as many
// inliers as an ideal pinhole would; without it, the fisheye scene loses inliers.
#include <vmap/geometry/calibrated.hpp>
#include <vmap/geometry/camera.hpp>
#include <vmap/geometry/essential.hpp>
#include <vmap/geometry/fundamental.hpp>

#include "support/errors.hpp"
#include "support/lens_scene.hpp"

#include <doctest/doctest.h>

#include <string>
#include <vector>

// Every member of the shipped adapter stacks compiles (Sophus' practice).
template class vmap::Calibrated<vmap::FundamentalEstimator>;
template class vmap::Calibrated<vmap::HomographyEstimator>;
template class vmap::Calibrated<vmap::EssentialEstimator>;
static_assert(vmap::Estimator<vmap::EssentialEstimator>);
static_assert(vmap::Estimator<vmap::Calibrated<vmap::FundamentalEstimator>>);
static_assert(vmap::Estimator<vmap::Calibrated<vmap::EssentialEstimator>>);

namespace {

using vmap::test::LensScene;

/// Correct inliers (true inliers marked inlier) and wrong ones.
struct Tally {
  int correct = 0;
  int wrong = 0;
};

Tally tally(const LensScene& s, const vmap::Verification& v) {
  Tally t;
  REQUIRE(v.inlier_mask.size() == s.matches.size());
  for (std::size_t k = 0; k < s.matches.size(); ++k)
    if (v.inlier_mask[k]) (s.is_inlier[k] ? t.correct : t.wrong) += 1;
  return t;
}

/// The relative pose implied by F on ideal pixels (E = K^T F K), through recoverPose on
/// the inliers' normalised points.
vmap::RelativePose pose_from_f(const LensScene& s, const vmap::Camera& cam, const vmap::Verification& v, bool ideal_points) {
  std::vector<cv::Point2f> pa, pb;
  for (std::size_t k = 0; k < s.matches.size(); ++k)
    if (v.inlier_mask[k]) {
      pa.push_back(s.a.keypoints[k].pt);
      pb.push_back(s.b.keypoints[k].pt);
    }
  vmap::Camera pin = cam;
  if (ideal_points) pin.distortion.clear(), pin.lens = vmap::LensModel::pinhole;
  const auto na = vmap::normalize_points(pin, pa);
  const auto nb = vmap::normalize_points(pin, pb);
  const cv::Matx33d E = cam.K().t() * v.model * cam.K();
  cv::Mat R, t;
  cv::recoverPose(cv::Mat(E), na, nb, cv::Mat::eye(3, 3, CV_64F), R, t);
  vmap::RelativePose p;
  for (int r = 0; r < 3; ++r) {
    for (int c = 0; c < 3; ++c) p.rotation(r, c) = R.at<double>(r, c);
    p.translation[r] = t.at<double>(r, 0);
  }
  return p;
}

struct Run {
  int inliers = 0;
  Tally t;
  double rot = 0, dir = 0;
};

Run run_f(const LensScene& s, const vmap::Camera& cam, bool with_camera, bool ideal_points) {
  const vmap::FundamentalEstimator f({.check_degeneracy = false});
  const vmap::Calibrated<vmap::FundamentalEstimator> cf(with_camera ? std::optional(cam) : std::nullopt, f);
  const auto v = cf.verify(s.a, s.b, s.matches);
  Run r;
  REQUIRE(v.ok());
  r.inliers = v.inliers;
  r.t = tally(s, v);
  if (with_camera || ideal_points) {
    const auto p = pose_from_f(s, cam, v, ideal_points);
    r.rot = vmap::test::rotation_error_deg(p.rotation, s.R);
    r.dir = vmap::test::direction_error_deg(p.translation, s.t);
  }
  return r;
}

}  // namespace

TEST_CASE("measure") {
  for (const auto& cam : {vmap::test::wide_fisheye_camera(), vmap::test::wide_radtan_camera()}) {
    for (std::uint64_t seed : {1, 2, 3}) {
      const vmap::test::LensSceneOptions o{.seed = seed};
      const auto real = vmap::test::make_lens_scene(cam, o);
      const auto ideal = vmap::test::make_lens_scene(cam, o, true);
      const Run pin = run_f(ideal, cam, false, true);
      const Run cal = run_f(real, cam, true, false);
      const Run raw = run_f(real, cam, false, false);
      const vmap::EssentialEstimator ee(cam);
      const auto ve = ee.verify(real.a, real.b, real.matches);
      MESSAGE(std::string(vmap::to_string(cam.lens)) << " seed " << seed << " true " << real.true_inliers << " matches "
              << real.matches.size() << " | pinhole " << pin.inliers << " (" << pin.t.correct << "/" << pin.t.wrong
              << ") rot " << pin.rot << " dir " << pin.dir << " | calibrated " << cal.inliers << " (" << cal.t.correct
              << "/" << cal.t.wrong << ") rot " << cal.rot << " dir " << cal.dir << " | raw " << raw.inliers << " ("
              << raw.t.correct << "/" << raw.t.wrong << ") | E " << ve.inliers << " "
              << (ve.relative_pose ? vmap::test::rotation_error_deg(ve.relative_pose->rotation, real.R) : -1) << " "
              << (ve.relative_pose ? vmap::test::direction_error_deg(ve.relative_pose->translation, real.t) : -1));
    }
  }
}
