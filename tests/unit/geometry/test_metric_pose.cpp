// The metric pose on synthetic scenes with known poses: triangulation from two posed
// views and PnP recover the points and the pose exactly where the data are exact; a
// camera turning on the spot gives no baseline, too few points and an outlier-heavy match
// set give no pose (memory/metric_pose.hpp's reasons), and the covariance is what the
// noise makes it.
#include <vmap/geometry/metric_pose.hpp>
#include <vmap/geometry/pnp.hpp>
#include <vmap/geometry/triangulation.hpp>
#include <vmap/matching/brute_force.hpp>
#include <vmap/memory/metric_pose.hpp>

#include <doctest/doctest.h>

#include <opencv2/core/affine.hpp>

#include <cmath>
#include <cstdint>
#include <random>
#include <vector>

namespace {

const cv::Matx33d pose_K(500, 0, 320, 0, 500, 240, 0, 0, 1);

vmap::Camera pose_camera() {
  vmap::Camera c;
  c.fx = c.fy = 500;
  c.cx = 320;
  c.cy = 240;
  c.image_size = {640, 480};
  return c;
}

/// Points in a box 4-8 m in front of the origin's camera, each with a descriptor of its own.
struct PoseScene {
  std::vector<cv::Point3d> points;
  cv::Mat descriptors;  // one 32-byte row per point
};

PoseScene pose_scene(int n, std::uint32_t seed) {
  std::mt19937 rng(seed);
  std::uniform_real_distribution<double> u(-2.5, 2.5), z(4.0, 8.0);
  PoseScene s;
  cv::RNG r(seed);
  s.descriptors.create(n, 32, CV_8U);
  r.fill(s.descriptors, cv::RNG::UNIFORM, 0, 256);
  for (int i = 0; i < n; ++i) s.points.emplace_back(u(rng), 0.6 * u(rng), z(rng));
  return s;
}

cv::Point2d pixel_of(const cv::Affine3d& camera_to_world, const cv::Point3d& p) {
  const cv::Vec3d c = camera_to_world.inv() * cv::Vec3d(p.x, p.y, p.z);
  return {500 * c[0] / c[2] + 320, 500 * c[1] / c[2] + 240};
}

/// The features a camera at `pose` sees: every point inside the image, its descriptor;
/// `ids[i]` is the point of keypoint i.
struct View {
  vmap::Features features;
  std::vector<int> ids;
};

View view_of(const PoseScene& s, const cv::Affine3d& pose, double noise_px = 0.0, std::uint32_t seed = 0) {
  std::mt19937 rng(seed);
  std::normal_distribution<double> n(0.0, noise_px > 0 ? noise_px : 1.0);
  View v;
  v.features.image_size = {640, 480};
  for (int i = 0; i < static_cast<int>(s.points.size()); ++i) {
    cv::Point2d p = pixel_of(pose, s.points[static_cast<std::size_t>(i)]);
    if (noise_px > 0) p += cv::Point2d(n(rng), n(rng));
    if (p.x < 0 || p.y < 0 || p.x >= 640 || p.y >= 480) continue;
    v.features.keypoints.emplace_back(cv::Point2f(static_cast<float>(p.x), static_cast<float>(p.y)), 31.f);
    v.features.descriptors.push_back(s.descriptors.row(i));
    v.ids.push_back(i);
  }
  return v;
}

/// The query's matches to the key image (by point), every one verified, and the
/// relative pose two-view geometry would recover (X_key = R X_query + t).
struct Verified {
  vmap::Matches matches;
  vmap::Verification verification;
};

Verified verified(const View& query, const View& key, const cv::Affine3d& query_pose, const cv::Affine3d& key_pose) {
  Verified out;
  for (std::size_t i = 0; i < query.ids.size(); ++i)
    for (std::size_t j = 0; j < key.ids.size(); ++j)
      if (query.ids[i] == key.ids[j]) out.matches.emplace_back(static_cast<int>(i), static_cast<int>(j), 0.f);
  out.verification.status = vmap::VerificationStatus::verified;
  out.verification.matches = static_cast<int>(out.matches.size());
  out.verification.inliers = out.verification.matches;
  out.verification.inlier_mask.assign(out.matches.size(), 1);
  const cv::Affine3d rel = key_pose.inv() * query_pose;
  out.verification.relative_pose = vmap::RelativePose{rel.rotation(), cv::normalize(rel.translation()), 10};
  return out;
}

double position_error(const cv::Affine3d& a, const cv::Affine3d& b) { return cv::norm(a.translation() - b.translation()); }
double rotation_error(const cv::Affine3d& a, const cv::Affine3d& b) {
  return vmap::rotation_angle_deg(a.rotation().t() * b.rotation());
}

const cv::Affine3d key_pose = cv::Affine3d::Identity();
const cv::Affine3d left_pose(cv::Vec3d(0.0, 0.03, 0.0), cv::Vec3d(-0.4, 0.0, 0.05));
const cv::Affine3d right_pose(cv::Vec3d(0.01, -0.02, 0.0), cv::Vec3d(0.45, 0.02, -0.05));
const cv::Affine3d query_pose(cv::Vec3d(-0.02, 0.05, 0.01), cv::Vec3d(0.2, -0.05, 0.3));

}  // namespace

