#pragma once

// What the key-image selector says of each frame (KeyframeSelector::push,
// VisualMemory::push), in a header of its own: a program that reads the answers need not
// compile the selector.

#include <vmap/core/name_table.hpp>
#include <vmap/core/verification.hpp>

#include <cstddef>
#include <cstdint>
#include <optional>
#include <string_view>

namespace vmap {

/// Why a frame did or did not produce a key image.
enum class KeyReason : std::uint8_t {
  none,                 ///< S >= tau: the frame is still covered by the key image
  first_frame,          ///< K_1 = I_1
  below_threshold,      ///< verified, S < tau
  bound_below_threshold,  ///< raw matches / denominator < tau (estimator skipped), so S < tau
  verification_failed,  ///< no F-matrix (too few matches, no model, too few inliers)
};

/// The reasons' names, in words (core/names.hpp).
[[nodiscard]] constexpr auto names_of(KeyReason) noexcept {
  using R = KeyReason;
  return detail::NameTable<KeyReason, 5>{{{{R::none, "similar to the key image"},
                                           {R::first_frame, "first frame"},
                                           {R::below_threshold, "similarity below tau"},
                                           {R::bound_below_threshold, "match bound below tau (verification skipped)"},
                                           {R::verification_failed, "verification failed"}}}};
}
[[nodiscard]] constexpr std::string_view to_string(KeyReason r) noexcept { return names_of(r).name(r); }

/// What push() did with one frame.
struct FrameResult {
  std::size_t frame_index = 0;
  /// S(K, I_j) against the key image that was current when the frame arrived; when
  /// `exact` is false the estimator was skipped and this is the upper bound (< tau).
  double similarity = 0.0;
  bool exact = true;
  int raw_matches = 0;       ///< correspondences before verification
  int verified_matches = 0;  ///< inliers (0 if verification failed or was skipped)
  VerificationStatus status = VerificationStatus::verified;  ///< of the verification (meaningful when `exact`)
  bool key_taken = false;
  std::optional<std::size_t> key_frame;  ///< the frame that became a key image (j-1 or j)
  KeyReason reason = KeyReason::none;
};

}  // namespace vmap
