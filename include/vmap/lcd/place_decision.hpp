#pragma once

// "Same place?" as a decision with evidence and a reason (examples/methods.md, sec. 4),
// one for loop closure and for localization. A verified candidate is accepted only when its
// evidence tells places apart; otherwise the answer says why: the query shows an unknown
// place, two places are equally likely, the evidence is too little, or the camera never
// left the candidate's place (not a revisit).
//
// The evidence of one verified pair (query, candidate):
//   - inliers of the geometric model and the inlier ratio (inliers / tentative matches);
//   - the significance of the inliers: -log10 of the probability that at least that many
//     of the tentative matches fit the model by chance (a binomial tail, each match an
//     inlier by chance with probability `chance_inlier_rate`, the model's minimal sample
//     always fitting). Two unrelated images still give a fundamental matrix with some
//     inliers among many mutual ORB matches (1 px band): few inliers out of many
//     matches are what chance gives, many out of few are not (measured on every shared
//     sequence: examples/results/loops.md, "How the decision's defaults were chosen");
//   - the spread of the inliers over each image (the fraction of cells of a grid over
//     the keypoints' extent that hold an inlier, the smaller of the two views): a
//     repeated texture gives many inliers in one small patch;
//   - the bag-of-words score of the candidate.
// The confidence in [0, 1] is 1 - 2^(-significance / half_significance), scaled down
// when the inliers are bunched (spread below full_spread). One threshold on it
// (min_confidence) decides, so precision-recall curves are drawn over it.

#include <vmap/core/error.hpp>
#include <vmap/core/features.hpp>
#include <vmap/core/name_table.hpp>
#include <vmap/core/verification.hpp>
#include <vmap/lcd/options.hpp>

#include <opencv2/core.hpp>

#include <algorithm>
#include <cmath>
#include <cstddef>
#include <cstdint>
#include <optional>
#include <string>
#include <string_view>
#include <vector>

