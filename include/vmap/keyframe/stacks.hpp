#pragma once

// The named selectors: the key-image selection paper's stack and its A-KAZE and SIFT
// twins, as types (keyframe/selector.hpp is the class, for any stack). The F-matrix
// method is an option of FundamentalEstimator (FundamentalOptions::method, MAGSAC++ by
// default), so e.g. OrbMagsacSelector default-constructed is the paper's ORB 1000 +
// mutual NN + MAGSAC 1 px 0.99 + eq. 5 (García-Pintos et al. 2023, sec. 3).

#include <vmap/features/akaze.hpp>
#include <vmap/features/orb.hpp>
#include <vmap/features/sift.hpp>
#include <vmap/geometry/fundamental.hpp>
#include <vmap/geometry/similarity.hpp>
#include <vmap/keyframe/selector.hpp>
#include <vmap/matching/brute_force.hpp>

namespace vmap {

using OrbMagsacSelector = KeyframeSelector<OrbDescriptor, BruteForceMatcher, FundamentalEstimator, InlierRatio>;
using AkazeMagsacSelector = KeyframeSelector<AkazeDescriptor, BruteForceMatcher, FundamentalEstimator, InlierRatio>;
using SiftMagsacSelector = KeyframeSelector<SiftDescriptor, BruteForceMatcher, FundamentalEstimator, InlierRatio>;

}  // namespace vmap
