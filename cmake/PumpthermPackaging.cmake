# The Debian packages (docs/packaging.md): CPack's DEB generator, run once per package.
#
#   cmake --build build --target deb      -> build/pumptherm_<version>_<arch>.deb        (daemon)
#                                            build/pumptherm-tools_<version>_<arch>.deb  (tools)
#
# As Debian splits a daemon from its tools: `pumptherm` holds the gateway, its unit and the files
# it reads (install component `daemon`); `pumptherm-tools` the `pumptherm` command, the LCM viewer
# and the plant scenarios (component `tools`), whose libraries (Ceres, and through it BLAS, glog)
# a gateway host does not need. The `deb` target builds only what the packages hold, then runs
# CPack. Installed to /usr (the
# unit's ExecStart= names /usr/sbin/pumpthermd; daemon/resources.hpp finds shipped files in
# <exe>/../share/pumptherm). Dependencies are computed by dpkg-shlibdeps from the binaries.
include_guard(GLOBAL)

set(PUMPTHERM_DEBIAN_DIR "${PROJECT_SOURCE_DIR}/packaging/debian")

# The changelog's newest entry must be this version (lintian and dpkg read it).
file(STRINGS "${PUMPTHERM_DEBIAN_DIR}/changelog" pumptherm_changelog_head LIMIT_COUNT 1)
if(NOT pumptherm_changelog_head MATCHES "^pumptherm \\(${PROJECT_VERSION}\\) ")
  message(FATAL_ERROR "packaging/debian/changelog: first entry '${pumptherm_changelog_head}' "
    "is not version ${PROJECT_VERSION} (project() in CMakeLists.txt): add an entry")
endif()

# --- files only the package installs (absolute Debian paths, staged through DESTDIR) ---
# The unit, where packages put units on Debian 12.
install(FILES "${PROJECT_SOURCE_DIR}/systemd/pumpthermd.service"
  DESTINATION /lib/systemd/system COMPONENT deb EXCLUDE_FROM_ALL)
# The example configuration, a conffile. The unit waits for /etc/pumptherm/pumpthermd.toml.
install(FILES "${PROJECT_SOURCE_DIR}/systemd/pumpthermd.toml"
  DESTINATION /etc/pumptherm RENAME pumpthermd.toml.example COMPONENT deb EXCLUDE_FROM_ALL)
# Debian's documentation files: copyright, changelog (native package: changelog.gz).
set(pumptherm_changelog_gz "${PROJECT_BINARY_DIR}/packaging/changelog.gz")
add_custom_command(OUTPUT "${pumptherm_changelog_gz}"
  COMMAND ${CMAKE_COMMAND} -E make_directory "${PROJECT_BINARY_DIR}/packaging"
  COMMAND gzip -n -9 -c "${PUMPTHERM_DEBIAN_DIR}/changelog" > "${pumptherm_changelog_gz}"
  DEPENDS "${PUMPTHERM_DEBIAN_DIR}/changelog"
  COMMENT "gzip packaging/debian/changelog")
install(FILES "${PUMPTHERM_DEBIAN_DIR}/copyright" "${pumptherm_changelog_gz}"
  "${PROJECT_SOURCE_DIR}/docs/operator-guide.md"
  DESTINATION ${CMAKE_INSTALL_DATADIR}/doc/pumptherm COMPONENT deb EXCLUDE_FROM_ALL)
install(FILES "${PUMPTHERM_DEBIAN_DIR}/copyright" "${pumptherm_changelog_gz}"
  DESTINATION ${CMAKE_INSTALL_DATADIR}/doc/pumptherm-tools COMPONENT tools-deb EXCLUDE_FROM_ALL)

# The demo configuration (tools/demo.sh's), for the operator's guide.
install(FILES "${PROJECT_SOURCE_DIR}/tools/demo/pumpthermd-demo.toml"
  DESTINATION ${CMAKE_INSTALL_DATADIR}/pumptherm/examples COMPONENT daemon)

