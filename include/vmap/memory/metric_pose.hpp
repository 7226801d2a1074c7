#pragma once

// Where a query is, in metres (examples/memory.md, "Where am I, in metres"): the
// camera-to-world pose of an image that a memory's place decision put at key image K,
// when the memory's key images have SE(3) poses and its camera is known.
//
//  1. K's points: K's keypoints that the query's verified matches reach are matched (the
//     memory's own matcher) against the posed key images beside K in its session's chain,
//     and triangulated with the two poses (geometry/triangulation.hpp); a point is kept
//     when it lies in front of both, reprojects within the threshold in both and is seen
//     under enough parallax, the largest parallax of K's partners winning. Only the
//     points the query sees are triangulated, so the cost follows the query, not K.
//  2. 2D-3D: each of the query's verified matches to K (the F-matrix inliers of the
//     place decision) whose keypoint of K has a point.
//  3. The pose: robust PnP with USAC and Levenberg-Marquardt refinement, its covariance
//     from the refinement's Jacobian (geometry/pnp.hpp).
//  4. A pose only where the geometry holds, else none with the reason (PoseReason): no
//     posed key image beside K or no parallax between them (no baseline), too few
//     points, too few PnP inliers or too small a share of them, a rotation relative to K
//     that disagrees with the one the verified two-view geometry recovered (where that one
//     is determined), a covariance wider than the bounds.
//
// Sessions: K's partners are of its own session (each run's poses are in its own frame),
// so a fleet's robot or a session answers in the frame of the poses it was pushed with.
// Memory: nothing is kept between queries; per query, the matched subset of K and one
// partner's features at a time.

#include <vmap/core/concepts.hpp>
#include <vmap/core/error.hpp>
#include <vmap/core/features.hpp>
#include <vmap/core/verification.hpp>
#include <vmap/geometry/camera.hpp>
#include <vmap/geometry/metric_pose.hpp>
#include <vmap/geometry/pnp.hpp>
#include <vmap/geometry/triangulation.hpp>

#include <opencv2/core.hpp>
#include <opencv2/core/affine.hpp>

#include <algorithm>
#include <cmath>
#include <concepts>
#include <cstddef>
#include <cstdint>
#include <cstdio>
#include <optional>
#include <string>
#include <type_traits>
#include <vector>

