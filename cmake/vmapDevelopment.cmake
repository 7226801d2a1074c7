# Settings for vmap's own tests and examples only; nothing here reaches consumers of
# vmap::vmap (the library sets no global flags).

option(VMAP_WARNINGS_AS_ERRORS "Treat warnings in vmap's own tests and examples as errors" OFF)

set(VMAP_SHARED_DIR "${PROJECT_SOURCE_DIR}/../shared" CACHE PATH
    "Folder with the shared test data (data/) and models (models/)")
# The VMAP_REQUIRE_* options default from the environment so CI can require what the
# tests need while running the README's exact command; absence is then a configure
# error, never a skipped test.
function(vmap_required_option name doc)
  if(DEFINED ENV{${name}} AND "$ENV{${name}}")
    option(${name} "${doc}" ON)
  else()
    option(${name} "${doc}" OFF)
  endif()
endfunction()
vmap_required_option(VMAP_REQUIRE_SHARED_DATA "Fail instead of skipping when VMAP_SHARED_DIR is missing")
# The fleet's tests start a PostgreSQL server of their own (tests/support/pg_server.hpp).
vmap_required_option(VMAP_REQUIRE_POSTGRES "Fail to configure when PostgreSQL's server programs are missing")

get_filename_component(VMAP_SHARED_DIR "${VMAP_SHARED_DIR}" ABSOLUTE)
if(EXISTS "${VMAP_SHARED_DIR}/data" AND EXISTS "${VMAP_SHARED_DIR}/models")
  set(VMAP_HAVE_SHARED_DATA ON)
else()
  set(VMAP_HAVE_SHARED_DATA OFF)
  if(VMAP_REQUIRE_SHARED_DATA)
    message(FATAL_ERROR "VMAP_REQUIRE_SHARED_DATA is ON but ${VMAP_SHARED_DIR} has no data/ and models/. "
                        "Point -DVMAP_SHARED_DIR=... at the shared folder.")
  endif()
  message(STATUS "vmap: ${VMAP_SHARED_DIR} not found: tests on real data and models will be skipped")
endif()

add_library(vmap_dev_flags INTERFACE)
target_compile_options(vmap_dev_flags INTERFACE -Wall -Wextra -Wpedantic -Wshadow -Wnon-virtual-dtor
  $<$<BOOL:${VMAP_WARNINGS_AS_ERRORS}>:-Werror>)
# GCC 12 at -O3 reports std::string's own concatenation, inlined into vmap's functions that
# build messages (Camera::describe, the network loader's output names), as an overlapping
# memcpy (-Wrestrict, GCC bug 105651: a false positive in libstdc++'s code).
if(CMAKE_CXX_COMPILER_ID STREQUAL "GNU")
  target_compile_options(vmap_dev_flags INTERFACE -Wno-restrict)
endif()
