#pragma once

// Header-only, or compiled once. vmap is header-only: every function is defined in the
// headers, and a program compiles what it uses. A program that links vmap::stacks
// (CMakeLists.txt) is compiled with VMAP_COMPILED_STACKS instead, and then:
//   - the run-time layer's stacks of the shipped descriptors are declared `extern
//     template` (runtime/detail/compiled_stacks.hpp), so no file of the program
//     instantiates them;
//   - the classes that are not templates (io/frame_source.hpp's readers of videos, lists
//     and bags; runtime/memory.hpp's AnyMemory) are declared only: their definitions, in
//     the detail/*_impl.hpp headers, are compiled in one translation unit of vmap::stacks
//     each, so no file of the program parses OpenCV's videoio, the bag readers, SQLite or
//     a VisualMemory for them.
// VMAP_INLINE marks those definitions: `inline` in a header-only program, where every
// file that includes them compiles them; nothing under VMAP_COMPILED_STACKS, where the
// one translation unit that includes them gives the program their single definition.

#ifdef VMAP_COMPILED_STACKS
#define VMAP_INLINE
#else
#define VMAP_INLINE inline
#endif
