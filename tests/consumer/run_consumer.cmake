# Configures, builds and runs a separate project that uses vmap: either vmap's build
# tree installed into a scratch prefix and found with find_package(vmap), or (with
# VMAP_SOURCE_DIR) vmap's source tree added as its subfolder. Any failure fails the test.
file(REMOVE_RECURSE "${WORK_DIR}")
set(prefix "${WORK_DIR}/prefix")
function(run)
  execute_process(COMMAND ${ARGV} RESULT_VARIABLE rc OUTPUT_VARIABLE out ERROR_VARIABLE err)
  if(NOT rc EQUAL 0)
    message(FATAL_ERROR "command failed (${rc}): ${ARGV}\n${out}\n${err}")
  endif()
  message(STATUS "${out}")
endfunction()
if(VMAP_SOURCE_DIR)
  # vmap's source tree as a subfolder of the consumer (add_subdirectory). vmap's own
  # targets are then compiled by this build, with no optimisation: what is checked is
  # that the targets are there and link, not the speed of the program.
  run(${CMAKE_COMMAND} -S "${CONSUMER_SOURCE_DIR}" -B "${WORK_DIR}/build" -G "${GENERATOR}"
      "-DVMAP_SOURCE_DIR=${VMAP_SOURCE_DIR}" -DCMAKE_BUILD_TYPE=)
else()
  run(${CMAKE_COMMAND} --install "${VMAP_BUILD_DIR}" --prefix "${prefix}")
  run(${CMAKE_COMMAND} -S "${CONSUMER_SOURCE_DIR}" -B "${WORK_DIR}/build" -G "${GENERATOR}"
      "-DCMAKE_PREFIX_PATH=${prefix}" -DCMAKE_BUILD_TYPE=Release)
endif()
run(${CMAKE_COMMAND} --build "${WORK_DIR}/build")
run("${WORK_DIR}/build/vmap_consumer" "${SAMPLE_FRAMES}" "${WORK_DIR}/map.vmap")
if(EXISTS "${WORK_DIR}/build/vmap_consumer_stacks")
  run("${WORK_DIR}/build/vmap_consumer_stacks" "${SAMPLE_FRAMES}" "${WORK_DIR}/stacks.vmdb")
  # The memory of the sample frames, asked where its 31st frame was taken.
  get_filename_component(sample_dir "${SAMPLE_FRAMES}" DIRECTORY)
  file(GLOB images "${sample_dir}/rgb/*.jpg")
  list(SORT images)
  list(GET images 30 query)
  run("${WORK_DIR}/build/vmap_consumer_light" "${SAMPLE_FRAMES}" "${query}")
elseif(VMAP_STACKS)
  message(FATAL_ERROR "the installed package has no vmap::stacks component (find_package(vmap COMPONENTS stacks))")
endif()
if(EXISTS "${WORK_DIR}/build/vmap_consumer_bags")
  run("${WORK_DIR}/build/vmap_consumer_bags" "${WORK_DIR}/frames.mcap")
  run("${WORK_DIR}/build/vmap_consumer_no_bags" "${WORK_DIR}/frames.mcap")
elseif(VMAP_BAGS)
  message(FATAL_ERROR "the installed package has no vmap::bags component (find_package(vmap COMPONENTS bags))")
endif()
# The Python package, when the build made one: installed beside the headers, it imports
# from the prefix (the extension, its stubs and py.typed) and reads the sample frames.
if(PYTHON_EXECUTABLE AND PYTHON_INSTALL_DIR AND NOT VMAP_SOURCE_DIR)
  foreach(_f __init__.py __init__.pyi py.typed)
    if(NOT EXISTS "${prefix}/${PYTHON_INSTALL_DIR}/vmap/${_f}")
      message(FATAL_ERROR "cmake --install did not put vmap/${_f} in ${prefix}/${PYTHON_INSTALL_DIR}")
    endif()
  endforeach()
  # Newlines, not semicolons, between the statements: run() passes its arguments on as a
  # CMake list, which a semicolon would split.
  run(${CMAKE_COMMAND} -E env "PYTHONPATH=${prefix}/${PYTHON_INSTALL_DIR}" "${PYTHON_EXECUTABLE}" -c
      "import sys, vmap\nm = vmap.VisualMemory()\nfor image, _, _ in vmap.frames(sys.argv[1], grey=True):\n    m.push(image)\nassert vmap.__file__.startswith(sys.argv[2]) and m.key_images > 5, m\nprint('installed module:', vmap.__file__, m)"
      "${SAMPLE_FRAMES}" "${prefix}")
endif()
