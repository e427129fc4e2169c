# pumptherm_vcan_test(NAME <name> SCENARIO <file> [BINARIES <targets or paths>...]
#                     [FILES <files>...] [TIMEOUT <s>] [OUT_DIR <dir>])
#
# Adds the CTest test vcan.<name> (label "vcan", SKIP_RETURN_CODE 77) that runs SCENARIO with
# tests/vcan/run_vcan_test.sh: natively where the kernel has vcan, otherwise in a QEMU guest.
# BINARIES are CMake targets (their $<TARGET_FILE>, and a dependency) or paths; they land in
# $BIN_DIR with their shared libraries. FILES land in $DATA_DIR. Relative paths are taken from the
# calling CMakeLists.txt's source directory. TIMEOUT (default 300 s) bounds the harness; CTest's
# own timeout is 60 s longer so that the harness reports a hang itself. The guest's base
# initramfs is cached in <build>/tests/vcan-cache. OUT_DIR (relative to the current binary
# directory) receives what the scenario wrote under $OUT_DIR. See docs/testing-vcan.md.
#
# Include this file from any CMakeLists.txt that adds vcan tests.
include_guard(GLOBAL)

set(PUMPTHERM_VCAN_HARNESS "${CMAKE_CURRENT_LIST_DIR}/run_vcan_test.sh")

function(pumptherm_vcan_test)
  cmake_parse_arguments(ARG "" "NAME;SCENARIO;TIMEOUT;OUT_DIR" "BINARIES;FILES" ${ARGN})
  if(ARG_UNPARSED_ARGUMENTS)
    message(FATAL_ERROR "pumptherm_vcan_test: unknown arguments '${ARG_UNPARSED_ARGUMENTS}'")
  endif()
  if(NOT ARG_NAME OR NOT ARG_SCENARIO)
    message(FATAL_ERROR "pumptherm_vcan_test: NAME and SCENARIO are required")
  endif()
  if(NOT ARG_TIMEOUT)
    set(ARG_TIMEOUT 300)
  endif()
  if(NOT ARG_TIMEOUT MATCHES "^[1-9][0-9]*$")
    message(FATAL_ERROR "pumptherm_vcan_test(${ARG_NAME}): TIMEOUT '${ARG_TIMEOUT}' is not whole seconds")
  endif()

  get_filename_component(scenario "${ARG_SCENARIO}" ABSOLUTE BASE_DIR "${CMAKE_CURRENT_SOURCE_DIR}")
  if(NOT EXISTS "${scenario}")
    message(FATAL_ERROR "pumptherm_vcan_test(${ARG_NAME}): SCENARIO '${scenario}' does not exist")
  endif()

  set(args --name "${ARG_NAME}" --timeout "${ARG_TIMEOUT}"
           --cache-dir "${PROJECT_BINARY_DIR}/tests/vcan-cache")
  if(ARG_OUT_DIR)
    get_filename_component(out "${ARG_OUT_DIR}" ABSOLUTE BASE_DIR "${CMAKE_CURRENT_BINARY_DIR}")
    list(APPEND args --out-dir "${out}")
  endif()
  foreach(bin IN LISTS ARG_BINARIES)
    if(TARGET "${bin}")
      list(APPEND args --bin "$<TARGET_FILE:${bin}>")
    else()
      get_filename_component(path "${bin}" ABSOLUTE BASE_DIR "${CMAKE_CURRENT_SOURCE_DIR}")
      list(APPEND args --bin "${path}")
    endif()
  endforeach()
  foreach(file IN LISTS ARG_FILES)
    get_filename_component(path "${file}" ABSOLUTE BASE_DIR "${CMAKE_CURRENT_SOURCE_DIR}")
    list(APPEND args --file "${path}")
  endforeach()

  add_test(NAME vcan.${ARG_NAME}
           COMMAND "${PUMPTHERM_VCAN_HARNESS}" ${args} "${scenario}"
           WORKING_DIRECTORY "${PROJECT_BINARY_DIR}")
  math(EXPR ctest_timeout "${ARG_TIMEOUT} + 60")
  set_tests_properties(vcan.${ARG_NAME} PROPERTIES
    LABELS vcan
    SKIP_RETURN_CODE 77
    TIMEOUT ${ctest_timeout}
    # One QEMU (TCG) keeps one core busy.
    PROCESSORS 1)
endfunction()
