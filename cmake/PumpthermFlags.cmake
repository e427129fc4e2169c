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
endif()
