#!/usr/bin/env bash
# The main job on defaults, on a fresh Debian 12 machine: install packages,
# build, and run hsd_psf on the paper's configuration (outputs in out/paper_psf/).
set -euo pipefail
cd "$(dirname "$0")/.."
bash scripts/setup.sh
bash scripts/build.sh
build/bin/hsd_psf --config configs/paper.json --out out/paper_psf
echo "quickstart: done; see out/paper_psf/psf_atlas.png and out/paper_psf/psf.pt"
