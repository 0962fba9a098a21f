#!/usr/bin/env bash
# The quick end-to-end experiment on an existing build (scripts/quickstart.sh
# installs and builds first, then runs this), with configs/quick.json:
#   1. synthetic HS-D data if missing (out/quick/data), then joint training of
#      the DOE and the U-Net (out/quick/run),
#   2. evaluation on the held-out test scenes against the baselines
#      (out/quick/eval/metrics.json, report.md).
# Extra arguments go to hsd_train (e.g. --resume).
set -euo pipefail
cd "$(dirname "$0")/.."
CFG=configs/quick.json
build/bin/hsd_train --config "$CFG" --out out/quick/run "$@"
build/bin/hsd_eval --config "$CFG" --checkpoint out/quick/run/checkpoints/last.pt --out out/quick/eval
echo "quickstart: done. Test-set numbers against the baselines: out/quick/eval/report.md (metrics.json);"
echo "curves with the baselines drawn: out/quick/run/curves.png, val_psnr.png, val_depth.png;"
echo "reconstructions, depth maps and PSF atlases: out/quick/run/val/ and out/quick/eval/; checkpoint: out/quick/run/checkpoints/last.pt"
