# Helpers shared by every module's CMakeLists.txt.

# omnirig_library(NAME SOURCES ... DEPS ...): a static library whose includes are rooted at
# the repository root (#include "engine/geometry/rigid3.h").
function(omnirig_library name)
  cmake_parse_arguments(ARG "" "" "SOURCES;DEPS" ${ARGN})
  add_library(${name} STATIC ${ARG_SOURCES})
  target_include_directories(${name} PUBLIC ${PROJECT_SOURCE_DIR})
  target_link_libraries(${name} PUBLIC ${ARG_DEPS})
endfunction()

# omnirig_test(MODULE NAME SOURCES ... DEPS ... [LABELS ...]): a GoogleTest executable
# registered with ctest as MODULE/NAME. Labels: "unit" (the default: fast, also run in the
# sanitizer build) or "integration" (renders, end-to-end runs, servers: Release build only).
function(omnirig_test module name)
  if(NOT OMNIRIG_BUILD_TESTS)
    return()
  endif()
  cmake_parse_arguments(ARG "" "TIMEOUT" "SOURCES;DEPS;LABELS" ${ARGN})
  # The sanitizer build runs the unit tests only; skip building the rest there.
  if(OMNIRIG_SANITIZE AND "integration" IN_LIST ARG_LABELS)
    return()
  endif()
  string(REPLACE "/" "_" target "${module}_${name}_test")
  add_executable(${target} ${ARG_SOURCES})
  target_link_libraries(${target} PRIVATE ${ARG_DEPS} GTest::gtest GTest::gtest_main)
  add_test(NAME ${module}/${name} COMMAND ${target})
  if(NOT ARG_LABELS)
    set(ARG_LABELS unit)
  endif()
  if(NOT ARG_TIMEOUT)
    set(ARG_TIMEOUT 600)
  endif()
  set_tests_properties(${module}/${name} PROPERTIES LABELS "${ARG_LABELS}" TIMEOUT ${ARG_TIMEOUT}
    ENVIRONMENT "OMNIRIG_SOURCE_DIR=${PROJECT_SOURCE_DIR};OMNIRIG_BINARY_DIR=${PROJECT_BINARY_DIR}")
endfunction()