TEST_CASE("triangulate_posed: exact points from two posed views; no parallax, a wrong match, a point behind") {
  const PoseScene s = pose_scene(100, 1);
  std::vector<cv::Point2d> a, b;
  const auto normalised = [](const cv::Affine3d& pose, const cv::Point3d& p) {
    const cv::Vec3d c = pose.inv() * cv::Vec3d(p.x, p.y, p.z);
    return cv::Point2d(c[0] / c[2], c[1] / c[2]);
  };
  for (const auto& p : s.points) {
    a.push_back(normalised(key_pose, p));
    b.push_back(normalised(right_pose, p));
  }
  auto t = vmap::triangulate_posed(key_pose, a, right_pose, b, 500.0);
  REQUIRE(t.size() == s.points.size());
  for (std::size_t i = 0; i < t.size(); ++i) {
    REQUIRE(t[i].status == vmap::PointStatus::triangulated);
    CHECK(cv::norm(t[i].world - s.points[i]) < 1e-9);
    CHECK(t[i].error_px < 1e-6);
    CHECK(t[i].parallax_deg > 1.0);
  }
  // A camera that only turned: every ray pair is parallel, no depth.
  const cv::Affine3d turned(cv::Vec3d(0.0, 0.2, 0.05), cv::Vec3d(0, 0, 0));
  std::vector<cv::Point2d> c;
  for (const auto& p : s.points) c.push_back(normalised(turned, p));
  for (const auto& r : vmap::triangulate_posed(key_pose, a, turned, c, 500.0)) {
    CHECK(r.status == vmap::PointStatus::low_parallax);
    CHECK(r.parallax_deg < 1e-5);  // an arccos near 1 resolves no finer than 1.2e-6 degrees
  }
  // A wrong match: the rays miss each other.
  std::vector<cv::Point2d> wrong = b;
  std::swap(wrong[0], wrong[1]);
  t = vmap::triangulate_posed(key_pose, a, right_pose, wrong, 500.0);
  CHECK((t[0].status == vmap::PointStatus::off_the_rays || t[0].status == vmap::PointStatus::behind));
  // A point behind both cameras (its rays meet behind them).
  const cv::Point3d behind(0.5, 0.2, -5.0);
  const cv::Vec3d ka = key_pose.inv() * cv::Vec3d(behind.x, behind.y, behind.z);
  const cv::Vec3d kb = right_pose.inv() * cv::Vec3d(behind.x, behind.y, behind.z);
  t = vmap::triangulate_posed(key_pose, {{ka[0] / ka[2], ka[1] / ka[2]}}, right_pose, {{kb[0] / kb[2], kb[1] / kb[2]}},
                              500.0);
  CHECK(t[0].status == vmap::PointStatus::behind);
}

