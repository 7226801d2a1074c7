#pragma once

// The place decision's chance model, measured for a stack (lcd/place_decision.hpp).
//
// The decision weighs a pair's inliers against the rate at which tentative matches fit
// the model by chance (PlaceDecisionOptions::chance_inlier_rate). That rate belongs to
// the matcher and the estimator, not to the world: mutual ORB matches of unrelated images
// fit a fundamental matrix at 1 px about one time in ten, SIFT's far less often, and a
// dense matcher's cells differently again. So the rate is measured, from verifications
// of pairs of images known to show different places, and chosen so that a foreign pair
// reaches the same significance whatever the stack:
//
//   the chance rate is the smallest rate at which all but (1 - quantile) of the foreign
//   pairs have a significance of at most `significance` (5 by default),
//
// the strongest pair instead when almost no foreign pair makes a model at all. With these
// defaults ORB 1000, mutual NN and MAGSAC++ at 1 px measure about 0.1 on the shared
// sequences, the rate the decision was built with (examples/results/loops.md, "The
// chance rate of each stack"): the target is ORB's, and a confidence then means the same
// for every stack.
//
//   vmap::ChanceCalibration c = vmap::calibrate_chance_rate(matcher, estimator, places);
//   options.loops.decision.chance_inlier_rate = c.rate;  // stored with the memory
//
// `places` holds the features of two or more places (one vector each); pairs are drawn
// with one image from each of two different places, with a seed.

#include <vmap/core/concepts.hpp>
#include <vmap/core/error.hpp>
#include <vmap/core/features.hpp>
#include <vmap/lcd/loop_engine.hpp>
#include <vmap/lcd/place_decision.hpp>

#include <algorithm>
#include <cmath>
#include <cstddef>
#include <cstdint>
#include <random>
#include <span>
#include <string>
#include <vector>

