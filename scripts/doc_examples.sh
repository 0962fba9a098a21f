#!/usr/bin/env bash
# Runs the documentation's examples, so they cannot rot: every fenced ```sh
# block of README.md and docs/*.md that calls build/bin/ or a script of
# scripts/ (other than set-up, build and test) runs as written, on tiny
# versions of the shipped configs.
#
#   bash scripts/doc_examples.sh [BUILD_DIR] [WORK_DIR] [PAGE_PATTERN]
#
# BUILD_DIR defaults to build/ (its bin/ holds the apps); WORK_DIR to a new
# temporary folder (kept on failure, removed on success); PAGE_PATTERN (an
# extended regular expression, e.g. 'fabrication|data') runs only the pages
# whose path matches it.
#
# How: WORK_DIR/start is a stand-in for the repository root, with build/ and
# data/ linked, scripts/ copied, and configs/X.json for every shipped config
# replaced by {"extends": "<repo>/configs/X.json", <TINY>}: the same keys, on
# 3 bands, 2 depths, a 64-sample DOE, 4 training steps of 16-px patches and a
# width-4 network (TINY below). In it the README's first command's job
# (scripts/quick_job.sh) runs once, so out/quick/{data,run,eval} exist as
# they do after it. Each page then runs in its own copy of that folder: its
# blocks in order, in one bash session (set -euo pipefail), so a block may use
# an earlier block's files and variables, never another page's. Blocks without
# build/bin/ or such a script (setting up, building) are not run. Two
# rewrites: a --set train.steps=N in an example is cut to the tiny configs' 4
# steps, and so are scripts/prototype.sh's fine-tuning steps (FINETUNE_STEPS).
set -euo pipefail
root=$(cd "$(dirname "$0")/.." && pwd)
build=$(cd "${1:-$root/build}" && pwd)
work=${2:-$(mktemp -d /tmp/hsd_doc_examples.XXXXXX)}
only=${3:-}
mkdir -p "$work"
[ -x "$build/bin/hsd_train" ] || { echo "doc_examples: $build/bin/hsd_train: not built" >&2; exit 2; }

TINY='"optics": {"wavelengths_nm": [450, 550, 650], "depths_m": [0.5, 1.5], "aperture_diameter_m": 0.0005,
             "doe_pitch_m": 8e-06, "doe_samples": 64, "psf_size": 15, "pixel_pitch_m": 1.2e-05},
  "fisher": {"steps": 2, "design_samples": 64, "window_px": 15, "zernike_modes": 10, "scene_patch_px": 16},
  "model": {"base_width": 4, "levels": 2},
  "train": {"steps": 4, "batch_size": 2, "warmup_steps": 1, "val_every": 1000, "val_patches": 2,
            "checkpoint_every": 1000, "log_every": 100},
  "data": {"patch_size_px": 16, "render_margin_px": 0,
           "generator": {"train_scenes": 2, "val_scenes": 1, "test_scenes": 1, "width_px": 48, "height_px": 40}},
  "fabrication": {"tolerance": {"draws": 1, "subsamples": 1, "height_scale_error": [0, 0.1],
                                "roughness_rms_m": [0, 2e-08], "misalignment_m": [0, 2e-06],
                                "edge_blur_m": [0, 4e-06], "decentre_m": [0, 2e-05]}},
  "calibration": {"synthetic": {"exposures": 1}}'

start=$work/start
rm -rf "$start"
mkdir -p "$start/configs"
ln -s "$build" "$start/build"
ln -s "$root/data" "$start/data"
cp -r "$root/scripts" "$start/scripts"
for c in "$root"/configs/*.json; do
  printf '{"extends": "%s",\n  %s\n}\n' "$c" "$TINY" > "$start/configs/$(basename "$c")"
done

say() { printf 'doc_examples: %s\n' "$*"; }
t0=$SECONDS
say "the README's first command's job, tiny (scripts/quick_job.sh) in $start"
if ! (cd "$start" && bash scripts/quick_job.sh > "$work/quick_job.log" 2>&1); then
  say "FAILED: scripts/quick_job.sh; the end of $work/quick_job.log:"
  tail -20 "$work/quick_job.log"
  exit 1
fi

# Prints the ```sh blocks of $1 that call build/bin/ or one of the project's
# scripts (except setup, build, test and quickstart), in order.
sh_blocks() {
  awk '
    /^[ \t]*```sh[ \t]*$/ { inblock = 1; block = ""; next }
    /^[ \t]*```/ && inblock {
      inblock = 0
      runs_app = block ~ /build\/bin\//
      # the scripts of scripts/ too, except those that install, build or test
      runs_script = block ~ /scripts\/[a-z_]+\.sh/ && block !~ /scripts\/(setup|build|test|quickstart|doc_examples)\.sh/
      if (runs_app || runs_script) printf "%s", block
      next
    }
    inblock { sub(/^  /, ""); block = block $0 "\n" }
  ' "$1"
}

pages=("$root/README.md")
for p in "$root"/docs/*.md; do pages+=("$p"); done
failed=0
ran=0
for page in "${pages[@]}"; do
  rel=${page#"$root"/}
  if [ -n "$only" ] && ! echo "$rel" | grep -Eq "$only"; then continue; fi
  script=$(sh_blocks "$page")
  [ -n "$script" ] || continue
  name=$(echo "$rel" | tr '/.' '__')
  dir=$work/$name
  rm -rf "$dir"
  cp -a "$start" "$dir"
  # Steps asked for with --set train.steps=N are cut to the tiny configs' 4.
  script=$(printf '%s\n' "$script" | sed -E 's/train\.steps=[0-9]+/train.steps=4/g')
  # The log shows each command with the seconds since the page started.
  # scripts/prototype.sh's fine-tuning steps are cut the same way.
  printf 'set -euo pipefail\nexport FINETUNE_STEPS=4\nPS4='"'"'+ [${SECONDS}s] '"'"'\nset -x\n%s\n' "$script" > "$work/$name.sh"
  n=$(grep -cE 'build/bin/|scripts/[a-z_]+\.sh' "$work/$name.sh" || true)
  t=$SECONDS
  if (cd "$dir" && bash "$work/$name.sh" > "$work/$name.log" 2>&1); then
    say "$rel: $n commands ran ($((SECONDS - t)) s)"
    ran=$((ran + n))
  else
    say "FAILED: $rel (script $work/$name.sh, run in $dir); the end of $work/$name.log:"
    tail -20 "$work/$name.log"
    failed=1
  fi
done
if [ "$failed" -ne 0 ]; then
  say "some examples failed; work folder kept: $work"
  exit 1
fi
say "all examples ran: $ran commands on ${#pages[@]} pages in $((SECONDS - t0)) s"
[ -n "${2:-}" ] || rm -rf "$work"
