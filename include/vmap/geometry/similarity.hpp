#pragma once

#include <vmap/core/concepts.hpp>

#include <algorithm>
#include <cstddef>

namespace vmap {

/// Eq. 5 of García-Pintos et al. 2023: S(I_i, I_j) = f_match(D_i, D_j) / max(|D_i|, |D_j|),
/// f_match being the matches that survive geometric verification (0 when it failed).
struct InlierRatio {
  [[nodiscard]] double operator()(const Features& a, const Features& b, const Verification& v) const noexcept {
    return v.ok() ? ratio(a, b, v.inliers) : 0.0;
  }
  /// Verification only removes matches, so raw matches / max bound S from above.
  [[nodiscard]] double upper_bound(const Features& a, const Features& b, int raw_matches) const noexcept {
    return ratio(a, b, raw_matches);
  }

 private:
  static double ratio(const Features& a, const Features& b, int count) noexcept {
    const std::size_t denom = std::max(a.size(), b.size());
    return denom == 0 ? 0.0 : static_cast<double>(count) / static_cast<double>(denom);
  }
};

/// Normalised by the smaller feature set instead: the share of the poorer image's
/// features that are re-found. Kinder when one image is nearly blank (a wall), so it
/// keeps fewer key images in texture-poor stretches.
struct InlierRatioMin {
  [[nodiscard]] double operator()(const Features& a, const Features& b, const Verification& v) const noexcept {
    return v.ok() ? ratio(a, b, v.inliers) : 0.0;
  }
  [[nodiscard]] double upper_bound(const Features& a, const Features& b, int raw_matches) const noexcept {
    return ratio(a, b, raw_matches);
  }

 private:
  static double ratio(const Features& a, const Features& b, int count) noexcept {
    const std::size_t denom = std::min(a.size(), b.size());
    return denom == 0 ? 0.0 : std::min(1.0, static_cast<double>(count) / static_cast<double>(denom));
  }
};

static_assert(Similarity<InlierRatio>);
static_assert(Similarity<InlierRatioMin>);

}  // namespace vmap
