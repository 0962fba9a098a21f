#!/usr/bin/env bash
# Configures and builds hsd into build/ (Release, Ninja, precompiled torch header).
set -euo pipefail
cd "$(dirname "$0")/.."
cmake -S . -B build -G Ninja -DCMAKE_BUILD_TYPE=Release > build.log 2>&1 || { cat build.log; exit 1; }
cmake --build build -j "${HSD_BUILD_JOBS:-$(nproc)}"
rm -f build.log
