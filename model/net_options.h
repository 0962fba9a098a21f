// The network's options from the config (model.*, the band count of
// optics.wavelengths_nm, the depth head's range from optics.depths_m and the
// scenes' depth range widened by model.depth_margin): the one way the apps,
// training and the benchmarks build the network of a config.
#pragma once
#include "common/config.h"
#include "model/unet.h"

namespace hsd::model {

// train_dtype stays float32 (training resolves train.precision itself).
NetOptions net_options(const Config& cfg);

}  // namespace hsd::model
