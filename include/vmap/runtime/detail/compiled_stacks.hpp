#pragma once

// The run-time layer's stacks compiled once: the translation units of vmap::stacks
// (CMakeLists.txt generates one per descriptor) each say VMAP_INSTANTIATE_STACK(D) for
// one of the shipped descriptors, which instantiates every factory of the run-time layer
// for it: AnyMemory's memories, AnySelector's selectors and sweeps, AnyLoopDetector's
// detectors and check_pair. A program that links vmap::stacks is compiled with
// VMAP_COMPILED_STACKS, under which the run-time headers declare these instantiations
// `extern`, so none of its own translation units instantiates a whole VisualMemory,
// KeyframeSelector or LoopDetector of a shipped stack. A program that does not link it
// instantiates what it uses, as any header-only library (the same headers, nothing else
// changes). The classic descriptors' TUs also say VMAP_INSTANTIATE_NAMED_MEMORY, for the
// named stacks of memory/stacks.hpp (OrbVisualMemory and its A-KAZE and SIFT
// twins), which programs and tests use typed.

#include <vmap/runtime/loop_detector.hpp>
#include <vmap/runtime/detail/memory_model.hpp>
#include <vmap/runtime/pair.hpp>
#include <vmap/runtime/selector.hpp>

#define VMAP_INSTANTIATE_STACK(D)                \
  namespace vmap::detail {                       \
  template struct MemoryFactory<D>;              \
  template struct SelectorFactory<D>;            \
  template struct LoopDetectorFactory<D>;        \
  template struct PairFactory<D>;                \
  }

#define VMAP_INSTANTIATE_NAMED_MEMORY(D) \
  template class vmap::VisualMemory<D, vmap::BruteForceMatcher, vmap::FundamentalEstimator, vmap::InlierRatio>;