TEST_CASE("solve_pnp: the exact pose from exact points, and through 60 % outliers") {
  const PoseScene s = pose_scene(150, 2);
  std::vector<cv::Point2d> px;
  for (const auto& p : s.points) px.push_back(pixel_of(query_pose, p));
  vmap::PnpResult r = vmap::solve_pnp(s.points, px, pose_K);
  REQUIRE(r.found);
  CHECK(r.inliers == 150);
  // Exact up to where solvePnPRefineLM stops (its default: a step below FLT_EPSILON, about
  // 1e-7 relative), and an arccos near 1 (rotation_angle_deg) resolves 1.2e-6 degrees.
  CHECK(position_error(r.camera_to_world, query_pose) < 1e-6);
  CHECK(rotation_error(r.camera_to_world, query_pose) < 1e-5);
  CHECK(r.rms_px < 1e-4);
  // 90 of the 150 pixels replaced by random ones: the 60 true correspondences are found.
  std::mt19937 rng(3);
  std::uniform_real_distribution<double> x(0, 640), y(0, 480);
  for (std::size_t i = 0; i < 90; ++i) px[i] = {x(rng), y(rng)};
  r = vmap::solve_pnp(s.points, px, pose_K);
  REQUIRE(r.found);
  CHECK(r.inliers >= 60);
  CHECK(r.inliers <= 62);  // a random pixel may land within 2 px of its point's projection
  for (std::size_t i = 90; i < 150; ++i) CHECK(r.inlier_mask[i] == 1);
  CHECK(position_error(r.camera_to_world, query_pose) < 1e-6);
  // Fewer than 4 points: no pose.
  CHECK_FALSE(vmap::solve_pnp({s.points.begin(), s.points.begin() + 3}, {px.begin() + 90, px.begin() + 93}, pose_K).found);
}

TEST_CASE("solve_pnp: the covariance follows the noise (1 px: about 1 sigma per coordinate over many trials)") {
  // Position error against its covariance: the mean Mahalanobis distance squared of a
  // 3-D Gaussian is 3.
  std::mt19937 rng(4);
  std::normal_distribution<double> n(0.0, 1.0);
  double chi2 = 0.0;
  const int trials = 60;
  for (int k = 0; k < trials; ++k) {
    const PoseScene s = pose_scene(100, 10 + static_cast<std::uint32_t>(k));
    std::vector<cv::Point2d> px;
    for (const auto& p : s.points) px.push_back(pixel_of(query_pose, p) + cv::Point2d(n(rng), n(rng)));
    const vmap::PnpResult r = vmap::solve_pnp(s.points, px, pose_K, {.threshold_px = 4.0});
    REQUIRE(r.found);
    const cv::Vec3d d = r.camera_to_world.translation() - query_pose.translation();
    cv::Matx33d c;
    for (int i = 0; i < 3; ++i)
      for (int j = 0; j < 3; ++j) c(i, j) = r.covariance(i, j);
    chi2 += (d.t() * c.inv() * d)(0);
  }
  CHECK(chi2 / trials == doctest::Approx(3.0).epsilon(0.35));
}

TEST_CASE("place_query: the query's pose from the key image's points, exact on exact data") {
  const PoseScene s = pose_scene(300, 5);
  const View key = view_of(s, key_pose), left = view_of(s, left_pose), right = view_of(s, right_pose);
  const View query = view_of(s, query_pose);
  const Verified v = verified(query, key, query_pose, key_pose);
  const vmap::BruteForceMatcher matcher;
  const vmap::PoseAnswer a = vmap::place_query(query.features, v.matches, v.verification, 7, key.features, key_pose,
                                               {{&left.features, left_pose}, {&right.features, right_pose}}, matcher,
                                               pose_camera(), {});
  INFO(a.reason);
  REQUIRE(a.pose);
  CHECK(a.reason_code == vmap::PoseReason::posed);
  CHECK(a.pose->key == 7);
  CHECK(a.pose->points == static_cast<int>(v.matches.size()));
  CHECK(a.pose->inliers == a.pose->points);
  // Exact up to the LM's stop and the arccos's resolution (as solve_pnp's test says).
  CHECK(position_error(a.pose->camera_to_world, query_pose) < 1e-6);
  CHECK(rotation_error(a.pose->camera_to_world, query_pose) < 1e-5);
  REQUIRE(a.pose->rotation_disagreement_deg);
  CHECK(*a.pose->rotation_disagreement_deg < 1e-5);
}

