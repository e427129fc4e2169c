# What the vcan and system test functions (tests/vcan/PumpthermVcan.cmake,
# tests/system/PumpthermSystem.cmake) share: checking their arguments and the harness arguments
# built from them. Their harnesses share tests/guest/guest_run.sh.
include_guard(GLOBAL)

# pumptherm_guest_test_args(<function name> <default timeout s> <args var> <scenario var>
#                           <timeout var> <function's own ARGN>)
# Parses NAME, SCENARIO, TIMEOUT, BINARIES and FILES out of the ARGN of a test function, fails
# the configuration naming the function and test for a missing NAME or SCENARIO, a TIMEOUT that
# is not whole seconds or a SCENARIO that does not exist, and sets in the caller:
#   <args var>     --name, --timeout, --bin (a target's file, or a path) and --file arguments
#   <scenario var> the scenario's absolute path
#   <timeout var>  the timeout in seconds
# Relative paths are taken from the calling CMakeLists.txt's source directory. The keywords only
# one of the functions has (OUT_DIR; UNITS, NO_VCAN) are parsed here too, so that their values do
# not run into BINARIES or FILES, and left to that function.
function(pumptherm_guest_test_args fn default_timeout args_var scenario_var timeout_var)
  cmake_parse_arguments(ARG "NO_VCAN" "NAME;SCENARIO;TIMEOUT;OUT_DIR" "BINARIES;FILES;UNITS" ${ARGN})
  if(NOT ARG_NAME OR NOT ARG_SCENARIO)
    message(FATAL_ERROR "${fn}: NAME and SCENARIO are required")
  endif()
  if(NOT ARG_TIMEOUT)
    set(ARG_TIMEOUT ${default_timeout})
  endif()
  if(NOT ARG_TIMEOUT MATCHES "^[1-9][0-9]*$")
    message(FATAL_ERROR "${fn}(${ARG_NAME}): TIMEOUT '${ARG_TIMEOUT}' is not whole seconds")
  endif()
  get_filename_component(scenario "${ARG_SCENARIO}" ABSOLUTE BASE_DIR "${CMAKE_CURRENT_SOURCE_DIR}")
  if(NOT EXISTS "${scenario}")
    message(FATAL_ERROR "${fn}(${ARG_NAME}): SCENARIO '${scenario}' does not exist")
  endif()
  set(args --name "${ARG_NAME}" --timeout "${ARG_TIMEOUT}")
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
  set(${args_var} "${args}" PARENT_SCOPE)
  set(${scenario_var} "${scenario}" PARENT_SCOPE)
  set(${timeout_var} "${ARG_TIMEOUT}" PARENT_SCOPE)
endfunction()
