#pragma once

// The robust estimation methods, in a header of their own: a policy stack names one
// (runtime/policy_stack.hpp) without compiling the estimators.

#include <vmap/core/name_table.hpp>

#include <string_view>

namespace vmap {

/// Robust estimation methods for the two-view models.
enum class RobustMethod {
  magsac,       ///< MAGSAC++ (cv::USAC_MAGSAC), Barath et al. 2020
  ransac,       ///< classic RANSAC (cv::FM_RANSAC / cv::RANSAC)
  lmeds,        ///< least median of squares
  eight_point,  ///< plain 8-point (fundamental only), every match is an inlier
};

/// The names of the methods: magsac, ransac, lmeds, 8point (core/names.hpp).
[[nodiscard]] constexpr auto names_of(RobustMethod) noexcept {
  return detail::NameTable<RobustMethod, 4>{{{{RobustMethod::magsac, "magsac"},
                                              {RobustMethod::ransac, "ransac"},
                                              {RobustMethod::lmeds, "lmeds"},
                                              {RobustMethod::eight_point, "8point"}}}};
}
[[nodiscard]] constexpr std::string_view to_string(RobustMethod m) noexcept { return names_of(m).name(m); }

}  // namespace vmap
