#pragma once

#include <vmap/core/concepts.hpp>

#include <algorithm>
#include <cstddef>
#include <string>

namespace vmap {

/// Which feature count normalises the verified matches.
enum class RatioBase {
  larger,   ///< max(|D_i|, |D_j|): eq. 5 of García-Pintos et al. 2023
  smaller,  ///< min(|D_i|, |D_j|): the share of the poorer image's features re-found
};

/// Verified matches over a feature count: S(I_i, I_j) = f_match(D_i, D_j) / N, f_match
/// being the matches that survive geometric verification (0 when it failed).
template <RatioBase Base>
struct BasicInlierRatio {
  [[nodiscard]] double operator()(const Features& a, const Features& b, const Verification& v) const noexcept {
    return v.ok() ? ratio(a, b, v.inliers) : 0.0;
  }
  /// Verification only removes matches, so the raw matches over N bound S from above.
  [[nodiscard]] double upper_bound(const Features& a, const Features& b, int raw_matches) const noexcept {
    return ratio(a, b, raw_matches);
  }
  /// Its name (core/concepts.hpp, DescribesItself); it has no options.
  [[nodiscard]] std::string describe() const { return Base == RatioBase::larger ? "InlierRatio" : "InlierRatioMin"; }

 private:
  static double ratio(const Features& a, const Features& b, int count) noexcept {
    const std::size_t n = Base == RatioBase::larger ? std::max(a.size(), b.size()) : std::min(a.size(), b.size());
    return n == 0 ? 0.0 : std::min(1.0, static_cast<double>(count) / static_cast<double>(n));
  }
};

/// Eq. 5 of García-Pintos et al. 2023: S = f_match / max(|D_i|, |D_j|).
using InlierRatio = BasicInlierRatio<RatioBase::larger>;

/// Normalised by the smaller feature set instead: kinder when one image is nearly blank
/// (a wall), so it keeps fewer key images in texture-poor stretches.
using InlierRatioMin = BasicInlierRatio<RatioBase::smaller>;

static_assert(Similarity<InlierRatio>);
static_assert(Similarity<InlierRatioMin>);

}  // namespace vmap