namespace vmap {

/// When a query gets a metric pose (VisualMemory::set_pose_options). The defaults are
/// the ones measured in examples/results/localize.md ("Where am I, in metres").
struct MetricPoseOptions {
  /// Key images either side of K in its session's chain that triangulate K's points
  /// (those with an SE(3) pose): the farther ones see K's points under more parallax
  /// where the camera moves little between key images.
  std::size_t chain_reach = 4;
  /// min_parallax_deg 0.5: a query near K barely sees the depth error of a point of
  /// little parallax (the error moves the point along K's ray), and such points are most
  /// of what a camera that mostly turns has.
  TriangulationOptions triangulation{.max_reprojection_px = 2.0, .min_parallax_deg = 0.5};
  PnpOptions pnp{};
  int min_points = 12;               ///< 2D-3D correspondences the PnP needs
  int min_inliers = 12;              ///< PnP inliers a pose needs
  double min_inlier_ratio = 0.5;     ///< and their share of the correspondences
  /// The most the PnP's rotation relative to K may differ from the verified two-view
  /// geometry's (Verification::relative_pose), degrees: the bound of a gross error, since
  /// beyond it one of the two is grossly wrong. Not checked where a homography explains
  /// the verification's inliers (a plane, or a camera that only turned: the two-view
  /// rotation is then ill-determined).
  double max_rotation_disagreement_deg = 5.0;
  /// The widest standard deviation of the position (along its least certain direction,
  /// in the poses' units) and of the rotation (degrees) a pose may have.
  double max_position_sigma = 0.1;
  double max_rotation_sigma_deg = 1.0;
};

/// A posed key image beside K that triangulates its points: its features and pose.
struct PosedView {
  const Features* features = nullptr;
  cv::Affine3d camera_to_world = cv::Affine3d::Identity();
};

namespace detail {

inline void check_metric_pose_options(const MetricPoseOptions& o) {
  check_triangulation_options(o.triangulation);
  check_pnp_options(o.pnp);
  check(o.min_points >= 4, "MetricPoseOptions.min_points must be >= 4 (PnP's minimal sample is 3 points and a check)");
  check(o.min_inliers >= 4, "MetricPoseOptions.min_inliers must be >= 4");
  check(std::isfinite(o.min_inlier_ratio) && o.min_inlier_ratio >= 0 && o.min_inlier_ratio <= 1,
        "MetricPoseOptions.min_inlier_ratio must be in [0, 1]");
  check(std::isfinite(o.max_rotation_disagreement_deg) && o.max_rotation_disagreement_deg > 0,
        "MetricPoseOptions.max_rotation_disagreement_deg must be > 0");
  check(o.max_position_sigma > 0 && o.max_rotation_sigma_deg > 0,
        "MetricPoseOptions.max_position_sigma and max_rotation_sigma_deg must be > 0");
}

/// The camera of an estimator, when it has one: Calibrated's (optional), an
/// EssentialEstimator's, or the wrapped estimator's of a wrapper (XFeatRefined).
template <class E>
[[nodiscard]] const Camera* camera_of(const E& e) {
  if constexpr (requires { e.camera(); }) {
    using C = std::remove_cvref_t<decltype(e.camera())>;
    if constexpr (std::same_as<C, std::optional<Camera>>)
      return e.camera() ? &*e.camera() : nullptr;
    else if constexpr (std::same_as<C, Camera>)
      return &e.camera();
    else
      return nullptr;
  } else if constexpr (requires { e.estimator(); }) {
    return camera_of(e.estimator());
  } else {
    return nullptr;
  }
}

inline PoseAnswer no_pose(PoseReason code, std::string why) { return {std::nullopt, code, std::move(why)}; }

/// The keypoints of `f` at `indices`, with their descriptors: what K's partners are matched
/// against (the points the query sees).
inline Features feature_subset(const Features& f, const std::vector<int>& indices) {
  Features out;
  out.norm = f.norm;
  out.image_size = f.image_size;
  out.keypoints.reserve(indices.size());
  out.descriptors.create(static_cast<int>(indices.size()), f.descriptors.cols, f.descriptors.type());
  for (std::size_t i = 0; i < indices.size(); ++i) {
    out.keypoints.push_back(f.keypoints[static_cast<std::size_t>(indices[i])]);
    f.descriptors.row(indices[i]).copyTo(out.descriptors.row(static_cast<int>(i)));
  }
  return out;
}

inline std::vector<cv::Point2d> to_double(const std::vector<cv::Point2f>& p) {
  std::vector<cv::Point2d> out;
  out.reserve(p.size());
  for (const auto& q : p) out.emplace_back(q.x, q.y);
  return out;
}

}  // namespace detail

/// The pose of the camera that took `query` (its features), placed at key image `key`
/// (features `key_features`, pose `key_pose`) by the verified `matches` (queryIdx into
/// the query, trainIdx into the key image) and `verification` (its inlier_mask over
/// them, its relative_pose when the camera is calibrated), with the points the `partners`
/// triangulate with the key image. `matcher` is the memory's. Expected outcomes are
/// values (PoseAnswer's reason); only inconsistent arguments throw.
template <Matcher M>
[[nodiscard]] PoseAnswer place_query(const Features& query, const Matches& matches, const Verification& verification,
                                     std::uint32_t key, const Features& key_features, const cv::Affine3d& key_pose,
                                     const std::vector<PosedView>& partners, const M& matcher, const Camera& camera,
                                     const MetricPoseOptions& options) {
  detail::check_metric_pose_options(options);
  detail::check(verification.inlier_mask.size() == matches.size(),
                "place_query: the verification's inlier mask does not cover the matches");
  char buf[200];
  const std::string k = "key image " + std::to_string(key);
  if (partners.empty())
    return detail::no_pose(PoseReason::no_baseline, k + " has no posed key image beside it in its session's chain");

  // The key image's keypoints the query's verified matches reach, each once.
  std::vector<int> slot(key_features.keypoints.size(), -1);  // keypoint of K -> its index in `seen`
  std::vector<int> seen;
  for (std::size_t m = 0; m < matches.size(); ++m) {
    if (!verification.inlier_mask[m]) continue;
    const int t = matches[m].trainIdx, q = matches[m].queryIdx;
    detail::check(t >= 0 && static_cast<std::size_t>(t) < slot.size() && q >= 0 &&
                      static_cast<std::size_t>(q) < query.keypoints.size(),
                  "place_query: a match indexes no keypoint");
    if (slot[static_cast<std::size_t>(t)] < 0) {
      slot[static_cast<std::size_t>(t)] = static_cast<int>(seen.size());
      seen.push_back(t);
    }
  }
  const Features subset = detail::feature_subset(key_features, seen);

  // Step 1: their points, the largest parallax of the partners winning. The partners
  // farthest from K come first, and a correspondence is triangulated only when its
  // parallax (known before the point) beats the point its keypoint has: the result is
  // that of triangulating every one, for the cost of a few.
  std::vector<const PosedView*> order;
  for (const PosedView& p : partners) order.push_back(&p);
  const cv::Vec3d centre = key_pose.translation();
  std::stable_sort(order.begin(), order.end(), [&](const PosedView* x, const PosedView* y) {
    return cv::norm(x->camera_to_world.translation() - centre) > cv::norm(y->camera_to_world.translation() - centre);
  });
  std::vector<TriangulatedPoint> best(seen.size());  // low_parallax, parallax 0: nothing yet
  std::vector<std::uint8_t> matched(seen.size(), 0);
  const double focal = camera.focal();
  for (const PosedView* p : order) {
    const Matches pm = matcher.match(subset, *p->features);
    if (pm.empty()) continue;
    std::vector<cv::Point2f> a, b;
    a.reserve(pm.size());
    b.reserve(pm.size());
    for (const cv::DMatch& d : pm) {
      a.push_back(subset.keypoints[static_cast<std::size_t>(d.queryIdx)].pt);
      b.push_back(p->features->keypoints[static_cast<std::size_t>(d.trainIdx)].pt);
    }
    const std::vector<cv::Point2d> na = detail::to_double(normalize_points(camera, a));
    const std::vector<cv::Point2d> nb = detail::to_double(normalize_points(camera, b));
    std::vector<std::size_t> at;  // pm's entries to triangulate
    std::vector<cv::Point2d> fa, fb;
    for (std::size_t i = 0; i < pm.size(); ++i) {
      if (!std::isfinite(na[i].x) || !std::isfinite(na[i].y) || !std::isfinite(nb[i].x) || !std::isfinite(nb[i].y))
        continue;  // beyond the lens model's field of view
      const auto s = static_cast<std::size_t>(pm[i].queryIdx);
      matched[s] = 1;
      const double parallax = parallax_deg(key_pose, na[i], p->camera_to_world, nb[i]);
      TriangulatedPoint& b0 = best[s];
      if (b0.status == PointStatus::triangulated ? parallax <= b0.parallax_deg
                                                 : parallax < options.triangulation.min_parallax_deg) {
        if (b0.status != PointStatus::triangulated) b0.parallax_deg = std::max(b0.parallax_deg, parallax);
        continue;
      }
      at.push_back(i);
      fa.push_back(na[i]);
      fb.push_back(nb[i]);
    }
    const std::vector<TriangulatedPoint> t =
        triangulate_posed(key_pose, fa, p->camera_to_world, fb, focal, options.triangulation);
    for (std::size_t i = 0; i < t.size(); ++i) {
      // A triangulated point beats the one before (its parallax is larger); a point that
      // failed with enough parallax (behind, off the rays: a wrong match) says more than
      // none with too little.
      TriangulatedPoint& b0 = best[static_cast<std::size_t>(pm[at[i]].queryIdx)];
      if (t[i].status == PointStatus::triangulated || b0.status == PointStatus::low_parallax) b0 = t[i];
    }
  }

  // Step 2: the 2D-3D correspondences.
  std::vector<cv::Point3d> world;
  std::vector<cv::Point2f> raw;
  int low_parallax = 0, other = 0;
  for (std::size_t m = 0; m < matches.size(); ++m) {
    if (!verification.inlier_mask[m]) continue;
    const auto s = static_cast<std::size_t>(slot[static_cast<std::size_t>(matches[m].trainIdx)]);
    if (!matched[s]) continue;
    if (best[s].status == PointStatus::triangulated) {
      world.push_back(best[s].world);
      raw.push_back(query.keypoints[static_cast<std::size_t>(matches[m].queryIdx)].pt);
    } else if (best[s].status == PointStatus::low_parallax) {
      ++low_parallax;
    } else {
      ++other;
    }
  }
  const std::vector<cv::Point2f> ideal = undistort_points(camera, raw);
  std::vector<cv::Point3d> w;
  std::vector<cv::Point2d> x;
  for (std::size_t i = 0; i < ideal.size(); ++i)
    if (std::isfinite(ideal[i].x) && std::isfinite(ideal[i].y)) {
      w.push_back(world[i]);
      x.emplace_back(ideal[i].x, ideal[i].y);
    }
  const int points = static_cast<int>(w.size());
  if (points < options.min_points) {
    // Most of the points refused for parallax: the key images saw them from (nearly) one
    // spot, the camera turned there. Otherwise the matches themselves were too few.
    const bool baseline = low_parallax > points + other;
    std::snprintf(buf, sizeof buf, "%s: %d of the query's %d verified matches reach a 3D point (%d needed); %d refused for parallax below %.1f deg",
                  k.c_str(), points, verification.inliers, options.min_points, low_parallax,
                  options.triangulation.min_parallax_deg);
    return detail::no_pose(baseline ? PoseReason::no_baseline : PoseReason::too_few_points, buf);
  }

  // Step 3: PnP.
  const PnpResult r = solve_pnp(w, x, camera.K(), options.pnp);
  const double need = std::max<double>(options.min_inliers, options.min_inlier_ratio * points);
  if (!r.found || r.inliers < need) {
    std::snprintf(buf, sizeof buf, "%s: PnP found %d inliers of %d points (%.0f needed)", k.c_str(),
                  r.found ? r.inliers : 0, points, std::ceil(need));
    return detail::no_pose(PoseReason::few_inliers, buf);
  }
  MetricPose pose;
  pose.camera_to_world = r.camera_to_world;
  pose.covariance = r.covariance;
  pose.key = key;
  pose.points = points;
  pose.inliers = r.inliers;
  pose.reprojection_px = r.rms_px;

  // Step 4: the checks. X_key = R X_query + t, as Verification::relative_pose states it.
  if (verification.relative_pose) {
    const cv::Matx33d pnp = key_pose.rotation().t() * pose.rotation();
    pose.rotation_disagreement_deg = rotation_angle_deg(pnp.t() * verification.relative_pose->rotation);
    if (verification.degeneracy == Degeneracy::none &&
        *pose.rotation_disagreement_deg > options.max_rotation_disagreement_deg) {
      std::snprintf(buf, sizeof buf, "%s: the PnP's rotation differs from the verified relative rotation by %.1f deg (> %.1f)",
                    k.c_str(), *pose.rotation_disagreement_deg, options.max_rotation_disagreement_deg);
      return detail::no_pose(PoseReason::rotation_disagrees, buf);
    }
  }
  const double ps = pose.position_sigma_max(), rs = pose.rotation_sigma_deg();
  if (!(ps <= options.max_position_sigma) || !(rs <= options.max_rotation_sigma_deg)) {
    std::snprintf(buf, sizeof buf, "%s: sigma %.3g in position (max %.3g), %.2f deg in rotation (max %.2f)", k.c_str(),
                  ps, options.max_position_sigma, rs, options.max_rotation_sigma_deg);
    return detail::no_pose(PoseReason::uncertain, buf);
  }
  std::snprintf(buf, sizeof buf, "%s: %d of %d points, %.2f px", k.c_str(), pose.inliers, points, pose.reprojection_px);
  return {pose, PoseReason::posed, buf};
}

}  // namespace vmap
