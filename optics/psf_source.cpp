#include "optics/psf_source.h"

#include <torch/torch.h>

#include "optics/all_in_focus.h"
#include "optics/psf_file.h"

namespace hsd::optics {

PsfProvider fixed_psf_provider(const torch::Tensor& psf) {
  return [psf](const torch::Tensor& height_m, const std::vector<int64_t>& layers, const std::vector<int64_t>& bands) {
    const auto idx = [&](const std::vector<int64_t>& v) { return torch::tensor(v, torch::kInt64).to(psf.device()); };
    torch::Tensor p = psf.index_select(1, idx(layers));
    p = bands.empty() ? p.narrow(0, 0, 0) : p.index_select(0, idx(bands));
    return p.to(height_m.scalar_type());
  };
}

std::string psf_file_path(const OpticsConfig& cfg) {
  return cfg.psf_source == PsfSource::file ? cfg.psf_path : std::string();
}

torch::Tensor fixed_psf_stack(const OpticsConfig& cfg, const Material& material, torch::Device device) {
  if (cfg.psf_source == PsfSource::all_in_focus) return all_in_focus_psf(cfg, material, device);
  const std::string path = psf_file_path(cfg);
  if (!path.empty()) return psf_for_config(read_psf_file(path), cfg, path, "config key optics.psf_source", device);
  return {};
}

PsfProvider psf_source_provider(const OpticsConfig& cfg, const Material& material, torch::Device device) {
  const torch::Tensor p = fixed_psf_stack(cfg, material, device);
  return p.defined() ? fixed_psf_provider(p) : nullptr;
}

torch::Tensor imaging_psf_stack(const PsfSimulator& sim, const torch::Tensor& height_m, const PsfProvider& provider) {
  torch::NoGradGuard no_grad;
  const torch::Tensor h = height_m.detach();
  if (!provider) return sim.compute(h).psf;
  std::vector<int64_t> layers(sim.spec().depths_m.size()), bands(sim.spec().wavelengths_m.size());
  for (size_t i = 0; i < layers.size(); ++i) layers[i] = int64_t(i);
  for (size_t i = 0; i < bands.size(); ++i) bands[i] = int64_t(i);
  return provider(h, layers, bands);
}

}  // namespace hsd::optics
