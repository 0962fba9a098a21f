// hsd_bench reconstruct: seconds per megapixel and peak memory of the exported
// (TorchScript) reconstructor on a --size x --size frame in tiles of --tile
// with --overlap, for the config's network (default: the paper's).
#include <cstdio>

#include <torch/script.h>
#include <torch/torch.h>

#include "bench/bench_util.h"
#include "bench/benches.h"
#include "common/error.h"
#include "common/log.h"
#include "model/spectral_upsampling.h"
#include "model/tiled_inference.h"
#include "model/torchscript_export.h"
#include "optics/spectrum.h"

namespace hsd::bench {

int bench_reconstruct(Config cfg, const AppArgs& args, BenchOutput& out) {
  const int64_t size = args.integer("--size", 1024), tile = args.integer("--tile", 512), overlap = args.integer("--overlap", 64);
  if (size < 64 || size > 8192) input_error("--size", "must be in [64, 8192]");
  const auto bands = cfg.optics.wavelengths_m();
  const torch::Tensor omega = optics::camera_response(cfg.sensor.camera, bands, cfg.optics.band_width_m());
  model::NetOptions o;
  o.bands = int64_t(bands.size()), o.base_width = cfg.model.base_width, o.levels = cfg.model.levels, o.norm = cfg.model.norm;
  torch::manual_seed(int64_t(cfg.seed));
  model::HsdNet net(o, model::spectral_upsampling_weights(omega));
  net->eval();
  torch::jit::Module m = model::export_torchscript(net, {bands, {}});
  torch::NoGradGuard ng;
  const torch::Tensor img = torch::rand({3, size, size});
  auto f = [&](const torch::Tensor& x) { return model::run_reconstructor(m, x); };
  log::info("reconstructing a " + std::to_string(size) + "^2 frame ...");
  const double rss0 = current_rss_mib();
  const double t = median_seconds([&] { model::tiled_reconstruct(f, img, tile, overlap); }, int(args.integer("--repeats", 1)));
  const double peak = peak_rss_during([&] { model::tiled_reconstruct(f, img, tile, overlap); });
  const double mp = double(size) * double(size) / 1e6;
  out.json = Json{{"bench", "reconstruct"}, {"threads", torch::get_num_threads()}, {"size", size}, {"tile", tile},
                  {"overlap", overlap}, {"bands", o.bands}, {"base_width", o.base_width}, {"levels", o.levels},
                  {"seconds", t}, {"seconds_per_megapixel", t / mp}, {"peak_rss_mib", peak}, {"rss_at_start_mib", rss0}};
  char buf[400];
  std::snprintf(buf, sizeof buf,
                "reconstruct (TorchScript export): %lld x %lld frame, tiles %lld + %lld overlap, %lld bands, U-Net %lld x %lld, threads %d\n"
                "%.2f s  ->  %.2f s per megapixel, peak RSS %.0f MiB\n",
                (long long)size, (long long)size, (long long)tile, (long long)overlap, (long long)o.bands,
                (long long)o.base_width, (long long)o.levels, torch::get_num_threads(), t, t / mp, peak);
  out.text = buf;
  return 0;
}

}  // namespace hsd::bench
