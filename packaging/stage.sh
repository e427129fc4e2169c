#!/bin/sh
# CPack's install command for a Debian package (cmake/PumpthermPackaging.cmake): stages the
# already built tree, without building, into CPack's staging directory ($CMAKE_INSTALL_PREFIX,
# set by CPack) as DESTDIR with prefix /usr.
#   stage.sh BUILD_DIR daemon   pumptherm: component `daemon` stripped, then `deb` (unit, example
#                               configuration, copyright, changelog, operator's guide)
#   stage.sh BUILD_DIR tools    pumptherm-tools: component `tools` stripped, then `tools-deb`
set -eu
: "${CMAKE_INSTALL_PREFIX:?set by CPack to the staging directory}"
case "$2" in
  daemon) extra=deb ;;
  tools) extra=tools-deb ;;
  *) echo "stage.sh: unknown package '$2' (daemon or tools)" >&2; exit 2 ;;
esac
DESTDIR=$CMAKE_INSTALL_PREFIX cmake --install "$1" --prefix /usr --strip --component "$2" >/dev/null
DESTDIR=$CMAKE_INSTALL_PREFIX cmake --install "$1" --prefix /usr --component "$extra" >/dev/null
