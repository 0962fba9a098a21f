// hsd_curves --help: shared by the app and its launcher (apps/launcher.cpp),
// which prints it without loading LibTorch.
#pragma once

namespace hsd::usage {

inline constexpr const char* kText =
    "hsd_curves --runs DIR,DIR[,...] [--columns val_loss,val_hs_psnr_db,val_depth_rmse_m] --out DIR\n"
    "  Compares training runs: one plot per metrics.csv column with every run's\n"
    "  curve (x: step), DIR/<column>.png and all of them in DIR/curves.png, and a\n"
    "  table of each run's last value per column with its difference from the first\n"
    "  run's (printed and in DIR/curves.md). A run is a hsd_train output folder;\n"
    "  its name in the legend is the folder's name.";

}  // namespace hsd::usage
