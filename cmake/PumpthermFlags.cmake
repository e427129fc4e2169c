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
    # One build for the sanitized unit tests and the fuzz targets (tools/test-all.sh): every
    # source also carries libFuzzer's coverage instrumentation, so the fuzz targets link the
    # libraries as they are instead of instrumented copies (tests/fuzz/CMakeLists.txt). The unit
    # tests do not link libFuzzer; the sanitizer runtime has no-op defaults for its callbacks.
    add_compile_options(-fsanitize=fuzzer-no-link)
  endif()
endif()
