#pragma once

// The key-image selector's options, alone: a program that only configures a selector (or
// a memory, memory/options.hpp) includes this instead of keyframe/selector.hpp.

#include <vmap/core/name_table.hpp>

#include <cstdint>
#include <string_view>

namespace vmap {

/// Which frame becomes the new key image when frame j no longer resembles the key image.
enum class KeyRule : std::uint8_t {
  previous_frame,  ///< eq. 6: I_{j-1}, the last frame that still passed (the default)
  current_frame,   ///< Algorithm 1 as printed: I_j itself
};

/// previous (eq. 6), current (Algorithm 1) (core/names.hpp).
[[nodiscard]] constexpr auto names_of(KeyRule) noexcept {
  return detail::NameTable<KeyRule, 2>{{{{KeyRule::previous_frame, "previous"}, {KeyRule::current_frame, "current"}}}};
}
[[nodiscard]] constexpr std::string_view to_string(KeyRule r) noexcept { return names_of(r).name(r); }

struct SelectorOptions {
  /// tau: a new key image is taken when S(K_i, I_j) < tau; in (0, 1].
  double tau = 0.3;
  KeyRule rule = KeyRule::previous_frame;
  /// Skip the estimator when raw matches / eq. 5 denominator (an upper bound of S) is
  /// already below tau. Never changes the key images; it only leaves the similarity of
  /// such frames unknown (FrameResult::exact = false).
  bool skip_by_upper_bound = true;
  /// Keep each key image's pixels in the VisualMap (for contact sheets and map files).
  bool keep_images = false;
};

}  // namespace vmap
