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
include(${CMAKE_CURRENT_LIST_DIR}/../guest/PumpthermGuest.cmake)

set(PUMPTHERM_VCAN_HARNESS "${CMAKE_CURRENT_LIST_DIR}/run_vcan_test.sh")

function(pumptherm_vcan_test)
  cmake_parse_arguments(ARG "" "NAME;SCENARIO;TIMEOUT;OUT_DIR" "BINARIES;FILES" ${ARGN})
  if(ARG_UNPARSED_ARGUMENTS)
    message(FATAL_ERROR "pumptherm_vcan_test: unknown arguments '${ARG_UNPARSED_ARGUMENTS}'")
  endif()
  pumptherm_guest_test_args(pumptherm_vcan_test 300 args scenario timeout ${ARGN})
  list(APPEND args --cache-dir "${PROJECT_BINARY_DIR}/tests/vcan-cache")
  if(ARG_OUT_DIR)
    get_filename_component(out "${ARG_OUT_DIR}" ABSOLUTE BASE_DIR "${CMAKE_CURRENT_BINARY_DIR}")
    list(APPEND args --out-dir "${out}")
  endif()

  add_test(NAME vcan.${ARG_NAME}
           COMMAND "${PUMPTHERM_VCAN_HARNESS}" ${args} "${scenario}"
           WORKING_DIRECTORY "${PROJECT_BINARY_DIR}")
  math(EXPR ctest_timeout "${timeout} + 60")
  set_tests_properties(vcan.${ARG_NAME} PROPERTIES
    LABELS vcan
    SKIP_RETURN_CODE 77
    TIMEOUT ${ctest_timeout}
    # One QEMU (TCG) keeps one core busy.
    PROCESSORS 1)
endfunction()
