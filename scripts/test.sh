#!/usr/bin/env bash
# Install packages, build, run every test (Catch2 through ctest).
set -euo pipefail
cd "$(dirname "$0")/.."
bash scripts/setup.sh
bash scripts/build.sh
cd build
ctest --output-on-failure --timeout 600
