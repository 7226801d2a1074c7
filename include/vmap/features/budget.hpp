#pragma once

// The keypoint budget of a descriptor ("--nfeatures"): OpenCV's detectors reserve
// memory for the whole budget per pyramid level before detecting, so a budget of 1e9
// is a bad_alloc and 2e9 a length_error deep inside OpenCV. The budget is checked
// against a documented maximum instead, with a message naming the option.

#include <vmap/core/error.hpp>

#include <string>

namespace vmap {

/// Largest keypoint budget a descriptor accepts: 2^20 (1 048 576), far more than the
/// keypoints of any camera frame (a 4K frame yields a few tens of thousands).
inline constexpr int max_keypoint_budget = 1 << 20;

namespace detail {

/// Checks a keypoint budget: in [minimum, max_keypoint_budget]; `option` names it
/// ("OrbOptions.features").
inline void check_keypoint_budget(int budget, int minimum, const std::string& option) {
  check(budget >= minimum && budget <= max_keypoint_budget,
        option + " must be in [" + std::to_string(minimum) + ", " + std::to_string(max_keypoint_budget) + "], got " +
            std::to_string(budget));
}

}  // namespace detail
}  // namespace vmap
