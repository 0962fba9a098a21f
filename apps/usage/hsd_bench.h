// hsd_bench --help: shared by the app and its launcher (apps/launcher.cpp),
// which prints it without loading LibTorch.
#pragma once

namespace hsd::usage {

inline constexpr const char* kText =
    "hsd_bench NAME [--json] [--config FILE] [--set key=VALUE ...] [--threads N] [--repeats K]\n"
    "  NAME: psf   time, peak memory and accuracy of the config's whole PSF stack\n"
    "              (forward, forward+backward), with the FFT+bilinear baseline\n"
    "              and point-sampled pixels side by side (--no-baseline skips it)\n"
    "  NAME: sim   forward+backward of PSF + sensor image formation on one patch,\n"
    "              with the straightforward baseline and the floor of bare GEMMs/FFTs;\n"
    "              --patch 256 --bands 25 --depths 7 --psf 63 --pupil 512 set the work\n"
    "  NAME: data  the data path: scene generation, loading with 1 and N threads,\n"
    "              the patch sampler and patch extraction (--scenes 8 --patches 20000)\n"
    "  NAME: train seconds per training step and peak memory, the network in float32\n"
    "              and in bfloat16 side by side, patches rendered with the config's\n"
    "              scene margin (--patch 256 --batch 1); --profile adds the step's\n"
    "              phases (PSF, sensor, network, loss, backward parts, optimizer)\n"
    "  NAME: dist  data-parallel training against one process on the same global\n"
    "              batch: --ranks local ranks (Gloo, cores/ranks threads each) with\n"
    "              global and per-rank batch norm, the same work as independent\n"
    "              processes (the machine's floor), the share in collectives, and\n"
    "              the gradient average bucketed vs per tensor\n"
    "              (--ranks 2 --batch 4 --patch 128)\n"
    "  NAME: reconstruct  seconds per megapixel of the exported reconstructor in tiles,\n"
    "              float32 and bfloat16 (--size 2048 --tile 512 --overlap 32)\n"
    "  NAME: accuracy --out DIR  error against run time of the simulator's knobs\n"
    "              (precision, pixel nodes, low-rank cut, pupil oversampling, cell\n"
    "              integration, spectral samples, window, FFT method) against a\n"
    "              converged float64 reference, and what leaving out unneeded work\n"
    "              saves: error_vs_runtime.csv/.png, leave_out.csv, accuracy.md\n"
    "              (--patch 128 --band-stride 3 --ref-oversampling 4 --ref-spectral 5)\n"
    "  NAME: apps  whole processes as a user runs them: hsd_psf --help, the app's\n"
    "              start-up alone, and hsd_simulate on a one-layer and an\n"
    "              all-layer scene (--size 384)\n"
    "  --config defaults to configs/paper.json of the source tree.\n"
    "  --json prints exactly one JSON object on stdout.";

}  // namespace hsd::usage
