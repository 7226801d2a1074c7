# What the light headers promise, checked with the compiler's own include list (-H):
#   - the options headers need neither OpenCV nor Eigen: they preprocess with vmap's
#     include folder alone, so a file that only configures vmap parses no library;
#   - io/frame_source.hpp in a program linking vmap::stacks (VMAP_COMPILED_STACKS)
#     declares the readers only: OpenCV's videoio, SQLite and the bag readers are not
#     included.
# Run by CTest: cmake -DCXX=... -DINCLUDE_DIR=... -DOPENCV_INCLUDE_DIR=... -P light_headers.cmake
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
          vmap/som/options.hpp vmap/io/frame_source.hpp)
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