namespace vmap {

/// One verification of a pair of images of different places.
struct ChanceSample {
  int fitted = 0;   ///< tentative matches the model was fitted to (Verification::fitted)
  int inliers = 0;  ///< 0 when no model was verified
};

/// How the chance rate is chosen from the foreign pairs (see the top of this file).
struct ChanceCalibrationOptions {
  /// The share of foreign pairs whose significance stays at or below `significance`.
  double quantile = 0.99;
  /// The significance the foreign pair at the quantile reaches: 5 (a confidence of 0.25,
  /// half of min_confidence), where ORB's pair at the quantile stands at its rate of 0.1.
  double significance = 5.0;
  /// Pairs with fewer inliers count as significance 0: the decision does not weigh them.
  int min_inliers = PlaceDecisionOptions{}.min_inliers;
  /// Fewer foreign pairs than this cannot place the quantile: 100.
  std::size_t min_pairs = 100;
};

/// What the calibration measured.
struct ChanceCalibration {
  double rate = 0.0;            ///< set PlaceDecisionOptions::chance_inlier_rate to this
  std::size_t pairs = 0;        ///< foreign pairs verified
  std::size_t weighed = 0;      ///< of those, with at least min_inliers inliers
  double strongest = 0.0;       ///< the strongest foreign pair's significance at `rate`
};

/// The highest chance rate a calibration gives: above it the pairs are not foreign.
inline constexpr double max_chance_rate = 0.5;

namespace detail {

inline double sample_significance(const ChanceSample& s, int sample, double rate, int min_inliers) {
  if (s.inliers < min_inliers || s.inliers <= 0) return 0.0;
  return binomial_tail_significance(s.inliers - sample, s.fitted - sample, rate);
}

/// The significance of the pair at `quantile` of all pairs (ascending) at `rate`.
inline double quantile_significance(std::span<const ChanceSample> samples, int sample, double rate,
                                    const ChanceCalibrationOptions& o) {
  std::vector<double> s;
  s.reserve(samples.size());
  for (const ChanceSample& c : samples) s.push_back(sample_significance(c, sample, rate, o.min_inliers));
  const auto k = std::min(s.size() - 1, static_cast<std::size_t>(std::floor(o.quantile * static_cast<double>(s.size()))));
  std::nth_element(s.begin(), s.begin() + static_cast<std::ptrdiff_t>(k), s.end());
  return s[k];
}

}  // namespace detail

/// The chance rate of the foreign pairs `samples`, verified with model `model` (see the
/// top of this file). An Error when the options are out of range, there are fewer than
/// min_pairs samples, one has more inliers than fitted matches, none makes a model the
/// decision weighs, or they fit far beyond chance (the places share views).
[[nodiscard]] inline ChanceCalibration chance_rate_from(std::span<const ChanceSample> samples, PlaceModel model,
                                                        const ChanceCalibrationOptions& o = {}) {
  detail::check(std::isfinite(o.quantile) && o.quantile > 0.0 && o.quantile < 1.0, [&] {
    return "ChanceCalibrationOptions.quantile must be in (0, 1), got " + std::to_string(o.quantile);
  });
  detail::check(std::isfinite(o.significance) && o.significance > 0.0, [&] {
    return "ChanceCalibrationOptions.significance must be > 0, got " + std::to_string(o.significance);
  });
  detail::check(samples.size() >= std::max<std::size_t>(o.min_pairs, 1), [&] {
    return "chance calibration: " + std::to_string(samples.size()) + " foreign pairs, at least " +
           std::to_string(o.min_pairs) + " are needed to place the " + std::to_string(o.quantile) + " quantile";
  });
  const int sample = detail::minimal_sample(model);
  ChanceCalibration c;
  c.pairs = samples.size();
  for (const ChanceSample& s : samples) {
    detail::check(s.fitted >= 0 && s.inliers >= 0 && s.inliers <= s.fitted, [&] {
      return "chance calibration: a sample has " + std::to_string(s.inliers) + " inliers of " + std::to_string(s.fitted) +
             " fitted matches";
    });
    if (s.inliers >= o.min_inliers && s.inliers > 0) ++c.weighed;
  }
  detail::check(c.weighed > 0, [&] {
    return "chance calibration: none of " + std::to_string(c.pairs) + " foreign pairs has " +
           std::to_string(o.min_inliers) + " inliers, so chance never makes a model the decision weighs and its rate "
           "cannot be measured; verify more pairs";
  });
  // The significance falls as the rate rises: bisect, on a log scale between 1e-4 and
  // max_chance_rate, for the rate at which the pair at the quantile reaches
  // `significance`. When fewer than (1 - quantile) of the pairs are weighed at all, the
  // pair at the quantile is never significant: the strongest pair sets the rate instead.
  ChanceCalibrationOptions at = o;
  if (detail::quantile_significance(samples, sample, 1e-4, at) <= 0.0) at.quantile = 1.0;
  // Pairs that stay significant at max_chance_rate are not chance (no stack's matches
  // fit by chance one time in two): the "foreign" places share views, the same place
  // given twice or overlapping ones.
  detail::check(detail::quantile_significance(samples, sample, max_chance_rate, at) <= o.significance, [&] {
    return "chance calibration: the foreign pairs fit the model far beyond chance (at a rate of 0.5 the pair at the " +
           std::to_string(at.quantile) + " quantile is still significant): the places share views; give places that "
           "share nothing";
  });
  double lo = std::log(1e-4), hi = std::log(max_chance_rate);
  for (int i = 0; i < 60; ++i) {
    const double mid = 0.5 * (lo + hi);
    (detail::quantile_significance(samples, sample, std::exp(mid), at) > o.significance ? lo : hi) = mid;
  }
  c.rate = std::exp(hi);
  for (const ChanceSample& s : samples)
    c.strongest = std::max(c.strongest, detail::sample_significance(s, sample, c.rate, o.min_inliers));
  return c;
}

/// How many foreign pairs to verify, and the seed that draws them.
struct ChancePairs {
  std::size_t pairs = 200;
  std::uint64_t seed = 1;
};

/// Verifies `draw.pairs` pairs of images of different places with `matcher` and
/// `estimator` (the stack's own) and measures the chance rate from them (see the top of
/// this file). `places`: the features of two or more places, each with an image. The
/// same places, stack and seed give the same rate.
template <Matcher M, Estimator E>
[[nodiscard]] ChanceCalibration calibrate_chance_rate(const M& matcher, const E& estimator,
                                                      const std::vector<std::vector<Features>>& places,
                                                      const ChancePairs& draw = {}, const ChanceCalibrationOptions& o = {}) {
  std::size_t nonempty = 0;
  for (const auto& p : places) nonempty += p.empty() ? 0 : 1;
  detail::check(nonempty >= 2 && nonempty == places.size(), [&] {
    return "chance calibration: needs at least two places, each with an image; got " + std::to_string(places.size()) +
           " places, " + std::to_string(places.size() - nonempty) + " of them empty";
  });
  // rng() % n rather than a std distribution: the same pairs with every standard library.
  std::mt19937_64 rng(draw.seed);
  std::vector<ChanceSample> samples;
  samples.reserve(draw.pairs);
  for (std::size_t i = 0; i < draw.pairs; ++i) {
    const std::size_t a = rng() % places.size();
    std::size_t b = rng() % (places.size() - 1);
    if (b >= a) ++b;
    const Features& fa = places[a][rng() % places[a].size()];
    const Features& fb = places[b][rng() % places[b].size()];
    const Matches matches = matcher.match(fa, fb);
    const Verification v = estimator.verify(fa, fb, matches);
    samples.push_back({v.fitted.value_or(static_cast<int>(matches.size())), v.ok() ? v.inliers : 0});
  }
  return chance_rate_from(samples, place_model_of<E>(), o);
}

}  // namespace vmap
