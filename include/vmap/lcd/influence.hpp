#pragma once

// Label influence of LFM-LCD (Zhu et al., Sensors 2021, eq. 5): over a sample of M label
// vectors, E(i) = p(i) / M, p(i) being the number of vectors with c(i) = 1. A label is a
// useful tree level only when it splits the frames: one that is almost never present
// sends nearly every frame down the same branch while doubling the tree (and a label seen
// once or twice is as likely a false detection as an object), and one that is present
// almost everywhere separates nothing but its own misses. Both are dropped.

#include <vmap/core/error.hpp>
#include <vmap/lcd/label_vector.hpp>
#include <vmap/lcd/options.hpp>

#include <algorithm>
#include <cmath>
#include <cstddef>
#include <string>
#include <utility>
#include <vector>

namespace vmap {

namespace detail {

inline void check_influence_options(const InfluenceOptions& o) {
  check(std::isfinite(o.min_influence) && std::isfinite(o.max_influence) && o.min_influence >= 0.0 &&
            o.max_influence <= 1.0 && o.min_influence <= o.max_influence,
        [&] {
          return "InfluenceOptions: need 0 <= min_influence <= max_influence <= 1, got [" +
                 std::to_string(o.min_influence) + ", " + std::to_string(o.max_influence) + "]";
        });
}

}  // namespace detail

/// Eq. 5 over a sample of label vectors of equal length: E(i) = p(i) / M. An empty sample
/// gives all zeros; vectors of differing length or with entries other than 0/1 are an
/// Error.
[[nodiscard]] inline std::vector<double> label_influence(const std::vector<LabelVector>& sample) {
  if (sample.empty()) return {};
  const std::size_t n = sample.front().size();
  std::vector<std::size_t> p(n, 0);
  for (std::size_t k = 0; k < sample.size(); ++k) {
    detail::check(sample[k].size() == n, [&] {
      return "label_influence: vector " + std::to_string(k) + " has length " + std::to_string(sample[k].size()) +
             ", the first has " + std::to_string(n);
    });
    for (std::size_t i = 0; i < n; ++i) {
      detail::check(sample[k][i] <= 1,
                    [&] { return "label_influence: vector " + std::to_string(k) + " holds a value other than 0/1"; });
      p[i] += sample[k][i];
    }
  }
  std::vector<double> e(n);
  for (std::size_t i = 0; i < n; ++i) e[i] = static_cast<double>(p[i]) / static_cast<double>(sample.size());
  return e;
}

/// Indices i whose influence lies in [min_influence, max_influence], ascending.
[[nodiscard]] inline std::vector<std::size_t> kept_levels(const std::vector<double>& influence,
                                                          const InfluenceOptions& options = {}) {
  detail::check_influence_options(options);
  std::vector<std::size_t> out;
  for (std::size_t i = 0; i < influence.size(); ++i)
    if (influence[i] >= options.min_influence && influence[i] <= options.max_influence) out.push_back(i);
  return out;
}

/// One label's line in the influence report.
struct LabelInfluence {
  int label = -1;
  double influence = 0.0;  ///< E(i) = p(i) / M
  double mean_area = 0.0;  ///< pixels^2, the default ordering key
  bool kept = false;
};

/// The tree's label schema from a sample: labels ordered large to small (by
/// `user_order` first, the labels it does not name after it by mean box area), then
/// pruned to the eq. 5 influence band. `report`, when given, receives every label seen
/// with its influence, in the schema's order.
[[nodiscard]] inline LabelSchema make_label_schema(const LabelStatistics& stats, const InfluenceOptions& options = {},
                                                   const std::vector<int>& user_order = {},
                                                   std::vector<LabelInfluence>* report = nullptr) {
  detail::check_influence_options(options);
  std::vector<int> order;
  for (int l : user_order)
    if (std::find(order.begin(), order.end(), l) == order.end()) order.push_back(l);
  for (int l : stats.labels_by_area())
    if (std::find(order.begin(), order.end(), l) == order.end()) order.push_back(l);
  std::vector<int> kept;
  if (report) report->clear();
  for (int l : order) {
    const double e = stats.samples() == 0 ? 0.0
                                          : static_cast<double>(stats.presence(l)) / static_cast<double>(stats.samples());
    const bool keep = e >= options.min_influence && e <= options.max_influence;
    if (keep) kept.push_back(l);
    if (report) report->push_back({l, e, stats.mean_area(l), keep});
  }
  return LabelSchema(std::move(kept));
}

}  // namespace vmap