TEST_CASE("place_query: 1 px noise gives centimetres, within the covariance's sigma") {
  const PoseScene s = pose_scene(300, 6);
  const View key = view_of(s, key_pose, 1.0, 1), left = view_of(s, left_pose, 1.0, 2), right = view_of(s, right_pose, 1.0, 3);
  const View query = view_of(s, query_pose, 1.0, 4);
  const Verified v = verified(query, key, query_pose, key_pose);
  const vmap::PoseAnswer a = vmap::place_query(query.features, v.matches, v.verification, 0, key.features, key_pose,
                                               {{&left.features, left_pose}, {&right.features, right_pose}},
                                               vmap::BruteForceMatcher{}, pose_camera(), {});
  INFO(a.reason);
  REQUIRE(a.pose);
  CHECK(position_error(a.pose->camera_to_world, query_pose) < 0.05);
  CHECK(rotation_error(a.pose->camera_to_world, query_pose) < 0.5);
  CHECK(a.pose->reprojection_px < 2.0);
  CHECK(a.pose->position_sigma_max() > 0.0);
  CHECK(a.pose->position_sigma_max() < 0.05);
}

TEST_CASE("place_query: a camera turning on the spot has no baseline: no pose, and the reason") {
  const PoseScene s = pose_scene(300, 7);
  const cv::Affine3d turned_left(cv::Vec3d(0.0, 0.08, 0.0), cv::Vec3d(0, 0, 0));
  const cv::Affine3d turned_right(cv::Vec3d(0.0, -0.08, 0.02), cv::Vec3d(0, 0, 0));
  const View key = view_of(s, key_pose), left = view_of(s, turned_left), right = view_of(s, turned_right);
  const View query = view_of(s, query_pose);
  const Verified v = verified(query, key, query_pose, key_pose);
  const vmap::PoseAnswer a = vmap::place_query(query.features, v.matches, v.verification, 3, key.features, key_pose,
                                               {{&left.features, turned_left}, {&right.features, turned_right}},
                                               vmap::BruteForceMatcher{}, pose_camera(), {});
  CHECK_FALSE(a.pose);
  CHECK(a.reason_code == vmap::PoseReason::no_baseline);
  CHECK(a.reason.find("parallax") != std::string::npos);
  // No posed key image beside it at all: no baseline either.
  const vmap::PoseAnswer none = vmap::place_query(query.features, v.matches, v.verification, 3, key.features, key_pose,
                                                  {}, vmap::BruteForceMatcher{}, pose_camera(), {});
  CHECK_FALSE(none.pose);
  CHECK(none.reason_code == vmap::PoseReason::no_baseline);
}

