// hsd_bench reconstruct: seconds per megapixel and peak memory of the exported
// (TorchScript) reconstructor on a --size x --size frame in tiles of --tile
// with --overlap, for the config's network (default: the paper's), in float32
// and in bfloat16 side by side, with the difference between the two.
#include <cstdio>

#include <torch/script.h>
#include <torch/torch.h>

#include "bench/bench_util.h"
#include "bench/benches.h"
#include "common/error.h"
#include "common/log.h"
#include "model/spectral_upsampling.h"
#include "model/net_options.h"
#include "model/tiled_inference.h"
#include "model/torchscript_export.h"
#include "optics/spectrum.h"

namespace hsd::bench {

int bench_reconstruct(Config cfg, const AppArgs& args, BenchOutput& out) {
  const int64_t size = args.integer("--size", 2048), tile = args.integer("--tile", 512), overlap = args.integer("--overlap", 32);
  if (size < 64 || size > 8192) input_error("--size", "must be in [64, 8192]");
  const auto bands = cfg.optics.wavelengths_m();
  const torch::Tensor omega = optics::camera_response(cfg.sensor.camera, bands, cfg.optics.band_width_m());
  // The config's network without the Wiener pre-inversion (it needs a DOE's
  // PSFs; the benchmark times the reconstructor alone).
  model::NetOptions o = model::net_options(cfg);
  o.preinverse_layers = 0, o.residual_preinverse = false;
  torch::manual_seed(int64_t(cfg.seed));
  model::HsdNet net(o, model::spectral_upsampling_weights(omega));
  net->eval();
  torch::jit::Module f32 = model::export_torchscript(net, {bands, {}, {}});
  torch::jit::Module bf16 = f32.clone();
  model::set_reconstructor_precision(f32, torch::kFloat32);   // channels-last weights
  model::set_reconstructor_precision(bf16, torch::kBFloat16);
  torch::NoGradGuard ng;
  const torch::Tensor img = torch::rand({3, size, size});
  const double mp = double(size) * double(size) / 1e6;
  const int repeats = int(args.integer("--repeats", 1));
  struct Measured {
    double seconds = 0, peak = 0;
    std::pair<torch::Tensor, torch::Tensor> result;
  };
  // hsd_reconstruct's default context: 2·overlap in float32, overlap in bfloat16
  auto measure = [&](torch::jit::Module& m, const std::string& name, int64_t context) {
    log::info("reconstructing a " + std::to_string(size) + "^2 frame in " + name + " ...");
    auto f = [&](const torch::Tensor& x) { return model::run_reconstructor(m, x); };
    Measured r;
    r.seconds = median_seconds([&] { r.result = model::tiled_reconstruct(f, img, tile, overlap, {}, context); }, repeats);
    r.peak = peak_rss_during([&] { model::tiled_reconstruct(f, img, tile, overlap, {}, context); });
    return r;
  };
  const double rss0 = current_rss_mib();
  const Measured a = measure(f32, "float32", 2 * overlap), b = measure(bf16, "bfloat16", overlap);
  const double hs_err = ((b.result.first - a.result.first).abs().mean() / a.result.first.abs().mean()).item<double>();
  const double depth_err = (b.result.second - a.result.second).abs().max().item<double>();
  out.json = Json{{"bench", "reconstruct"}, {"threads", torch::get_num_threads()}, {"size", size}, {"tile", tile},
                  {"overlap", overlap}, {"bands", o.bands}, {"base_width", o.base_width}, {"levels", o.levels},
                  {"seconds", a.seconds}, {"seconds_per_megapixel", a.seconds / mp}, {"peak_rss_mib", a.peak},
                  {"seconds_bfloat16", b.seconds}, {"seconds_per_megapixel_bfloat16", b.seconds / mp},
                  {"peak_rss_mib_bfloat16", b.peak}, {"bfloat16_hs_mean_rel_diff", hs_err},
                  {"bfloat16_depth_max_diff_m", depth_err}, {"context_float32", 2 * overlap},
                  {"context_bfloat16", overlap}, {"rss_at_start_mib", rss0}};
  char buf[700];
  std::snprintf(buf, sizeof buf,
                "reconstruct (TorchScript export): %lld x %lld frame, tiles %lld + %lld overlap, %lld bands, U-Net %lld x %lld, threads %d\n"
                "float32:  %.2f s  ->  %.2f s per megapixel, peak RSS %.0f MiB\n"
                "bfloat16: %.2f s  ->  %.2f s per megapixel, peak RSS %.0f MiB; vs float32: cube mean rel. diff %.2e, depth max diff %.2e m\n",
                (long long)size, (long long)size, (long long)tile, (long long)overlap, (long long)o.bands,
                (long long)o.base_width, (long long)o.levels, torch::get_num_threads(), a.seconds, a.seconds / mp, a.peak,
                b.seconds, b.seconds / mp, b.peak, hs_err, depth_err);
  out.text = buf;
  return 0;
}

}  // namespace hsd::bench
