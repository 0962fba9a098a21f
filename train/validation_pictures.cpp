#include "train/validation_pictures.h"

#include <algorithm>

#include "data/image_io.h"
#include "data/preview.h"
#include "viz/plot.h"
#include "viz/psf_atlas.h"

namespace hsd::train {

void write_validation_pictures(const std::string& stem, const ValidationPictures& v) {
  const auto& bands = v.wavelengths_m;
  const double bw = v.band_width_m;
  const torch::Tensor truth0 = data::spectral_to_linear_srgb(v.truth[0].cpu(), bands, bw);
  const double white = std::max(1e-6, truth0.max().item<double>());
  std::vector<std::string> parts;
  for (int64_t k = 0; k < v.truth.size(0); ++k) {
    const torch::Tensor I = v.truth[k], J = v.sensor[k];
    const std::string p = stem + std::to_string(k) + "_";
    for (const char* f : {"truth_srgb", "sensor", "recon_srgb", "error_hs", "truth_depth", "recon_depth"})
      parts.push_back(p + f + ".png");
    data::write_srgb_png(p + "truth_srgb.png", k == 0 ? truth0 : data::spectral_to_linear_srgb(I.cpu(), bands, bw), white);
    data::write_srgb_png(p + "recon_srgb.png", data::spectral_to_linear_srgb(v.out.hs[k].clamp_min(0).cpu(), bands, bw), white);
    data::write_srgb_png(p + "sensor.png", J.cpu(), std::max(1e-6, J.max().item<double>()));
    data::write_depth_png(p + "truth_depth.png", v.depth_m[k].cpu(), {}, v.near_m, v.far_m);
    data::write_depth_png(p + "recon_depth.png", v.out.depth_m[k].cpu(), {}, v.near_m, v.far_m);
    // Error map: |Î − I| averaged over bands, as grey scaled to the patch's peak radiance / 4.
    const torch::Tensor err = (v.out.hs[k] - I).abs().mean(0).cpu();
    data::write_srgb_png(p + "error_hs.png", err.unsqueeze(0).expand({3, -1, -1}), std::max(1e-6, 0.25 * I.max().item<double>()));
  }
  viz::write_montage(parts, 6, 3.0, stem + "reconstructions.png");
  viz::write_psf_atlas(stem + "psf_atlas.png", v.psf.cpu(), bands, v.depths_m);
}

}  // namespace hsd::train
