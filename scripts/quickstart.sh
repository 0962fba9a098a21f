#!/usr/bin/env bash
# The main job on defaults, on a fresh Debian 12 machine: install packages,
# build, and run the quick end-to-end experiment: generate synthetic HS-D data
# if missing (out/quick/data), then train the DOE and the U-Net jointly with
# configs/quick.json (outputs in out/quick/run). Extra arguments go to
# hsd_train (e.g. --resume, or --set train.steps=600).
set -euo pipefail
cd "$(dirname "$0")/.."
bash scripts/setup.sh
bash scripts/build.sh
build/bin/hsd_train --config configs/quick.json --out out/quick/run "$@"
echo "quickstart: done. Curves: out/quick/run/curves.png and val_psnr.png; metrics: out/quick/run/metrics.csv;"
echo "reconstructions, depth maps, error maps and PSF atlases: out/quick/run/val/; checkpoint: out/quick/run/checkpoints/last.pt"
