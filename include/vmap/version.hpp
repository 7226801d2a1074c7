#pragma once

// The one place the version lives; CMakeLists.txt reads these three lines.
#define VMAP_VERSION_MAJOR 0
#define VMAP_VERSION_MINOR 1
#define VMAP_VERSION_PATCH 0

namespace vmap {

inline constexpr int version_major = VMAP_VERSION_MAJOR;
inline constexpr int version_minor = VMAP_VERSION_MINOR;
inline constexpr int version_patch = VMAP_VERSION_PATCH;

}  // namespace vmap
