#include "bench/baseline_psf.h"

#include <cmath>

#include <torch/torch.h>

#include "optics/aperture.h"
#include "optics/fresnel_mft.h"

namespace hsd::bench {

torch::Tensor baseline_fft_psf(const optics::PsfSpec& spec, const torch::Tensor& aperture, const torch::Tensor& height_m) {
  namespace F = torch::nn::functional;
  const int64_t N = spec.doe_samples, P = spec.psf_size, Np = 2 * N;
  const auto cdt = spec.real_dtype == torch::kFloat64 ? torch::kComplexDouble : torch::kComplexFloat;
  const torch::Tensor x = optics::centred_coordinates(N, spec.doe_pitch_m);
  const torch::Tensor pix = optics::centred_coordinates(P, spec.pixel_pitch_m);
  std::vector<torch::Tensor> per_l;
  for (size_t l = 0; l < spec.wavelengths_m.size(); ++l) {
    const double lam = spec.wavelengths_m[l];
    const torch::Tensor field = optics::compute_pupil_field(aperture, height_m, lam, spec.refractive_index[l], cdt);
    // FFT bin k (after fftshift, k = −N..N−1) sits at x = k·λs/(2Nδ); the window
    // needs fractional bin positions x_c/(λs/(2Nδ)), mapped to grid_sample's [−1, 1].
    const double bin = lam * spec.sensor_distance_m / (double(Np) * spec.doe_pitch_m);
    const torch::Tensor g1 = ((pix / bin + double(N)) / double(Np - 1) * 2.0 - 1.0).to(spec.real_dtype);  // [P]
    const torch::Tensor grid = torch::stack({g1.view({1, -1}).expand({P, P}), g1.view({-1, 1}).expand({P, P})}, -1)
                                   .unsqueeze(0);  // [1, P, P, 2] (x, y)
    std::vector<torch::Tensor> per_z;
    for (double z : spec.depths_m) {
      const torch::Tensor chirp = optics::compute_defocus_chirp(x, lam, z, spec.sensor_distance_m, cdt);
      const torch::Tensor u = field * chirp.view({-1, 1}) * chirp.view({1, -1});
      const torch::Tensor padded = F::pad(u, F::PadFuncOptions({N / 2, N - N / 2, N / 2, N - N / 2}));
      const torch::Tensor spectrum = torch::fft::fftshift(torch::fft::fft2(torch::fft::ifftshift(padded)));
      const torch::Tensor I = optics::intensity(spectrum).view({1, 1, Np, Np});
      const torch::Tensor s = F::grid_sample(I, grid, F::GridSampleFuncOptions().mode(torch::kBilinear).align_corners(true))
                                  .view({P, P});
      per_z.push_back(s / s.sum().clamp_min(1e-30));
    }
    per_l.push_back(torch::stack(per_z));
  }
  return torch::stack(per_l);
}

}  // namespace hsd::bench