# --- man pages (docs/man), gzipped as Debian wants them; installed with everything else ---
set(PUMPTHERM_MAN_PAGES pumpthermd.8 pumpthermd.toml.5 pumptherm.1 pumptherm-spy.1 pumptherm-lcm-demo.1)
set(pumptherm_man_gz "")
foreach(page IN LISTS PUMPTHERM_MAN_PAGES)
  set(gz "${PROJECT_BINARY_DIR}/man/${page}.gz")
  add_custom_command(OUTPUT "${gz}"
    COMMAND ${CMAKE_COMMAND} -E make_directory "${PROJECT_BINARY_DIR}/man"
    COMMAND gzip -n -9 -c "${PROJECT_SOURCE_DIR}/docs/man/${page}" > "${gz}"
    DEPENDS "${PROJECT_SOURCE_DIR}/docs/man/${page}"
    COMMENT "gzip docs/man/${page}")
  string(REGEX REPLACE "^.*\\.([0-9])$" "\\1" section "${page}")
  # Section 1 pages describe the tools; 5 and 8 the daemon.
  if(section STREQUAL "1")
    set(component tools)
  else()
    set(component daemon)
  endif()
  install(FILES "${gz}" DESTINATION ${CMAKE_INSTALL_MANDIR}/man${section} COMPONENT ${component})
  list(APPEND pumptherm_man_gz "${gz}")
endforeach()
add_custom_target(pumptherm_man_pages ALL DEPENDS ${pumptherm_man_gz})

