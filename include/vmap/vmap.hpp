#pragma once

// Umbrella header: everything vmap offers. Include the area headers directly to keep
// compile times down.

#include <vmap/version.hpp>

#include <vmap/core/concepts.hpp>
#include <vmap/core/error.hpp>
#include <vmap/core/features.hpp>
#include <vmap/core/verification.hpp>

#include <vmap/features/akaze.hpp>
#include <vmap/features/orb.hpp>
#include <vmap/features/sift.hpp>

#include <vmap/matching/brute_force.hpp>

#include <vmap/geometry/fundamental.hpp>
#include <vmap/geometry/homography.hpp>
#include <vmap/geometry/similarity.hpp>

#include <vmap/hooks/detection.hpp>
#include <vmap/hooks/pair_matcher.hpp>

#include <vmap/io/atomic_file.hpp>
#include <vmap/io/frame_source.hpp>
