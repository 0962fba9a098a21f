// hsd_reconstruct: a sensor image (linear RGB EXR, or an 8/16-bit sRGB PNG
// decoded to linear) -> DIR/hs.exr (S0.<nm> radiance channels), DIR/depth.exr
// (Z, metres), DIR/hs_srgb.png and DIR/depth.png, with an exported
// reconstructor (hsd_export). Large frames run in overlapping tiles
// (model/tiled_inference.h) with a progress bar.
#include <filesystem>
#include <memory>

#include <opencv2/imgcodecs.hpp>
#include <opencv2/imgproc.hpp>
#include <torch/script.h>
#include <torch/torch.h>

#include "common/app.h"
#include "common/atomic_file.h"
#include "common/error.h"
#include "common/log.h"
#include "data/image_io.h"
#include "data/preview.h"
#include "data/scene_exr.h"
#include "model/tiled_inference.h"
#include "model/torchscript_export.h"
#include "usage/hsd_reconstruct.h"

using namespace hsd;

namespace {

const char* kUsage = usage::kText;

torch::Tensor read_input(const std::string& path) {
  if (!std::filesystem::exists(path)) input_error(path, "no such file (--input)");
  const std::string ext = std::filesystem::path(path).extension().string();
  if (ext == ".exr" || ext == ".EXR") {
    torch::Tensor t = data::read_channels_exr(path, {"R", "G", "B"});
    check_finite_input(t, path, "the image (channel, row, column)");
    return t;
  }
  cv::Mat m = data::read_image(path, cv::IMREAD_UNCHANGED, "--input: an OpenEXR with R, G, B or a PNG");
  if (m.channels() != 3) input_error(path, "has " + std::to_string(m.channels()) + " channels; a colour (3-channel) image is needed");
  if (m.depth() != CV_8U && m.depth() != CV_16U) input_error(path, "must be 8- or 16-bit");
  cv::cvtColor(m, m, cv::COLOR_BGR2RGB);
  cv::Mat f;
  m.convertTo(f, CV_32F, m.depth() == CV_8U ? 1.0 / 255.0 : 1.0 / 65535.0);
  m.release();
  const int64_t H = f.rows, W = f.cols;
  // One planar copy, then the sRGB decoding (a 22-megapixel frame is 265 MB per copy).
  return data::srgb_to_linear(torch::from_blob(f.data, {H, W, 3}, torch::kFloat32).permute({2, 0, 1}).contiguous());
}

int run(const AppArgs& args) {
  const std::string model_path = args.option("--model", ""), input = args.option("--input", "");
  if (model_path.empty()) input_error("--model", "required (DIR/reconstructor.pt from hsd_export)");
  if (input.empty()) input_error("--input", "required (a linear RGB EXR or an sRGB PNG)");
  const int64_t tile = args.integer("--tile", 512), overlap = args.integer("--overlap", 32);
  const std::string precision = args.option("--precision", "float32");
  if (precision != "float32" && precision != "bfloat16")
    input_error("--precision", "expected float32 or bfloat16, got \"" + precision + "\"");
  if (tile < 32 || tile % 32 || overlap < 0 || overlap % 32 || 2 * overlap >= tile)
    input_error("--tile/--overlap", "need multiples of 32 with 2·overlap < tile");
  // Context: float32 keeps 2·overlap (seams 1e-7 of the cube's maximum for the
  // paper network); in bfloat16 the rounding (2e-4) already equals the seams of
  // `overlap` pixels of context, so more context would buy nothing (docs/benchmarks.md).
  const int64_t context = args.integer("--context", precision == "bfloat16" ? overlap : 2 * overlap);
  if (context < overlap || context % 32) input_error("--context", "must be a multiple of 32 and at least --overlap");
  // Large frames: give freed memory back above 64 MiB instead of keeping up to
  // 1 GiB for reuse (every app's setting), so the peak stays bounded.
  keep_freed_memory(64);
  const std::string& o = args.out_dir;
  check_output_paths({o + "/hs.exr", o + "/depth.exr", o + "/depth.png", o + "/hs_srgb.png"});
  torch::jit::Module m = model::load_reconstructor(model_path);
  model::set_reconstructor_precision(m, precision == "bfloat16" ? torch::kBFloat16 : torch::kFloat32);
  const torch::Tensor wl = m.attr("wavelengths_m").toTensor(), range = m.attr("depth_range_m").toTensor();
  torch::Tensor image = read_input(input);
  const int64_t H = image.size(1), W = image.size(2);
  release_freed_memory();  // the decoder's buffers
  setup_threads(0);
  make_dirs(args.out_dir);
  torch::NoGradGuard ng;
  std::unique_ptr<log::Progress> progress;
  auto f = [&](const torch::Tensor& x) { return model::run_reconstructor(m, x); };
  auto [hs, depth] = model::tiled_reconstruct(f, image, tile, overlap, [&](int64_t done, int64_t total) {
    if (!progress) progress = std::make_unique<log::Progress>("tiles", long(total));
    progress->step();
    if (done % 8 == 0) release_freed_memory();  // the tiles' temporaries, so the heap does not creep
  }, context);
  if (progress) progress->finish();
  check_finite(hs, "the model's cube for " + input + " (nothing written)");
  check_finite(depth, "the model's depth map for " + input + " (nothing written)");
  image = torch::Tensor();  // from here on only the outputs are held
  std::vector<double> wavelengths(wl.data_ptr<double>(), wl.data_ptr<double>() + wl.numel());
  std::vector<std::string> names;
  for (double w : wavelengths) names.push_back(data::spectral_channel_name("S0", w));
  data::write_channels_exr(args.out_dir + "/hs.exr", hs, names);
  data::write_channels_exr(args.out_dir + "/depth.exr", depth, {"Z"});
  data::write_depth_png(args.out_dir + "/depth.png", depth, {}, range[0].item<double>(), range[1].item<double>());
  depth = torch::Tensor();
  const double bw = wavelengths.size() > 1 ? (wavelengths.back() - wavelengths.front()) / double(wavelengths.size() - 1) : 10e-9;
  // The preview in bands of rows: a 22-megapixel cube is 2.2 GB in float32, so
  // no full-size temporary (a clamped or float64 copy) is made; the cube is
  // released before the PNG is encoded.
  torch::Tensor rgb = torch::empty({3, H, W});
  for (int64_t r = 0; r < H; r += 128) {
    const int64_t n = std::min<int64_t>(128, H - r);
    rgb.narrow(1, r, n).copy_(data::spectral_to_linear_srgb(hs.narrow(1, r, n).clamp_min(0), wavelengths, bw));
  }
  hs = torch::Tensor();
  release_freed_memory();
  data::write_srgb_png(args.out_dir + "/hs_srgb.png", rgb, std::max(1e-6, rgb.max().item<double>()));
  log::info("wrote " + args.out_dir + "/hs.exr (" + std::to_string(names.size()) + " bands), depth.exr, hs_srgb.png, depth.png (" +
            std::to_string(W) + "x" + std::to_string(H) + ")");
  return 0;
}

}  // namespace

int main(int argc, char** argv) {
  AppSpec spec{"hsd_reconstruct", kUsage, {"--model", "--input", "--tile", "--overlap", "--context", "--precision"}, {}, false, true};
  return run_app(spec, argc, argv, run);
}
