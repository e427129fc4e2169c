# pumptherm_system_test(NAME <name> SCENARIO <file> [BINARIES <targets or paths>...]
#                       [UNITS <unit files>...] [FILES <files>...] [TIMEOUT <s>] [NO_VCAN])
#
# Adds the CTest test system.<name> (label "system", SKIP_RETURN_CODE 77) that runs SCENARIO as
# root in a Debian 12 guest with systemd (tests/system/run_system_test.sh, QEMU TCG).
# BINARIES are CMake targets (their $<TARGET_FILE>; CTest does not build them: build first) or
# paths; each is installed where an ExecStart= of one of the UNITS names a program of its name
# (/usr/sbin/pumpthermd for systemd/pumpthermd.service), else in /usr/local/bin; shared libraries
# the guest lacks go with it. UNITS are installed in /etc/systemd/system. FILES land in
# $DATA_DIR. Relative paths are taken from the calling CMakeLists.txt's source directory. vcan0
# is created before the scenario unless NO_VCAN. What the scenario writes to $OUT_DIR comes back
# to <build>/tests/system-out/<name>/. TIMEOUT (default 600 s) bounds one guest run; CTest's own
# timeout is 60 s longer so that the harness reports a hang itself.
#
# The cached base image (debootstrap, built once, needs root) is made by the fixture test
# system.base_image that every system test requires, so that its few minutes do not count against
# a test's TIMEOUT. See docs/testing-system.md.
include_guard(GLOBAL)
include(${CMAKE_CURRENT_LIST_DIR}/../guest/PumpthermGuest.cmake)

# A cache variable, so that pumptherm_system_test() works from any directory (include_guard).
set(PUMPTHERM_SYSTEM_HARNESS "${CMAKE_CURRENT_LIST_DIR}/run_system_test.sh" CACHE INTERNAL "system test harness")

# The fixture: finds or builds the base image (debootstrap + mke2fs; a few minutes, once).
add_test(NAME system.base_image
         COMMAND "${PUMPTHERM_SYSTEM_HARNESS}" --build-base
         WORKING_DIRECTORY "${PROJECT_BINARY_DIR}")
set_tests_properties(system.base_image PROPERTIES
  LABELS system
  SKIP_RETURN_CODE 77
  TIMEOUT 1800
  FIXTURES_SETUP pumptherm_system_base
  PROCESSORS 1)

function(pumptherm_system_test)
  cmake_parse_arguments(ARG "NO_VCAN" "NAME;SCENARIO;TIMEOUT" "BINARIES;UNITS;FILES" ${ARGN})
  if(ARG_UNPARSED_ARGUMENTS)
    message(FATAL_ERROR "pumptherm_system_test: unknown arguments '${ARG_UNPARSED_ARGUMENTS}'")
  endif()
  pumptherm_guest_test_args(pumptherm_system_test 600 args scenario timeout ${ARGN})
  list(APPEND args --out-dir "${PROJECT_BINARY_DIR}/tests/system-out/${ARG_NAME}")
  if(ARG_NO_VCAN)
    list(APPEND args --no-vcan)
  endif()
  foreach(unit IN LISTS ARG_UNITS)
    get_filename_component(path "${unit}" ABSOLUTE BASE_DIR "${CMAKE_CURRENT_SOURCE_DIR}")
    if(NOT EXISTS "${path}")
      message(FATAL_ERROR "pumptherm_system_test(${ARG_NAME}): unit '${path}' does not exist")
    endif()
    list(APPEND args --unit "${path}")
  endforeach()

  add_test(NAME system.${ARG_NAME}
           COMMAND "${PUMPTHERM_SYSTEM_HARNESS}" ${args} "${scenario}"
           WORKING_DIRECTORY "${PROJECT_BINARY_DIR}")
  math(EXPR ctest_timeout "${timeout} + 60")
  set_tests_properties(system.${ARG_NAME} PROPERTIES
    LABELS system
    SKIP_RETURN_CODE 77
    TIMEOUT ${ctest_timeout}
    FIXTURES_REQUIRED pumptherm_system_base
    # One QEMU (TCG) keeps one core busy.
    PROCESSORS 1)
endfunction()
