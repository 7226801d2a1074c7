#pragma once

// Median / mean / max of a list of errors, as the localization tables report them.

#include <algorithm>
#include <numeric>
#include <vector>

namespace vmap::examples {

struct ErrorStats {
  double median = 0, mean = 0, max = 0;
};

inline ErrorStats error_stats(std::vector<double> e) {
  ErrorStats s;
  if (e.empty()) return s;
  std::sort(e.begin(), e.end());
  s.median = e.size() % 2 ? e[e.size() / 2] : 0.5 * (e[e.size() / 2 - 1] + e[e.size() / 2]);
  s.mean = std::accumulate(e.begin(), e.end(), 0.0) / static_cast<double>(e.size());
  s.max = e.back();
  return s;
}

}  // namespace vmap::examples
