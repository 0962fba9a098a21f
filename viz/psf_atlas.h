// The PSF atlas picture (the paper's Fig. 4): one tile per (λ, z), rows
// wavelengths and columns depths, each PSF scaled to its own peak, gamma 1/2 to
// show the tails, tinted with its wavelength's display colour; rows and columns
// labelled. Written as PNG through a temporary file.
#pragma once
#include <string>
#include <vector>

#include <torch/types.h>

namespace hsd::viz {

// psf [L, Z, P, P]; returns an 8-bit BGR image (cv::Mat stored in a torch uint8 tensor [H, W, 3]).
torch::Tensor render_psf_atlas(const torch::Tensor& psf, const std::vector<double>& wavelengths_m,
                               const std::vector<double>& depths_m);
void write_psf_atlas(const std::string& path, const torch::Tensor& psf, const std::vector<double>& wavelengths_m,
                     const std::vector<double>& depths_m);

}  // namespace hsd::viz
