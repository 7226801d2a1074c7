#pragma once

// Nearest-wall choice of the GCS localization paper (Trujillo-Romero 2024;
// examples/methods.md, sec. 3 step 2): A-KAZE keypoints are counted in the left and right halves of a
// forward-looking image; the half with more keypoints shows the nearer wall, and the
// robot turns its camera to it.

#include <vmap/core/concepts.hpp>
#include <vmap/core/error.hpp>
#include <vmap/core/features.hpp>
#include <vmap/core/name_table.hpp>

#include <opencv2/core.hpp>

#include <cstddef>
#include <string_view>

namespace vmap {

enum class WallSide { left, right };

/// left, right (core/names.hpp).
[[nodiscard]] constexpr auto names_of(WallSide) noexcept {
  return detail::NameTable<WallSide, 2>{{{{WallSide::left, "left"}, {WallSide::right, "right"}}}};
}
[[nodiscard]] constexpr std::string_view to_string(WallSide s) noexcept { return names_of(s).name(s); }

struct NearestWall {
  WallSide side = WallSide::left;  ///< the half with more keypoints (left on a tie)
  std::size_t left = 0;            ///< keypoints with x < width / 2
  std::size_t right = 0;           ///< keypoints with x >= width / 2
  [[nodiscard]] bool tie() const noexcept { return left == right; }
};

/// Counts the keypoints of `f` per image half. Needs Features::image_size.
inline NearestWall nearest_wall(const Features& f) {
  detail::check(f.image_size.width > 0, "nearest_wall: the features carry no image size");
  NearestWall out;
  const float half = static_cast<float>(f.image_size.width) / 2.0f;
  for (const auto& k : f.keypoints) (k.pt.x < half ? out.left : out.right) += 1;
  out.side = out.right > out.left ? WallSide::right : WallSide::left;
  return out;
}

/// Extracts features of `image` with `descriptor` (A-KAZE in the paper) and counts them.
template <Descriptor D>
NearestWall nearest_wall(D& descriptor, const cv::Mat& image) {
  detail::check(!image.empty(), "nearest_wall: the image is empty");
  return nearest_wall(descriptor.extract(image));
}

}  // namespace vmap
