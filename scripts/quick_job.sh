#!/usr/bin/env bash
# The quick end-to-end experiment on an existing build (scripts/quickstart.sh
# installs and builds first, then runs this), with configs/quick.json:
#   1. synthetic HS-D data if missing (out/quick/data), then joint training of
#      the DOE and the U-Net (out/quick/run),
#   2. evaluation on the held-out test scenes against the baselines
#      (out/quick/eval/metrics.json, report.md).
# Extra arguments go to hsd_train (e.g. --resume).
#
# Training runs as local data-parallel ranks (scripts/launch_distributed.sh)
# on a machine with 2 or more cores: 2 ranks of one thread each step faster
# than one process with both threads, whose small operations gain almost
# nothing from the second thread (docs/benchmarks.md, "hsd_bench dist"), and
# the run is one process's up to float rounding (docs/training.md, "What a
# step means with W ranks"). HSD_QUICK_RANKS=1 trains in one process;
# HSD_QUICK_RANKS=N uses N ranks (N must divide the batch of 4).
set -euo pipefail
cd "$(dirname "$0")/.."
CFG=configs/quick.json
ranks=${HSD_QUICK_RANKS:-}
if [ -z "$ranks" ]; then
  ranks=1
  [ "$(nproc 2>/dev/null || echo 1)" -ge 2 ] && ranks=2
fi
if ! [[ "$ranks" =~ ^[1-9][0-9]*$ ]]; then
  echo "quick_job: error: HSD_QUICK_RANKS must be a positive integer (got '$ranks')" >&2
  exit 2
fi
if [ "$ranks" -gt 1 ]; then
  bash scripts/launch_distributed.sh --nproc "$ranks" -- --config "$CFG" --out out/quick/run "$@"
else
  build/bin/hsd_train --config "$CFG" --out out/quick/run "$@"
fi
build/bin/hsd_eval --config "$CFG" --checkpoint out/quick/run/checkpoints/last.pt --out out/quick/eval
echo "quickstart: done. Test-set numbers against the baselines: out/quick/eval/report.md (metrics.json);"
echo "curves with the baselines drawn: out/quick/run/curves.png, val_psnr.png, val_depth.png;"
echo "reconstructions, depth maps and PSF atlases: out/quick/run/val/ and out/quick/eval/; checkpoint: out/quick/run/checkpoints/last.pt"
