# Target-scoped compiler flags for pumptherm's own targets.
function(pumptherm_target_flags target)
  target_compile_options(${target} PRIVATE -Wall -Wextra -Wpedantic -Wshadow -Wnon-virtual-dtor)
  if(PUMPTHERM_WERROR)
    target_compile_options(${target} PRIVATE -Werror)
  endif()
endfunction()

if(PUMPTHERM_SANITIZE)
  # Applied to the whole build so that libraries and tests agree on the runtime.
  # vptr: GCC 12 reports a false positive on LCM 1.3's dispatch to subscribed handler methods
  # (docs/lcm.md); every other UBSan check stays on.
  add_compile_options(-fsanitize=address,undefined -fno-sanitize=vptr -fno-omit-frame-pointer
                      -fno-sanitize-recover=undefined)
  add_link_options(-fsanitize=address,undefined)
  if(PUMPTHERM_FUZZ AND CMAKE_CXX_COMPILER_ID MATCHES "Clang")
    # One build for the sanitized unit tests and the fuzz targets (tools/test-all.sh): the
    # libraries a fuzz target links also carry libFuzzer's coverage instrumentation
    # (pumptherm_fuzz_coverage below), so the fuzz targets link the libraries as they are instead
    # of instrumented copies (tests/fuzz/CMakeLists.txt). The unit tests link the same libraries
    # but not libFuzzer; the sanitizer runtime has no-op defaults for its callbacks.
    set(PUMPTHERM_FUZZ_COVERAGE_OPTIONS -fsanitize=fuzzer-no-link)
  endif()
endif()

# pumptherm_fuzz_coverage(): in the sanitizer + fuzz build, libFuzzer's coverage instrumentation
# for every target this directory (and its subdirectories) defines after the call. Called by the
# directories of the libraries the fuzz targets link (protocol, estimators, shipped, daemon,
# tools/common); the fuzz targets' own sources get it from -fsanitize=fuzzer. Sources no fuzz
# target links (the unit tests, the CLI) are left without it: it makes their compiles and the
# sanitized tests slower and gives libFuzzer nothing (docs/testing.md, "Compile time").
macro(pumptherm_fuzz_coverage)
  if(PUMPTHERM_FUZZ_COVERAGE_OPTIONS)
    add_compile_options(${PUMPTHERM_FUZZ_COVERAGE_OPTIONS})
  endif()
endmacro()