namespace vmap {

/// The geometric model a candidate was verified with.
enum class PlaceModel : std::uint8_t {
  fundamental,  ///< raw pixels, 7 degrees of freedom
  essential,    ///< a calibrated camera, 5 degrees of freedom
};

/// fundamental, essential (core/names.hpp).
[[nodiscard]] constexpr auto names_of(PlaceModel) noexcept {
  return detail::NameTable<PlaceModel, 2>{
      {{{PlaceModel::fundamental, "fundamental"}, {PlaceModel::essential, "essential"}}}};
}
[[nodiscard]] constexpr std::string_view to_string(PlaceModel m) noexcept { return names_of(m).name(m); }

/// What one verified pair says about "same place?".
struct PlaceEvidence {
  int matches = 0;              ///< tentative correspondences the model was fitted to (Verification::fitted)
  int inliers = 0;              ///< those the model explains
  double inlier_ratio = 0.0;    ///< inliers / matches
  /// -log10 P(at least `inliers` of `matches` fit by chance); 0 when unverified.
  double significance = 0.0;
  double spread = 0.0;          ///< fraction of grid cells with an inlier, the smaller view
  double bow_score = 0.0;       ///< the candidate's bag-of-words score (0 when not ranked)
  PlaceModel model = PlaceModel::fundamental;
};

/// Why a query was or was not placed.
enum class PlaceStatus : std::uint8_t {
  accepted,             ///< the best place's confidence reaches the threshold
  unknown_place,        ///< candidates were verified, none with enough confidence
  ambiguous,            ///< two distinct places are (nearly) equally likely
  too_little_evidence,  ///< nothing to weigh: no candidate, no model, or not yet confirmed
  not_a_revisit,        ///< the best candidate is the place the camera never left
};

/// The statuses' names, in words (core/names.hpp).
[[nodiscard]] constexpr auto names_of(PlaceStatus) noexcept {
  return detail::NameTable<PlaceStatus, 5>{{{{PlaceStatus::accepted, "accepted"},
                                             {PlaceStatus::unknown_place, "unknown place"},
                                             {PlaceStatus::ambiguous, "ambiguous"},
                                             {PlaceStatus::too_little_evidence, "too little evidence"},
                                             {PlaceStatus::not_a_revisit, "not a revisit"}}}};
}
[[nodiscard]] constexpr std::string_view to_string(PlaceStatus s) noexcept { return names_of(s).name(s); }

/// Why a decision has its status, one value per case, so that a program can act on it
/// (wait for more frames, move the camera, retrain) without reading the text. The five
/// "too little evidence" cases of the loop engine and the two of a memory's localization
/// are told apart here; the decision's `reason` text adds the numbers.
enum class DecisionReason : std::uint8_t {
  no_candidates,           ///< too little evidence: the index proposed no candidate
  below_bow_score,         ///< too little evidence: every candidate below the bag-of-words score
  not_verified,            ///< too little evidence: candidates ranked, none verified
  too_few_inliers,         ///< too little evidence: the best model has fewer inliers than min_inliers
  not_yet_confirmed,       ///< too little evidence: accepted, not yet by enough earlier queries
  empty_memory,            ///< too little evidence: the memory has no key image
  no_query_features,       ///< too little evidence: the query image has no features
  camera_stayed,           ///< not a revisit: the camera never left the candidates' place
  low_confidence,          ///< unknown place: the best confidence is below min_confidence
  two_places,              ///< ambiguous: a second place nearly as confident
  confident,               ///< accepted: the best confidence reaches min_confidence
};

/// The reasons' names, in words (core/names.hpp: to_string and from_string read them).
[[nodiscard]] constexpr auto names_of(DecisionReason) noexcept {
  using R = DecisionReason;
  return detail::NameTable<DecisionReason, 11>{{{{R::no_candidates, "no candidates"},
                                                 {R::below_bow_score, "every candidate below the bag-of-words score"},
                                                 {R::not_verified, "no candidate verified"},
                                                 {R::too_few_inliers, "too few inliers"},
                                                 {R::not_yet_confirmed, "not yet confirmed"},
                                                 {R::empty_memory, "the memory has no key image"},
                                                 {R::no_query_features, "the query image has no features"},
                                                 {R::camera_stayed, "the camera never left the candidates' place"},
                                                 {R::low_confidence, "confidence below the threshold"},
                                                 {R::two_places, "two places equally likely"},
                                                 {R::confident, "confidence reaches the threshold"}}}};
}
[[nodiscard]] constexpr std::string_view to_string(DecisionReason r) noexcept { return names_of(r).name(r); }

/// The status a reason belongs to.
[[nodiscard]] constexpr PlaceStatus status_of(DecisionReason r) noexcept {
  switch (r) {
    case DecisionReason::camera_stayed: return PlaceStatus::not_a_revisit;
    case DecisionReason::low_confidence: return PlaceStatus::unknown_place;
    case DecisionReason::two_places: return PlaceStatus::ambiguous;
    case DecisionReason::confident: return PlaceStatus::accepted;
    default: return PlaceStatus::too_little_evidence;
  }
}

namespace detail {

/// "Owner.option ..." for an option's error message (appended rather than concatenated
/// from temporaries: GCC 12 at -O2 reports a false -Warray-bounds on the latter).
inline std::string option_name(std::string_view owner, std::string_view rest) {
  std::string s;
  s.reserve(owner.size() + rest.size());
  s.append(owner);
  s.append(rest);
  return s;
}

inline void check_place_decision_options(const PlaceDecisionOptions& o, std::string_view owner) {
  const auto in01 = [](double v) { return std::isfinite(v) && v >= 0.0 && v <= 1.0; };
  check(in01(o.min_confidence), [&] {
    return detail::option_name(owner, ".decision.min_confidence must be in [0, 1], got ") + std::to_string(o.min_confidence);
  });
  check(o.min_inliers >= 0,
        [&] { return detail::option_name(owner, ".decision.min_inliers must be >= 0, got ") + std::to_string(o.min_inliers); });
  check(std::isfinite(o.chance_inlier_rate) && o.chance_inlier_rate > 0 && o.chance_inlier_rate < 1,
        [&] { return detail::option_name(owner, ".decision.chance_inlier_rate must be in (0, 1)"); });
  check(std::isfinite(o.half_significance) && o.half_significance > 0,
        [&] { return detail::option_name(owner, ".decision.half_significance must be > 0"); });
  check(o.spread_grid >= 1 && o.spread_grid <= 64,
        [&] { return detail::option_name(owner, ".decision.spread_grid must be in 1..64, got ") + std::to_string(o.spread_grid); });
  check(in01(o.full_spread), [&] { return detail::option_name(owner, ".decision.full_spread must be in [0, 1]"); });
  check(in01(o.ambiguity_ratio), [&] { return detail::option_name(owner, ".decision.ambiguity_ratio must be in [0, 1]"); });
}

/// Fraction of the cells of a grid x grid partition of the points' extent that hold at
/// least one of the `used` points.
inline double cell_coverage(const std::vector<cv::KeyPoint>& all, const std::vector<cv::Point2f>& used, int grid) {
  if (used.empty() || all.empty()) return 0.0;
  float x0 = all.front().pt.x, x1 = x0, y0 = all.front().pt.y, y1 = y0;
  for (const cv::KeyPoint& k : all) {
    x0 = std::min(x0, k.pt.x);
    x1 = std::max(x1, k.pt.x);
    y0 = std::min(y0, k.pt.y);
    y1 = std::max(y1, k.pt.y);
  }
  const float w = std::max(x1 - x0, 1e-3f), h = std::max(y1 - y0, 1e-3f);
  std::vector<std::uint8_t> hit(static_cast<std::size_t>(grid) * static_cast<std::size_t>(grid), 0);
  for (const cv::Point2f& p : used) {
    const int cx = std::clamp(static_cast<int>((p.x - x0) / w * static_cast<float>(grid)), 0, grid - 1);
    const int cy = std::clamp(static_cast<int>((p.y - y0) / h * static_cast<float>(grid)), 0, grid - 1);
    hit[static_cast<std::size_t>(cy * grid + cx)] = 1;
  }
  return static_cast<double>(std::count(hit.begin(), hit.end(), std::uint8_t{1})) / static_cast<double>(hit.size());
}

/// -log10 P(X >= k) for X ~ Binomial(n, p): the tail summed in log space from its
/// largest term (k >= n p here, so the terms fall from the first).
inline double binomial_tail_significance(int k, int n, double p) {
  if (k <= 0 || n <= 0) return 0.0;
  if (k > n) k = n;
  const double lp = std::log(p), lq = std::log1p(-p);
  const auto term = [&](int i) {
    return std::lgamma(n + 1.0) - std::lgamma(i + 1.0) - std::lgamma(n - i + 1.0) + i * lp + (n - i) * lq;
  };
  int first = k;
  const int mode = static_cast<int>(std::floor((n + 1) * p));
  if (first < mode) first = mode;  // below the mode the tail is about 1: no evidence
  const double top = term(first);
  double sum = 0.0;
  for (int i = first; i <= n; ++i) {
    const double t = term(i) - top;
    if (t < -40.0) break;  // the rest adds less than 1e-17 relative
    sum += std::exp(t);
  }
  const double log10_tail = (top + std::log(sum)) / std::log(10.0);
  return k <= mode ? 0.0 : std::max(0.0, -log10_tail);
}

/// Points of the model's minimal sample: they fit whatever the data.
[[nodiscard]] constexpr int minimal_sample(PlaceModel m) noexcept { return m == PlaceModel::essential ? 5 : 7; }

}  // namespace detail

/// The evidence of a verified pair: `matches` between `query` (queryIdx) and `candidate`
/// (trainIdx), `v` their verification. Unverified pairs give zero inliers.
[[nodiscard]] inline PlaceEvidence measure_place_evidence(const Features& query, const Features& candidate,
                                                          const Matches& matches, const Verification& v,
                                                          PlaceModel model, const PlaceDecisionOptions& o = {}) {
  PlaceEvidence e;
  e.model = model;
  e.matches = v.fitted.value_or(static_cast<int>(matches.size()));
  if (!v.ok()) return e;
  e.inliers = v.inliers;
  e.inlier_ratio = e.matches > 0 ? static_cast<double>(e.inliers) / static_cast<double>(e.matches) : 0.0;
  const int sample = detail::minimal_sample(model);
  e.significance = detail::binomial_tail_significance(e.inliers - sample, e.matches - sample, o.chance_inlier_rate);
  std::vector<cv::Point2f> in_q, in_c;
  const std::size_t n = std::min(matches.size(), v.inlier_mask.size());
  for (std::size_t i = 0; i < n; ++i) {
    if (v.inlier_mask[i] == 0) continue;
    const cv::DMatch& m = matches[i];
    if (m.queryIdx < 0 || m.trainIdx < 0 || static_cast<std::size_t>(m.queryIdx) >= query.keypoints.size() ||
        static_cast<std::size_t>(m.trainIdx) >= candidate.keypoints.size())
      continue;
    in_q.push_back(query.keypoints[static_cast<std::size_t>(m.queryIdx)].pt);
    in_c.push_back(candidate.keypoints[static_cast<std::size_t>(m.trainIdx)].pt);
  }
  e.spread = std::min(detail::cell_coverage(query.keypoints, in_q, o.spread_grid),
                      detail::cell_coverage(candidate.keypoints, in_c, o.spread_grid));
  return e;
}

/// The confidence in [0, 1] the evidence gives: 1 - 2^(-significance /
/// half_significance), scaled down by a spread below full_spread; 0 below min_inliers.
[[nodiscard]] inline double place_confidence(const PlaceEvidence& e, const PlaceDecisionOptions& o = {}) {
  if (e.inliers < o.min_inliers || e.inliers <= 0) return 0.0;
  const double base = 1.0 - std::exp2(-e.significance / o.half_significance);
  const double spread = o.full_spread > 0 ? std::min(1.0, e.spread / o.full_spread) : 1.0;
  return std::clamp(base * spread, 0.0, 1.0);
}

}  // namespace vmap
