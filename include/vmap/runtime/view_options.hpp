#pragma once

// The values of a memory's page (runtime/view.hpp): the answers it shows, how it is
// written, and what was written. Apart from the page's code so that a program that only
// passes answers around compiles none of it.

#include <vmap/lcd/place_decision.hpp>
#include <vmap/memory/types.hpp>

#include <array>
#include <cstddef>
#include <cstdint>
#include <filesystem>
#include <optional>
#include <string>
#include <utility>
#include <vector>

namespace vmap {

/// A metric pose answered for a query: camera-to-world, the position in metres and the
/// rotation as a quaternion in TUM order (qx, qy, qz, qw), with its figures (inliers,
/// reprojection error, ...) by name.
struct ViewPose {
  std::array<double, 3> position{};
  std::array<double, 4> quaternion{0.0, 0.0, 0.0, 1.0};
  std::vector<std::pair<std::string, double>> figures{};
};

/// One query's answer as the page shows it.
struct ViewAnswer {
  std::string image;      ///< the query's name (its file)
  bool accepted = false;  ///< placed on `key`
  std::string status;     ///< "accepted", "unknown place", ... (to_string(PlaceStatus))
  std::string reason;     ///< why, in words
  double confidence = 0.0;
  std::optional<std::uint32_t> key;  ///< the key image it was placed on (accepted)
  std::string robot;  ///< a fleet's memory: the robot whose memory answered; empty otherwise
  std::optional<ViewPose> pose;  ///< the metric pose, where one was answered
  std::string pose_reason;       ///< why there is no metric pose (empty when unknown)
};

/// localize()'s answer for the query `image` as the page shows it.
[[nodiscard]] inline ViewAnswer view_answer(std::string image, const MemoryLocalization& a, std::string robot = {}) {
  ViewAnswer v;
  v.image = std::move(image);
  v.accepted = a.ok();
  v.status = std::string(to_string(a.status));
  v.reason = a.reason;
  v.confidence = a.confidence;
  if (const PlaceLink* b = a.best()) v.key = b->key;
  v.robot = std::move(robot);
  return v;
}

/// How write_view writes the page.
struct ViewOptions {
  /// The queries placed on the page (empty: no answers shown). A key image or robot the
  /// memory does not have is an Error (answers of another memory).
  std::vector<ViewAnswer> answers{};
  /// The longest side of the key images written, pixels (smaller ones are kept as they
  /// are); 0 writes no image.
  int image_side = 480;
  int jpeg_quality = 85;  ///< 1..100
  /// Verify each loop again to draw its matches (the memory's matcher and estimator on
  /// the two key images' features, as the loop was found); false draws none.
  bool matches = true;
  /// The page's title (default: the memory's name).
  std::string title{};
};

/// What write_view wrote.
struct ViewResult {
  std::filesystem::path index;  ///< DIR/index.html
  std::size_t key_images = 0, loops = 0, runs = 0;
  std::size_t images = 0;        ///< key images with their pixels on the page
  std::size_t matched_loops = 0;  ///< loops with their matches drawn
  std::size_t answers = 0, placed = 0;  ///< queries shown, of them placed on a key image
  bool posed = false;            ///< the map from above (every key image has a pose), else the time line
  std::string images_from;       ///< where the pixels came from, in words
  std::uintmax_t bytes = 0;      ///< the folder's size
  double seconds = 0.0;
};

/// What `source` is to view_source: a memory (a store or a .vmem file, or a folder holding
/// memory.vmdb), a fleet's memory (a postgresql:// URI), or a visual map (a map.vmap file,
/// or the folder `vmap build --out` wrote, holding one).
enum class ViewSourceKind : std::uint8_t { memory, fleet, visual_map };

}  // namespace vmap
