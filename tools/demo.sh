#!/usr/bin/env bash
# The main job on the bundled default: builds pumpthermd and runs it offline on the bundled
# candump recording (no kernel CAN needed), printing what it saw per CAN ID.
set -euo pipefail
cd "$(dirname "$0")/.."
cmake -S . -B build -G Ninja -DCMAKE_BUILD_TYPE=RelWithDebInfo >/dev/null
cmake --build build -j "${PUMPTHERM_JOBS:-$(nproc)}" --target pumpthermd
echo
echo "pumpthermd -r tests/data/skeleton.log"
build/daemon/pumpthermd -r tests/data/skeleton.log
