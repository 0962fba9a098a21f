#!/usr/bin/env bash
# The main job on defaults, on a fresh Debian 12 machine: install packages,
# build, and run the quick end-to-end experiment (scripts/quick_job.sh:
# configs/quick.json, data if missing, joint training, evaluation against the
# baselines; out/quick/{data,run,eval}). Extra arguments go to hsd_train
# (e.g. --resume).
set -euo pipefail
cd "$(dirname "$0")/.."
bash scripts/setup.sh
bash scripts/build.sh
bash scripts/quick_job.sh "$@"
