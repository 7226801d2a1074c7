# What the light headers promise, checked with the compiler's own include list (-H):
#   - the options headers need neither OpenCV nor Eigen: they preprocess with vmap's
#     include folder alone, so a file that only configures vmap parses no library;
#   - io/frame_source.hpp in a program linking vmap::stacks (VMAP_COMPILED_STACKS)
#     declares the readers only: OpenCV's videoio, SQLite and the bag readers are not
#     included;
#   - runtime/memory.hpp there declares AnyMemory only: no VisualMemory, selector,
#     vocabulary tree, GCS, memory store or SQLite;
#   - the value headers a program reads answers with (memory/types.hpp,
#     runtime/policy_stack.hpp) compile none of the classes that make the answers, in
#     either form.
# Run by CTest: cmake -DCXX=... -DINCLUDE_DIR=... -DOPENCV_INCLUDE_DIR=... -DEIGEN_INCLUDE_DIR=...
#   -DPG_INCLUDE_DIR=... (libpq's, which the memory store includes)
#   -P light_headers.cmake
function(includes_of out header)
  execute_process(
    COMMAND "${CXX}" -std=c++20 -E -H -x c++ - -o /dev/null ${ARGN}
    INPUT_FILE "${WORK_DIR}/${header}.in"
    RESULT_VARIABLE rc ERROR_VARIABLE err)
  if(NOT rc EQUAL 0)
    message(FATAL_ERROR "<${header}> does not preprocess with ${ARGN}:\n${err}")
  endif()
  set(${out} "${err}" PARENT_SCOPE)
endfunction()

file(MAKE_DIRECTORY "${WORK_DIR}")
foreach(h vmap/memory/options.hpp vmap/keyframe/options.hpp vmap/lcd/options.hpp vmap/place/options.hpp
          vmap/som/options.hpp vmap/io/frame_source.hpp vmap/runtime/memory.hpp vmap/memory/types.hpp
          vmap/runtime/policy_stack.hpp)
  string(MAKE_C_IDENTIFIER "${h}" _id)
  file(WRITE "${WORK_DIR}/${_id}.in" "#include <${h}>\n")
endforeach()

foreach(h vmap/memory/options.hpp vmap/keyframe/options.hpp vmap/lcd/options.hpp vmap/place/options.hpp
          vmap/som/options.hpp)
  string(MAKE_C_IDENTIFIER "${h}" _id)
  includes_of(list "${_id}" "-I${INCLUDE_DIR}")
  if(list MATCHES "opencv2|[Ee]igen")
    message(FATAL_ERROR "<${h}> includes OpenCV or Eigen:\n${list}")
  endif()
  message(STATUS "<${h}>: no OpenCV, no Eigen")
endforeach()

string(MAKE_C_IDENTIFIER "vmap/io/frame_source.hpp" _id)
includes_of(list "${_id}" "-I${INCLUDE_DIR}" "-isystem${OPENCV_INCLUDE_DIR}" -DVMAP_COMPILED_STACKS)
foreach(heavy "opencv2/videoio" "sqlite3.h" "vmap/io/bag/bag.hpp" "frame_source_impl.hpp")
  string(FIND "${list}" "${heavy}" at)
  if(NOT at EQUAL -1)
    message(FATAL_ERROR "<vmap/io/frame_source.hpp> with VMAP_COMPILED_STACKS includes ${heavy}:\n${list}")
  endif()
endforeach()
# Header-only, the readers come with it.
includes_of(list "${_id}" "-I${INCLUDE_DIR}" "-isystem${OPENCV_INCLUDE_DIR}")
string(FIND "${list}" "frame_source_impl.hpp" at)
if(at EQUAL -1)
  message(FATAL_ERROR "<vmap/io/frame_source.hpp> header-only does not include its readers")
endif()
message(STATUS "<vmap/io/frame_source.hpp>: the readers only header-only")

# The run-time layer's memory, and the value headers, against the headers that make them.
set(_heavy "memory/visual_memory.hpp" "keyframe/selector.hpp" "place/vocabulary_tree.hpp" "som/gcs.hpp"
           "memory/store.hpp" "sqlite3.h" "libpq-fe.h" "features/orb.hpp" "geometry/fundamental.hpp" "geometry/pnp.hpp")
set(_flags "-I${INCLUDE_DIR}" "-isystem${OPENCV_INCLUDE_DIR}" "-isystem${EIGEN_INCLUDE_DIR}" "-isystem${PG_INCLUDE_DIR}")
foreach(h vmap/runtime/memory.hpp vmap/memory/types.hpp vmap/runtime/policy_stack.hpp)
  string(MAKE_C_IDENTIFIER "${h}" _id)
  set(_modes -DVMAP_COMPILED_STACKS)
  if(NOT h STREQUAL "vmap/runtime/memory.hpp")
    list(APPEND _modes -UVMAP_COMPILED_STACKS)
  endif()
  foreach(mode ${_modes})
    includes_of(list "${_id}" ${_flags} ${mode})
    foreach(heavy ${_heavy} "memory_impl.hpp" "memory_model.hpp")
      string(FIND "${list}" "${heavy}" at)
      if(NOT at EQUAL -1)
        message(FATAL_ERROR "<${h}> (${mode}) includes ${heavy}:\n${list}")
      endif()
    endforeach()
  endforeach()
  message(STATUS "<${h}>: none of the classes that make its values")
endforeach()
# Header-only, AnyMemory's definitions come with it.
string(MAKE_C_IDENTIFIER "vmap/runtime/memory.hpp" _id)
includes_of(list "${_id}" ${_flags})
string(FIND "${list}" "memory_impl.hpp" at)
if(at EQUAL -1)
  message(FATAL_ERROR "<vmap/runtime/memory.hpp> header-only does not include its definitions")
endif()
message(STATUS "<vmap/runtime/memory.hpp>: its definitions only header-only")
