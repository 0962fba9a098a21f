// hsd_ablate --help: shared by the app and its launcher (apps/launcher.cpp),
// which prints it without loading LibTorch.
#pragma once

namespace hsd::usage {

inline constexpr const char* kText =
    "hsd_ablate --config FILE [--seeds 0,1,2] [--set key=VALUE ...] --out DIR\n"
    "  Trains the config's network with the DOE fixed to fresnel, spiral and fisher,\n"
    "  learned end to end from fisher, and the all-in-focus control (no optical\n"
    "  cue), same data and budget; evaluates each on the test split against the\n"
    "  baselines, and writes DIR/ablation.md (mean +- std over seeds, pairwise\n"
    "  2-standard-error comparisons), DIR/ablation.csv and DIR/error_vs_time.png. Each arm's training and evaluation output is in\n"
    "  DIR/<arm>_seed<k>/{run,eval}. Small budget: configs/ablation_quick.json;\n"
    "  the paper's: configs/ablation_paper.json.";

}  // namespace hsd::usage