TEST_CASE("place_query: too few points, an outlier-heavy match set, a disagreeing rotation: no pose") {
  const PoseScene s = pose_scene(300, 8);
  const View key = view_of(s, key_pose), left = view_of(s, left_pose), right = view_of(s, right_pose);
  const View query = view_of(s, query_pose);
  const std::vector<vmap::PosedView> partners{{&left.features, left_pose}, {&right.features, right_pose}};
  const vmap::Camera camera = pose_camera();
  SUBCASE("too few points") {
    Verified v = verified(query, key, query_pose, key_pose);
    v.matches.resize(8);
    v.verification.inlier_mask.resize(8);
    v.verification.inliers = 8;
    const vmap::PoseAnswer a = vmap::place_query(query.features, v.matches, v.verification, 0, key.features, key_pose,
                                                 partners, vmap::BruteForceMatcher{}, camera, {});
    CHECK_FALSE(a.pose);
    CHECK(a.reason_code == vmap::PoseReason::too_few_points);
    CHECK(a.reason.find("8 of the query's 8 verified matches reach a 3D point (12 needed)") != std::string::npos);
  }
  SUBCASE("outlier-heavy: 60 % of the verified matches point at other keypoints") {
    Verified v = verified(query, key, query_pose, key_pose);
    const int n = static_cast<int>(key.ids.size());
    for (std::size_t i = 0; i < v.matches.size(); ++i)
      if (i % 5 < 3) v.matches[i].trainIdx = static_cast<int>((static_cast<int>(i) * 37 + 11) % n);
    // Keep each keypoint of the key image once, as a mutual matcher does.
    std::vector<char> used(static_cast<std::size_t>(n), 0);
    vmap::Matches kept;
    for (const auto& m : v.matches)
      if (!used[static_cast<std::size_t>(m.trainIdx)]) {
        used[static_cast<std::size_t>(m.trainIdx)] = 1;
        kept.push_back(m);
      }
    v.matches = kept;
    v.verification.inlier_mask.assign(kept.size(), 1);
    v.verification.inliers = static_cast<int>(kept.size());
    const vmap::PoseAnswer a = vmap::place_query(query.features, v.matches, v.verification, 0, key.features, key_pose,
                                                 partners, vmap::BruteForceMatcher{}, camera, {});
    CHECK_FALSE(a.pose);
    CHECK(a.reason_code == vmap::PoseReason::few_inliers);
    // With the share of inliers not asked for, the PnP finds the right pose among them.
    vmap::MetricPoseOptions o;
    o.min_inlier_ratio = 0.0;
    const vmap::PoseAnswer b = vmap::place_query(query.features, v.matches, v.verification, 0, key.features, key_pose,
                                                 partners, vmap::BruteForceMatcher{}, camera, o);
    REQUIRE(b.pose);
    CHECK(position_error(b.pose->camera_to_world, query_pose) < 1e-6);
    CHECK(b.pose->inliers < b.pose->points / 2);
  }
  SUBCASE("a rotation that disagrees with the verified relative rotation") {
    Verified v = verified(query, key, query_pose, key_pose);
    v.verification.relative_pose->rotation =
        cv::Affine3d(cv::Vec3d(0.0, 10.0 * CV_PI / 180.0, 0.0), cv::Vec3d()).rotation() * v.verification.relative_pose->rotation;
    const vmap::PoseAnswer a = vmap::place_query(query.features, v.matches, v.verification, 0, key.features, key_pose,
                                                 partners, vmap::BruteForceMatcher{}, camera, {});
    CHECK_FALSE(a.pose);
    CHECK(a.reason_code == vmap::PoseReason::rotation_disagrees);
    CHECK(a.reason.find("10.0 deg") != std::string::npos);
  }
  SUBCASE("a covariance wider than the bound") {
    const Verified v = verified(query, key, query_pose, key_pose);
    vmap::MetricPoseOptions o;
    o.max_position_sigma = 1e-12;  // exact data still leave a rounding residual above this
    const View noisy = view_of(s, query_pose, 0.5, 9);
    const vmap::PoseAnswer a = vmap::place_query(noisy.features, v.matches, v.verification, 0, key.features, key_pose,
                                                 partners, vmap::BruteForceMatcher{}, camera, o);
    CHECK_FALSE(a.pose);
    CHECK(a.reason_code == vmap::PoseReason::uncertain);
  }
}

TEST_CASE("MetricPoseOptions: invalid values are an Error") {
  vmap::MetricPoseOptions o;
  o.min_points = 3;
  CHECK_THROWS_AS(vmap::detail::check_metric_pose_options(o), vmap::Error);
  o = {};
  o.triangulation.min_parallax_deg = -1;
  CHECK_THROWS_AS(vmap::detail::check_metric_pose_options(o), vmap::Error);
  o = {};
  o.pnp.threshold_px = 0;
  CHECK_THROWS_AS(vmap::detail::check_metric_pose_options(o), vmap::Error);
}
