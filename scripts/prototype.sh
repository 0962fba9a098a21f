#!/usr/bin/env bash
# The simulated-prototype round trip (docs/camera.md, "From simulation to a real
# camera"): what a researcher does with a real camera, with the fab and the
# lab bench simulated.
#   1. a learned DOE and its network: the quick config trained end to end
#      (IDEAL_CHECKPOINT=path reuses one, e.g. out/quick/run/checkpoints/last.pt);
#   2. the DOE "fabricated" with errors (fabrication.error below) and its
#      point-source captures made with noise, background, a dark frame and hot
#      pixels (hsd_calibrate --make-captures), twice with independent noise;
#   3. the captures calibrated into a measured PSF stack (hsd_calibrate),
#      compared with the truth and with the repeat capture (is what is left noise?);
#   4. the network fine-tuned on the measured PSFs (optics.psf_source =
#      file:..., train.init_checkpoint), beside two controls with the same
#      steps: fine-tuned on the design's PSFs (more steps, no new optics) and on
#      the fabricated DOE's true PSFs (the best calibration could give);
#   5. every network evaluated on the test split imaged through the fabricated
#      DOE's true PSFs (hsd_eval --camera-psf), also the ideal network with only
#      its Wiener pre-inversion switched to the measured PSFs (no retraining),
#      and the summary table printed.
# Needs a build (bash scripts/build.sh). Outputs in OUT (default out/prototype).
set -euo pipefail
cd "$(dirname "$0")/.."
CFG=${CONFIG:-configs/quick.json}
OUT=${OUT:-out/prototype}
STEPS=${FINETUNE_STEPS:-500}
B=build/bin
# The fab's errors (docs/camera.md: a mild and a severe level were measured).
FAB=(--set fabrication.error.height_scale_error=${FAB_SCALE:-0.05} --set fabrication.error.roughness_rms_m=${FAB_ROUGHNESS_M:-2e-8}
     --set fabrication.error.roughness_correlation_m=${FAB_CORRELATION_M:-1.6e-5} --set fabrication.error.edge_blur_m=${FAB_BLUR_M:-4e-6})
IDEAL=${IDEAL_CHECKPOINT:-$OUT/ideal/checkpoints/last.pt}
if [ ! -f "$IDEAL" ]; then
  echo "prototype: 1/5 training the ideal system ($CFG) into $OUT/ideal"
  $B/hsd_train --config "$CFG" --out "$OUT/ideal"
fi
DOE=(--set "optics.doe.init=file:$IDEAL")
TRUTH=$OUT/captures/truth_psf.pt
echo "prototype: 2/5 fabricating the DOE with errors and capturing its PSFs"
$B/hsd_calibrate --config "$CFG" "${DOE[@]}" "${FAB[@]}" --make-captures --out "$OUT/captures"
$B/hsd_calibrate --config "$CFG" "${DOE[@]}" "${FAB[@]}" --set calibration.synthetic.seed=1 --make-captures --out "$OUT/captures_repeat"
echo "prototype: 3/5 calibrating"
$B/hsd_calibrate --config "$CFG" "${DOE[@]}" --captures "$OUT/captures" --reference "$TRUTH" --out "$OUT/calibrated"
$B/hsd_calibrate --config "$CFG" "${DOE[@]}" --captures "$OUT/captures_repeat" --reference "$OUT/calibrated/psf.pt" --out "$OUT/calibrated_repeat"
echo "prototype: 4/5 fine-tuning ($STEPS steps each)"
TUNE=(--set train.init_checkpoint="$IDEAL" --set train.steps=$STEPS --set train.lr_net=5e-4)
finetune() {  # name, then config overrides
  local name=$1; shift
  [ -f "$OUT/$name/checkpoints/last.pt" ] || $B/hsd_train --config "$CFG" "${DOE[@]}" "${TUNE[@]}" "$@" --out "$OUT/$name"
}
finetune finetune_measured --set "optics.psf_source=file:$OUT/calibrated/psf.pt"
finetune finetune_design --set train.freeze_doe=true
finetune finetune_truth --set "optics.psf_source=file:$TRUTH"
echo "prototype: 5/5 evaluating through the fabricated DOE"
$B/hsd_eval --config "$CFG" --checkpoint "$IDEAL" --out "$OUT/eval/ideal_through_design"
$B/hsd_eval --config "$CFG" --checkpoint "$IDEAL" --camera-psf "$TRUTH" --out "$OUT/eval/ideal_through_fabricated"
# The same network, its Wiener pre-inversion given the measured PSFs: calibration without retraining.
$B/hsd_eval --config "$CFG" --set "optics.psf_source=file:$OUT/calibrated/psf.pt" --checkpoint "$IDEAL" --camera-psf "$TRUTH" \
  --out "$OUT/eval/ideal_measured_preinverse_through_fabricated"
for name in finetune_measured finetune_design finetune_truth; do
  $B/hsd_eval --config "$OUT/$name/config.json" --checkpoint "$OUT/$name/checkpoints/last.pt" --camera-psf "$TRUTH" \
    --out "$OUT/eval/${name}_through_fabricated"
done
num() { grep -o "\"$2\": *[-0-9.e+]*" "$1" | head -1 | sed 's/.*: *//'; }
printf '\nprototype: PSFs: fabricated vs design rel. L1 %s (mean); calibrated vs true %s; repeat capture vs first %s\n' \
  "$(num "$OUT/calibrated/mismatch.json" rel_l1_mean)" "$(num "$OUT/calibrated/mismatch.json" reference_rel_l1_mean)" \
  "$(num "$OUT/calibrated_repeat/mismatch.json" reference_rel_l1_mean)"
printf '%-52s %10s %10s %10s %12s %10s\n' "test split, imaged through" "HS PSNR" "upsampl." "Wiener" "depth RMSE" "constant"
for e in ideal_through_design ideal_through_fabricated ideal_measured_preinverse_through_fabricated finetune_design_through_fabricated finetune_measured_through_fabricated finetune_truth_through_fabricated; do
  m=$OUT/eval/$e/metrics.json
  printf '%-52s %10.2f %10.2f %10.2f %12.4f %10.4f\n' "$e" "$(num "$m" hs_psnr_db)" "$(num "$m" baseline_upsampling_hs_psnr_db)" \
    "$(num "$m" baseline_wiener_hs_psnr_db)" "$(num "$m" depth_rmse_m)" "$(num "$m" baseline_constant_depth_rmse_m)"
done
