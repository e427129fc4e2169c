#!/bin/sh
# CPack's install command for the Debian package (cmake/PumpthermPackaging.cmake): stages the
# already built tree, without building, into CPack's staging directory ($CMAKE_INSTALL_PREFIX,
# set by CPack) as DESTDIR with prefix /usr: the default component stripped, then the `deb`
# component (unit, example configuration, copyright, changelog).
#   stage.sh BUILD_DIR
set -eu
: "${CMAKE_INSTALL_PREFIX:?set by CPack to the staging directory}"
DESTDIR=$CMAKE_INSTALL_PREFIX cmake --install "$1" --prefix /usr --strip >/dev/null
DESTDIR=$CMAKE_INSTALL_PREFIX cmake --install "$1" --prefix /usr --component deb >/dev/null
