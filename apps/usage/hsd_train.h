// hsd_train --help: shared by the app and its launcher (apps/launcher.cpp),
// which prints it without loading LibTorch.
#pragma once

namespace hsd::usage {

inline constexpr const char* kText =
    "hsd_train --config FILE [--set key=VALUE ...] --out DIR [--resume]\n"
    "  Trains the DOE height map and the U-Net together (train.steps steps of\n"
    "  train.batch_size patches of data.patch_size_px from data.root, generated\n"
    "  first if missing and data.generate_if_missing). train.freeze_doe keeps the\n"
    "  DOE fixed. Writes DIR/metrics.csv, DIR/curves.png, DIR/val_psnr.png,\n"
    "  DIR/val/*.png, DIR/checkpoints/last.pt and DIR/config.json. --resume\n"
    "  continues from DIR/checkpoints/last.pt (same results as an uninterrupted\n"
    "  run with the same thread count).\n"
    "Data-parallel: with WORLD_SIZE, RANK, MASTER_ADDR, MASTER_PORT set (torchrun's\n"
    "  convention) this process is one rank; train.batch_size is the global batch\n"
    "  (each rank takes batch_size / WORLD_SIZE of it) and the result matches one\n"
    "  process up to float rounding. Rank 0 writes every file; a rank that dies or\n"
    "  stalls past distributed.timeout_s ends the others with exit code 4. threads = 0\n"
    "  gives each rank cores / LOCAL_WORLD_SIZE threads. scripts/launch_distributed.sh\n"
    "  starts N local ranks.";

}  // namespace hsd::usage
