#include "model/torchscript_export.h"

#include <filesystem>
#include <sstream>

#include "common/error.h"

namespace hsd::model {

namespace {

std::string flat(const std::string& name) {
  std::string s = name;
  for (char& c : s)
    if (c == '.') c = '_';
  return "p_" + s;
}

// TorchScript for one conv -> norm -> ReLU (×2) block registered under `mod`.
void block_source(std::ostringstream& o, const std::string& var, const std::string& mod, const std::string& norm) {
  const int stride = norm == "none" ? 2 : 3;  // Sequential indices per (conv, [norm], relu)
  for (int k = 0; k < 2; ++k) {
    const std::string conv = mod + "." + std::to_string(stride * k);
    o << "        " << var << " = torch.conv2d(" << var << ", self." << flat(conv + ".weight") << ", "
      << (norm == "none" ? "self." + flat(conv + ".bias") : std::string("None")) << ", [1, 1], [1, 1], [1, 1], 1)\n";
    if (norm != "none") {
      const std::string n = mod + "." + std::to_string(stride * k + 1);
      if (norm == "batch")
        o << "        " << var << " = torch.batch_norm(" << var << ", self." << flat(n + ".weight") << ", self."
          << flat(n + ".bias") << ", self." << flat(n + ".running_mean") << ", self." << flat(n + ".running_var")
          << ", False, 0.1, 1e-05, False)\n";
      else
        o << "        " << var << " = torch.group_norm(" << var << ", self.groups_" << flat(n) << ", self."
          << flat(n + ".weight") << ", self." << flat(n + ".bias") << ", 1e-05, False)\n";
    }
    o << "        " << var << " = torch.relu(" << var << ")\n";
  }
}

}  // namespace

torch::jit::Module export_torchscript(HsdNet& net, const ExportMetadata& meta) {
  const NetOptions& opt = net->options();
  torch::jit::Module m("HsdReconstructor");
  torch::NoGradGuard no_grad;
  for (const auto& p : net->named_parameters()) m.register_parameter(flat(p.key()), p.value().detach().clone(), false);
  for (const auto& b : net->named_buffers())
    if (b.key().find("num_batches_tracked") == std::string::npos) m.register_buffer(flat(b.key()), b.value().detach().clone());
  if (opt.norm == "group")
    for (const auto& mod : net->named_modules())
      if (auto* g = mod.value()->as<torch::nn::GroupNormImpl>())
        m.register_attribute("groups_" + flat(mod.key()), c10::IntType::get(), g->options.num_groups());
  m.register_attribute("wavelengths_m", c10::TensorType::get(), torch::tensor(meta.wavelengths_m, torch::kFloat64));
  m.register_attribute("depth_range_m", c10::TensorType::get(),
                       torch::tensor(std::vector<double>{opt.depth_min_m, opt.depth_max_m}, torch::kFloat64));
  for (const auto& [k, v] : meta.strings) m.register_attribute(k, c10::StringType::get(), v);
  for (const auto& [k, v] : meta.numbers) m.register_attribute(k, c10::FloatType::get(), v);

  const int64_t L = opt.levels, mult = int64_t(1) << L;
  std::ostringstream o;
  o << "def forward(self, image: Tensor) -> Tuple[Tensor, Tensor]:\n"
    << "        B = image.size(0)\n        C = image.size(1)\n        H = image.size(2)\n        W = image.size(3)\n"
    << "        ph = (" << mult << " - H % " << mult << ") % " << mult << "\n"
    << "        pw = (" << mult << " - W % " << mult << ") % " << mult << "\n"
    // The network runs in the dtype of its weights (float32 as exported; bfloat16
    // after set_reconstructor_precision), in the input's memory format (`to`
    // keeps it; run_reconstructor passes channels-last); the outputs are float32.
    << "        x = image\n"
    << "        if ph > 0 or pw > 0:\n"
    << "            if ph < H and pw < W:\n"
    << "                x = torch.reflection_pad2d(x, [0, pw, 0, ph])\n"
    << "            else:\n"
    << "                x = torch.replication_pad2d(x, [0, pw, 0, ph])\n"
    << "        x = x.to(self.p_head_hs_weight.dtype)\n";  // after padding: no bfloat16 padding kernels on the CPU
  for (int64_t l = 0; l < L; ++l) {
    block_source(o, "x", "down" + std::to_string(l), opt.norm);
    o << "        s" << l << " = x\n"
      << "        x = torch.max_pool2d(x, [2, 2], [2, 2], [0, 0], [1, 1], False)\n";
  }
  block_source(o, "x", "bottom", opt.norm);
  for (const std::string branch : {"hs", "depth"}) {
    o << "        y_" << branch << " = x\n";
    for (int64_t l = L - 1; l >= 0; --l) {
      const std::string y = "y_" + branch, up = "up_" + branch + std::to_string(l);
      o << "        " << y << " = torch.upsample_bilinear2d(" << y << ", [s" << l << ".size(2), s" << l
        << ".size(3)], False, None, None)\n"
        << "        " << y << " = torch.relu(torch.conv2d(" << y << ", self." << flat(up + ".weight") << ", self."
        << flat(up + ".bias") << ", [1, 1], [1, 1], [1, 1], 1))\n"
        << "        " << y << " = torch.cat([" << y << ", s" << l << "], 1)\n";
      block_source(o, y, "dec_" + branch + std::to_string(l), opt.norm);
    }
  }
  o << "        hs = torch.conv2d(y_hs, self.p_head_hs_weight, self.p_head_hs_bias, [1, 1], [0, 0], [1, 1], 1)\n"
    << "        d = torch.sigmoid(torch.conv2d(y_depth, self.p_head_depth_weight, self.p_head_depth_bias, [1, 1], [0, 0], [1, 1], 1))\n"
    << "        hs = hs[:, :, 0:H, 0:W].float().contiguous()\n"
    << "        d = d[:, :, 0:H, 0:W].float().contiguous()\n"
    << "        Lb = self.p_upsampling_weights.size(0)\n"
    << "        up = torch.mm(self.p_upsampling_weights.float(), image.float().permute([1, 0, 2, 3]).reshape([C, B * H * W]))\n"
    << "        hs = hs + up.reshape([Lb, B, H, W]).permute([1, 0, 2, 3])\n"
    << "        inv_far = 1.0 / " << c10::str(opt.depth_max_m) << "\n"
    << "        inv_near = 1.0 / " << c10::str(opt.depth_min_m) << "\n"
    << "        depth = 1.0 / (inv_far + d * (inv_near - inv_far))\n"
    << "        return (hs, depth)\n";
  m.define(o.str());
  m.eval();
  return m;
}

void set_reconstructor_precision(torch::jit::Module& m, c10::ScalarType dtype) {
  if (dtype != torch::kFloat32 && dtype != torch::kBFloat16)
    throw InputError("reconstructor precision must be float32 or bfloat16");
  torch::NoGradGuard ng;
  auto convert = [&](const std::string& name, torch::Tensor t) {
    if (name.find("upsampling") != std::string::npos || !t.is_floating_point()) return;  // the residual stays float32
    torch::Tensor v = t.detach().to(dtype);
    if (v.dim() == 4) v = v.contiguous(at::MemoryFormat::ChannelsLast);
    t.set_data(v);
  };
  for (const auto& p : m.named_parameters(false)) convert(p.name, p.value);
  for (const auto& b : m.named_buffers(false)) convert(b.name, b.value);
}

torch::jit::Module load_reconstructor(const std::string& path) {
  if (!std::filesystem::exists(path)) throw InputError(path + ": no such file (an exported reconstructor.pt)");
  torch::jit::Module m;
  try {
    m = torch::jit::load(path);
  } catch (const std::exception& e) {
    throw InputError(path + ": not a TorchScript module (" + std::string(e.what()).substr(0, 120) + ")");
  }
  if (!m.hasattr("wavelengths_m") || !m.hasattr("depth_range_m") || !m.find_method("forward"))
    throw InputError(path + ": is not an hsd reconstructor (needs forward, wavelengths_m and depth_range_m; make it with hsd_export)");
  m.eval();
  return m;
}

std::pair<torch::Tensor, torch::Tensor> run_reconstructor(torch::jit::Module& m, const torch::Tensor& x) {
  // channels-last: oneDNN's convolutions run about 1.3x faster than in NCHW
  const auto out = m.forward({x.dim() == 4 ? x.contiguous(at::MemoryFormat::ChannelsLast) : x}).toTuple();
  return {out->elements()[0].toTensor(), out->elements()[1].toTensor()};
}

}  // namespace hsd::model
