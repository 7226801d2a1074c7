#pragma once

#include <vmap/core/concepts.hpp>
#include <vmap/core/error.hpp>
#include <vmap/geometry/detail/robust.hpp>
#include <vmap/geometry/fundamental.hpp>

#include <opencv2/calib3d.hpp>
#include <opencv2/core.hpp>

#include <string>
#include <vector>

namespace vmap {

struct HomographyOptions {
  RobustMethod method = RobustMethod::magsac;  ///< eight_point is not a homography method
  double threshold_px = 3.0;                   ///< max. transfer error, pixels
  double confidence = 0.995;
  int max_iterations = 2000;
  int min_inliers = 8;
  std::uint64_t seed = 0;
};

/// Homography verification (x_b ~ H x_a): the right model for planar scenes and a
/// rotating camera, where the fundamental matrix is not determined.
class HomographyEstimator {
 public:
  static constexpr int minimal_matches = 4;

  explicit HomographyEstimator(const HomographyOptions& options = {}) : options_(options) {
    detail::check_threshold_options(options_.threshold_px, options_.confidence, options_.max_iterations,
                                    options_.min_inliers, "HomographyOptions");
    detail::check(options_.method != RobustMethod::eight_point,
                  "HomographyOptions.method: eight_point is a fundamental-matrix method; use magsac, ransac "
                  "or lmeds");
  }

  [[nodiscard]] Verification verify(const Features& a, const Features& b, const Matches& matches) const {
    Verification v;
    v.matches = static_cast<int>(matches.size());
    if (v.matches < minimal_matches) return v;
    std::vector<cv::Point2f> pa, pb;
    std::vector<int> order;
    detail::gather_points(a, b, matches, options_.seed, pa, pb, order);
    cv::Mat mask;
    cv::Mat H;
    const int method = options_.method == RobustMethod::magsac   ? cv::USAC_MAGSAC
                       : options_.method == RobustMethod::ransac ? cv::RANSAC
                                                                 : cv::LMEDS;
    try {
      H = cv::findHomography(pa, pb, method, options_.threshold_px, mask, options_.max_iterations,
                             options_.confidence);
    } catch (const cv::Exception&) {
      v.status = VerificationStatus::no_model;
      return v;
    }
    detail::fill_from_estimate(H, mask, order, options_.min_inliers, v);
    return v;
  }

  [[nodiscard]] const HomographyOptions& options() const noexcept { return options_; }

 private:
  HomographyOptions options_;
};

static_assert(Estimator<HomographyEstimator>);

}  // namespace vmap
