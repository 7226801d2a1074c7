#pragma once

// The named memories: the key-image selection paper's stack (ORB 1000 + mutual NN +
// MAGSAC++ + eq. 5) and its A-KAZE and SIFT twins, as VisualMemory types
// (memory/visual_memory.hpp is the class, for any stack). The run-time layer holds the
// same memories behind AnyMemory (runtime/memory.hpp), chosen by a PolicyStack.

#include <vmap/features/akaze.hpp>
#include <vmap/features/orb.hpp>
#include <vmap/features/sift.hpp>
#include <vmap/geometry/fundamental.hpp>
#include <vmap/geometry/similarity.hpp>
#include <vmap/matching/brute_force.hpp>
#include <vmap/memory/visual_memory.hpp>

namespace vmap {

using OrbVisualMemory = VisualMemory<OrbDescriptor, BruteForceMatcher, FundamentalEstimator, InlierRatio>;
using AkazeVisualMemory = VisualMemory<AkazeDescriptor, BruteForceMatcher, FundamentalEstimator, InlierRatio>;
using SiftVisualMemory = VisualMemory<SiftDescriptor, BruteForceMatcher, FundamentalEstimator, InlierRatio>;

}  // namespace vmap

// A program that links vmap::stacks (CMake) compiles the named stacks' members defined
// apart from the class (memory/detail/visual_memory_impl.hpp) once, there
// (runtime/detail/compiled_stacks.hpp).
#ifdef VMAP_COMPILED_STACKS
extern template class vmap::VisualMemory<vmap::OrbDescriptor, vmap::BruteForceMatcher, vmap::FundamentalEstimator,
                                         vmap::InlierRatio>;
extern template class vmap::VisualMemory<vmap::AkazeDescriptor, vmap::BruteForceMatcher, vmap::FundamentalEstimator,
                                         vmap::InlierRatio>;
extern template class vmap::VisualMemory<vmap::SiftDescriptor, vmap::BruteForceMatcher, vmap::FundamentalEstimator,
                                         vmap::InlierRatio>;
#endif