# --- CPack ---
set(CPACK_GENERATOR DEB)
set(CPACK_PACKAGE_NAME pumptherm)
set(CPACK_PACKAGE_VERSION "${PROJECT_VERSION}")
set(CPACK_PACKAGE_CONTACT "pumptherm maintainers <maintainers@users.noreply.h-seed-20734e4b.example>")
set(CPACK_PACKAGE_DESCRIPTION_SUMMARY "pump motor thermal gateway: CAN telemetry to temperatures and alarms")
set(CPACK_DEBIAN_PACKAGE_DESCRIPTION "pumpthermd sits beside turbo-molecular pump controllers on a CAN
bus and estimates motor temperatures no sensor reaches: the winding
temperature from the stator resistance identified online, and every part
of the motor from a lumped-parameter thermal network with a Kalman filter
fed by one frame sensor. It republishes temperatures and over-temperature
alarms on CAN (DBC) and LCM, as a hardened systemd service. The service
starts only once /etc/pumptherm/pumpthermd.toml exists.
.
The tools (the pumptherm command, pumptherm-spy) are in pumptherm-tools.")
set(CPACK_DEBIAN_PACKAGE_SECTION misc)
set(CPACK_DEBIAN_PACKAGE_PRIORITY optional)
set(CPACK_DEBIAN_FILE_NAME DEB-DEFAULT)        # pumptherm_<version>_<arch>.deb
set(CPACK_PACKAGING_INSTALL_PREFIX /usr)
set(CPACK_DEBIAN_PACKAGE_SHLIBDEPS ON)         # Depends: from the binaries' libraries
set(CPACK_DEBIAN_PACKAGE_GENERATE_SHLIBS OFF)
# The maintainer scripts use deb-systemd-helper/-invoke when present (guarded).
set(CPACK_DEBIAN_PACKAGE_SUGGESTS "pumptherm-tools, can-utils, liblcm-bin")
set(CPACK_DEBIAN_PACKAGE_CONTROL_EXTRA
  "${PUMPTHERM_DEBIAN_DIR}/postinst;${PUMPTHERM_DEBIAN_DIR}/prerm;${PUMPTHERM_DEBIAN_DIR}/postrm;${PUMPTHERM_DEBIAN_DIR}/conffiles")
set(CPACK_DEBIAN_PACKAGE_CONTROL_STRICT_PERMISSION ON)
# CPack's own install step would first build its `preinstall` target, i.e. every target, tests
# included. Instead the `deb` target below builds what the package holds, and CPack stages it with
# `cmake --install` (no build): the default component, then the `deb` component (the files above,
# which a plain `cmake --install` leaves out), stripped, under DESTDIR = CPack's staging dir.
set(CPACK_INSTALL_CMAKE_PROJECTS "")
set(CPACK_INSTALL_COMMANDS "${PROJECT_SOURCE_DIR}/packaging/stage.sh ${PROJECT_BINARY_DIR} daemon")
set(CPACK_OUTPUT_FILE_PREFIX "${PROJECT_BINARY_DIR}")
# The file the `deb` target writes (tests use it).
execute_process(COMMAND dpkg --print-architecture OUTPUT_VARIABLE pumptherm_deb_arch
  OUTPUT_STRIP_TRAILING_WHITESPACE RESULT_VARIABLE pumptherm_dpkg_rc)
if(NOT pumptherm_dpkg_rc EQUAL 0)
  set(pumptherm_deb_arch unknown)
endif()
set(PUMPTHERM_DEB_FILE "${PROJECT_BINARY_DIR}/pumptherm_${PROJECT_VERSION}_${pumptherm_deb_arch}.deb")
set(PUMPTHERM_TOOLS_DEB_FILE "${PROJECT_BINARY_DIR}/pumptherm-tools_${PROJECT_VERSION}_${pumptherm_deb_arch}.deb")
include(CPack)

# pumptherm-tools: the same settings (CPackConfig.cmake, read first) with its own name, text,
# dependencies and staging; no maintainer scripts (it has no service).
file(WRITE "${PROJECT_BINARY_DIR}/CPackConfig-tools.cmake" "include(\"${PROJECT_BINARY_DIR}/CPackConfig.cmake\")
set(CPACK_PACKAGE_NAME pumptherm-tools)
set(CPACK_PACKAGE_FILE_NAME pumptherm-tools-${PROJECT_VERSION}-Linux)
set(CPACK_PACKAGE_DESCRIPTION_SUMMARY \"tools for the pumptherm gateway: DBC, models, simulator, LCM viewer\")
set(CPACK_DEBIAN_PACKAGE_DESCRIPTION \"The pumptherm command beside the pumptherm gateway: DBC check and decode,
resistance identification, thermal model simulation and estimation, sensor
placement, the discrepancy workflow, the plant simulator, plots, the live
table from LCM (pumptherm watch), signed alarm clears; and pumptherm-spy
(lcm-spy with the pumptherm LCM types).\")
set(CPACK_DEBIAN_PACKAGE_DEPENDS \"pumptherm (= ${PROJECT_VERSION})\")
set(CPACK_DEBIAN_PACKAGE_RECOMMENDS \"default-jre | java-runtime, liblcm-java, libjchart2d-java\")
set(CPACK_DEBIAN_PACKAGE_SUGGESTS \"can-utils, liblcm-bin, gnuplot-nox\")
set(CPACK_DEBIAN_PACKAGE_CONTROL_EXTRA \"\")
set(CPACK_INSTALL_COMMANDS \"${PROJECT_SOURCE_DIR}/packaging/stage.sh ${PROJECT_BINARY_DIR} tools\")
")

# `deb`: build what the packages hold (not the tests), then CPack for each.
add_custom_target(deb
  COMMAND ${CMAKE_CPACK_COMMAND} -G DEB --config "${PROJECT_BINARY_DIR}/CPackConfig.cmake"
  COMMAND ${CMAKE_CPACK_COMMAND} -G DEB --config "${PROJECT_BINARY_DIR}/CPackConfig-tools.cmake"
  DEPENDS "${pumptherm_changelog_gz}"
  WORKING_DIRECTORY "${PROJECT_BINARY_DIR}"
  COMMENT "cpack -G DEB: ${PROJECT_BINARY_DIR}/pumptherm{,-tools}_${PROJECT_VERSION}_<arch>.deb"
  USES_TERMINAL)
add_dependencies(deb pumpthermd pumptherm pumptherm_lcm_demo pumptherm_lcm_types_jar pumptherm_spy_plugin_jar
  pumptherm_man_pages)
