#include "model/torchscript_export.h"

#include <filesystem>
#include <sstream>

#include "common/error.h"
#include "model/defocus_likelihood.h"
#include "model/depth_fusion.h"
#include "model/illuminant_reader.h"
#include "model/spectral_wiener.h"

namespace hsd::model {

namespace {

std::string flat(const std::string& name) {
  std::string s = name;
  for (char& c : s)
    if (c == '.') c = '_';
  return "p_" + s;
}

// TorchScript for one conv -> norm -> ReLU (×2) block registered under `mod`.
void block_source(std::ostringstream& o, const std::string& var, const std::string& mod, NormKind norm) {
  const int stride = norm == NormKind::none ? 2 : 3;  // Sequential indices per (conv, [norm], relu)
  for (int k = 0; k < 2; ++k) {
    const std::string conv = mod + "." + std::to_string(stride * k);
    o << "        " << var << " = torch.conv2d(" << var << ", self." << flat(conv + ".weight") << ", "
      << (norm == NormKind::none ? "self." + flat(conv + ".bias") : std::string("None")) << ", [1, 1], [1, 1], [1, 1], 1)\n";
    if (norm != NormKind::none) {
      const std::string n = mod + "." + std::to_string(stride * k + 1);
      if (norm == NormKind::batch)
        o << "        " << var << " = torch.batch_norm(" << var << ", self." << flat(n + ".weight") << ", self."
          << flat(n + ".bias") << ", self." << flat(n + ".running_mean") << ", self." << flat(n + ".running_var")
          << ", False, 0.1, 1e-05, False)\n";
      else  // statistics in float32 whatever the network's dtype: LibTorch's bfloat16 group_norm is far off (docs/apps.md)
        o << "        " << var << " = torch.group_norm(" << var << ".float(), self.groups_" << flat(n) << ", self."
          << flat(n + ".weight") << ".float(), self." << flat(n + ".bias") << ".float(), 1e-05, False).to(" << var << ".dtype)\n";
    }
    o << "        " << var << " = torch.relu(" << var << ")\n";
  }
}

// The network's parameters and batch-norm buffers under flat names, the
// group sizes of group norm, and the metadata, as the module's attributes.
void register_weights(torch::jit::Module& m, HsdNet& net, const ExportMetadata& meta) {
  const NetOptions& opt = net->options();
  for (const auto& p : net->named_parameters()) m.register_parameter(flat(p.key()), p.value().detach().clone(), false);
  for (const auto& b : net->named_buffers())
    if (b.key().find("num_batches_tracked") == std::string::npos) m.register_buffer(flat(b.key()), b.value().detach().clone());
  if (opt.norm == NormKind::group)
    for (const auto& mod : net->named_modules())
      if (auto* g = mod.value()->as<torch::nn::GroupNormImpl>())
        m.register_attribute("groups_" + flat(mod.key()), c10::IntType::get(), g->options.num_groups());
  m.register_attribute("wavelengths_m", c10::TensorType::get(), torch::tensor(meta.wavelengths_m, torch::kFloat64));
  m.register_attribute("depth_range_m", c10::TensorType::get(),
                       torch::tensor(std::vector<double>{opt.depth_min_m, opt.depth_max_m}, torch::kFloat64));
  for (const auto& [k, v] : meta.strings) m.register_attribute(k, c10::StringType::get(), v);
  for (const auto& [k, v] : meta.numbers) m.register_attribute(k, c10::FloatType::get(), v);
}

// preinverse(image) (with define_fast_fft_size): the Wiener pre-inversion
// (wiener_preinverse.cpp, line for line) with the PSFs of the DOE the network
// was trained with, fixed from now on.
void define_preinverse(torch::jit::Module& m, HsdNet& net) {
  const NetOptions& opt = net->options();
  if (!net->preinverse_psf().defined())
    throw InputError("export: the network's pre-inversion PSFs are not set (load a checkpoint first)");
  m.register_buffer("preinverse_psf", net->preinverse_psf().detach().to(torch::kFloat32).clone());
  std::ostringstream w;
  w << "def preinverse(self, image: Tensor) -> Tensor:\n"
    << "        B = image.size(0)\n        C = image.size(1)\n        H = image.size(2)\n        W = image.size(3)\n"
    << "        K = self.preinverse_psf.size(0)\n        P = self.preinverse_psf.size(2)\n        r = P // 2\n"
    << "        nh = self.fast_fft_size(H + 2 * r)\n        nw = self.fast_fft_size(W + 2 * r)\n"
    << "        x = torch.replication_pad2d(image, [r, nw - W - r, r, nh - H - r])\n"
    << "        k = torch.constant_pad_nd(self.preinverse_psf, [0, nw - P, 0, nh - P], 0.0)\n"
    << "        k = torch.roll(k, [-r, -r], [2, 3])\n"
    << "        Hf = torch.fft_rfft2(k)\n"
    << "        power = torch.real(Hf).square() + torch.imag(Hf).square()\n"
    << "        G = torch.conj(Hf) / (power + " << c10::str(opt.preinverse_reg) << ")\n"
    << "        Y = torch.fft_rfft2(x).unsqueeze(1)\n"
    << "        X = torch.fft_irfft2(Y * G.unsqueeze(0), [nh, nw])\n"
    << "        return X[:, :, :, r:r + H, r:r + W].reshape([B, K * C, H, W])\n";
  m.define(w.str());
}

// fast_fft_size(n) (common/fft_size.h): the smallest m >= n with no prime factor above 5.
void define_fast_fft_size(torch::jit::Module& m) {
  m.define(
      "def fast_fft_size(self, n: int) -> int:\n"
      "        m = n\n        done = False\n"
      "        while not done:\n"
      "            k = m\n"
      "            for p in [2, 3, 5]:\n"
      "                while k % p == 0:\n"
      "                    k = k // p\n"
      "            if k == 1:\n                done = True\n            else:\n                m += 1\n"
      "        return m\n");
}

// spectral_wiener(image): spectral_wiener_cube (spectral_wiener.cpp, line for
// line) with the band PSFs of the DOE the network was trained with and the
// prior it was trained on (the network's sw_* buffers); the factor Ω V of the
// prior's covariance (spectral_wiener_factor) is computed here once, in float64.
void define_spectral_wiener(torch::jit::Module& m, HsdNet& net) {
  if (!net->band_psf().defined())
    throw InputError("export: the network's band PSFs are not set (load a checkpoint first)");
  m.register_buffer("sw_psf", net->band_psf().detach().to(torch::kFloat32).clone());
  const auto buffers = net->named_buffers();
  m.register_buffer("sw_vq", spectral_wiener_factor(buffers["sw_omega"], buffers["sw_covariance"]).clone());
  // sw_psd(nh, nw): spectral_wiener_psd (spectral_wiener.cpp), shared with defocus_cost.
  std::ostringstream psd;
  psd << "def sw_psd(self, nh: int, nw: int) -> Tensor:\n"
      << "        nf = nw // 2 + 1\n"
      << "        iy = torch.arange(nh).double()\n"
      << "        fy = (torch.where(iy < float((nh + 1) // 2), iy, iy - float(nh)) / float(nh)).view([-1, 1])\n"
      << "        fx = (torch.arange(nf).double() / float(nw)).view([1, -1])\n"
      << "        S = torch.pow(torch.sqrt(fy.square() + fx.square()) + 1.0 / float(max(nh, nw)), -"
      << c10::str(SpectralPrior().psd_exponent) << ")\n"
      << "        S = S.flatten()\n        S = S / S[1:].mean()\n"
      << "        return torch.cat([S[0:1] * 10000.0, S[1:]])\n";
  m.define(psd.str());
  std::ostringstream w;
  w << "def spectral_wiener(self, image: Tensor, mu: Tensor, Sig: Tensor, Vq: Tensor) -> Tensor:\n"
    << "        B = image.size(0)\n        H = image.size(2)\n        W = image.size(3)\n"
    << "        L = self.sw_psf.size(0)\n        K = self.sw_psf.size(1)\n        P = self.sw_psf.size(2)\n        r = P // 2\n"
    << "        nh = self.fast_fft_size(H + 2 * r)\n        nw = self.fast_fft_size(W + 2 * r)\n"
    << "        nf = nw // 2 + 1\n        Fn = nh * nf\n"
    << "        Om = self.p_sw_omega.double()\n"
    << "        p = self.sw_psf.double()\n        a = P - r\n"
    << "        k = p.new_zeros([L, K, nh, nw])\n"
    << "        k[:, :, 0:a, 0:a] = p[:, :, r:P, r:P]\n"
    << "        k[:, :, 0:a, nw - r:nw] = p[:, :, r:P, 0:r]\n"
    << "        k[:, :, nh - r:nh, 0:a] = p[:, :, 0:r, r:P]\n"
    << "        k[:, :, nh - r:nh, nw - r:nw] = p[:, :, 0:r, 0:r]\n"
    << "        Kf = torch.fft_rfft2(k).reshape([L, K, Fn])\n"
    << "        Kbar = Kf.mean(1)\n"
    << "        rk = Vq.size(0) // 3 * K\n"
    << "        chunk = max(256, 4194304 // max(1, 3 * rk * 16))\n"
    << "        a00: List[Tensor] = []\n        a11: List[Tensor] = []\n        a22: List[Tensor] = []\n"
    << "        a01: List[Tensor] = []\n        a02: List[Tensor] = []\n        a12: List[Tensor] = []\n"
    << "        for block in torch.split(Kf, chunk, 2):\n"
    << "            n = block.size(2)\n"
    << "            kc = torch.view_as_real(block.contiguous()).reshape([L, K * n * 2])\n"
    << "            qr = torch.matmul(Vq, kc).view([3, rk, n * 2])\n"
    << "            q = torch.view_as_complex(qr.view([3, rk, n, 2]))\n"
    << "            a00.append(qr[0].square().sum(0).view([n, 2]).sum(1))\n"
    << "            a11.append(qr[1].square().sum(0).view([n, 2]).sum(1))\n"
    << "            a22.append(qr[2].square().sum(0).view([n, 2]).sum(1))\n"
    << "            a01.append(torch.view_as_complex(torch.view_as_real(q[0] * torch.conj(q[1])).view([rk, n * 2]).sum(0).view([n, 2])))\n"
    << "            a02.append(torch.view_as_complex(torch.view_as_real(q[0] * torch.conj(q[2])).view([rk, n * 2]).sum(0).view([n, 2])))\n"
    << "            a12.append(torch.view_as_complex(torch.view_as_real(q[1] * torch.conj(q[2])).view([rk, n * 2]).sum(0).view([n, 2])))\n"
    << "        inv_k = 1.0 / float(K)\n"
    << "        S = self.sw_psd(nh, nw)\n"
    << "        s2 = float(self.p_sw_noise_var.item())\n"
    << "        m00 = S * torch.cat(a00) * inv_k + s2\n        m11 = S * torch.cat(a11) * inv_k + s2\n        m22 = S * torch.cat(a22) * inv_k + s2\n"
    << "        m01 = S * torch.cat(a01) * inv_k\n        m02 = S * torch.cat(a02) * inv_k\n        m12 = S * torch.cat(a12) * inv_k\n"
    << "        c00 = m11 * m22 - torch.real(m12 * torch.conj(m12))\n"
    << "        c11 = m00 * m22 - torch.real(m02 * torch.conj(m02))\n"
    << "        c22 = m00 * m11 - torch.real(m01 * torch.conj(m01))\n"
    << "        c01 = m02 * torch.conj(m12) - m01 * m22\n"
    << "        c02 = m01 * m12 - m02 * m11\n"
    << "        c12 = m02 * torch.conj(m01) - m00 * m12\n"
    << "        det = m00 * c00 + torch.real(m01 * torch.conj(c01)) + torch.real(m02 * torch.conj(c02))\n"
    << "        y = image.double() - torch.matmul(Om, mu).view([1, 3, 1, 1])\n"
    << "        y = torch.replication_pad2d(y, [r, nw - W - r, r, nh - H - r])\n"
    << "        Y = torch.fft_rfft2(y).reshape([B, 3, Fn])\n"
    << "        Y0 = Y[:, 0]\n        Y1 = Y[:, 1]\n        Y2 = Y[:, 2]\n"
    << "        idet = 1.0 / det\n"
    << "        Z0 = (c00 * Y0 + c01 * Y1 + c02 * Y2) * idet\n"
    << "        Z1 = (torch.conj(c01) * Y0 + c11 * Y1 + c12 * Y2) * idet\n"
    << "        Z2 = (torch.conj(c02) * Y0 + torch.conj(c12) * Y1 + c22 * Y2) * idet\n"
    << "        Zr = torch.view_as_real(torch.stack([Z0, Z1, Z2], 0)).reshape([3, B * Fn * 2])\n"
    << "        u = torch.view_as_complex(torch.matmul(Om.t(), Zr).view([L, B, Fn, 2]))\n"
    << "        u = u * torch.conj(Kbar).unsqueeze(1)\n"
    << "        xr = torch.matmul(Sig, torch.view_as_real(u).reshape([L, B * Fn * 2])).view([L, B, Fn, 2])\n"
    << "        X = torch.view_as_complex((xr * S.view([1, 1, Fn, 1])).float()).transpose(0, 1).reshape([B, L, nh, nf])\n"
    << "        x = torch.fft_irfft2(X, [nh, nw])\n"
    << "        return x[:, :, r:r + H, r:r + W] + mu.float().view([1, L, 1, 1])\n";
  m.define(w.str());
}

// defocus_cost(image): spectral_defocus_cost_volume (defocus_likelihood.cpp,
// line for line) with the spectral Wiener base's band PSFs, prior and factor
// (define_spectral_wiener's buffers and sw_psd), the box given.
void define_spectral_defocus(torch::jit::Module& m) {
  std::ostringstream w;
  w << "def defocus_cost(self, image: Tensor, win: int, mu: Tensor, Vq: Tensor) -> Tensor:\n"
    << "        B = image.size(0)\n        H = image.size(2)\n        W = image.size(3)\n"
    << "        L = self.sw_psf.size(0)\n        K = self.sw_psf.size(1)\n        P = self.sw_psf.size(2)\n        r = P // 2\n"
    << "        nh = self.fast_fft_size(H + 2 * r)\n        nw = self.fast_fft_size(W + 2 * r)\n"
    << "        nf = nw // 2 + 1\n        Fn = nh * nf\n"
    << "        Om = self.p_sw_omega.double()\n"
    << "        R = Vq.size(0) // 3\n"
    << "        k = torch.constant_pad_nd(self.sw_psf.double(), [0, nw - P, 0, nh - P], 0.0)\n"
    << "        k = torch.roll(k, [-r, -r], [2, 3])\n"
    << "        Kf = torch.fft_rfft2(k).reshape([L, K, Fn])\n"
    << "        S = self.sw_psd(nh, nw)\n"
    << "        s2 = float(self.p_sw_noise_var.item())\n"
    << "        wcol = S.new_full([nf], 2.0)\n"
    << "        wcol[0] = 1.0\n"
    << "        if nw % 2 == 0:\n            wcol[nf - 1] = 1.0\n"
    << "        wf = wcol.repeat([nh]) / float(nh * nw)\n"
    << "        y = image.double() - torch.matmul(Om, mu).view([1, 3, 1, 1])\n"
    << "        y = torch.replication_pad2d(y, [r, nw - W - r, r, nh - H - r])\n"
    << "        Y = torch.fft_rfft2(y).reshape([B, 3, Fn])\n"
    << "        Y0 = Y[:, 0]\n        Y1 = Y[:, 1]\n        Y2 = Y[:, 2]\n"
    << "        h = win // 2\n        m = min(r, h)\n"
    << "        costs: List[Tensor] = []\n"
    << "        for z in range(K):\n"
    << "            kc = torch.view_as_real(Kf[:, z].contiguous()).reshape([L, Fn * 2])\n"
    << "            q = torch.view_as_complex(torch.matmul(Vq, kc).view([3, R, Fn, 2]))\n"
    << "            m00 = S * torch.real(q[0] * torch.conj(q[0])).sum(0) + s2\n"
    << "            m11 = S * torch.real(q[1] * torch.conj(q[1])).sum(0) + s2\n"
    << "            m22 = S * torch.real(q[2] * torch.conj(q[2])).sum(0) + s2\n"
    << "            m10 = S * (q[1] * torch.conj(q[0])).sum(0)\n"
    << "            m20 = S * (q[2] * torch.conj(q[0])).sum(0)\n"
    << "            m21 = S * (q[2] * torch.conj(q[1])).sum(0)\n"
    << "            l00 = m00.sqrt()\n"
    << "            l10 = m10 / l00\n            l20 = m20 / l00\n"
    << "            l11 = (m11 - torch.real(l10 * torch.conj(l10))).clamp_min(1e-300).sqrt()\n"
    << "            l21 = (m21 - l20 * torch.conj(l10)) / l11\n"
    << "            l22 = (m22 - torch.real(l20 * torch.conj(l20)) - torch.real(l21 * torch.conj(l21))).clamp_min(1e-300).sqrt()\n"
    << "            logdet = float((2.0 * (l00.log() + l11.log() + l22.log()) * wf).sum().item())\n"
    << "            w0 = Y0 / l00\n            w1 = (Y1 - l10 * w0) / l11\n            w2 = (Y2 - l20 * w0 - l21 * w1) / l22\n"
    << "            wx = torch.fft_irfft2(torch.stack([w0, w1, w2], 1).reshape([B, 3, nh, nf]), [nh, nw])\n"
    << "            en = wx[:, :, r - m:r + H + m, r - m:r + W + m].square().sum(1, keepdim=True)\n"
    << "            en = torch.avg_pool2d(en, [win, win], [1, 1], [h - m, h - m], False, False)\n"
    << "            costs.append(3.0 * torch.log(en / 3.0 + 1e-300) + logdet)\n"
    << "        c = torch.cat(costs, 1).float()\n"
    << "        return c - c.mean(1, keepdim=True)\n";
  m.define(w.str());
}

// sw_cube(image) and reader_cost(image, win): the spectral Wiener base with
// the prior HsdNetImpl::prior_for gives in eval mode (the buffers', its factor
// sw_vq computed once, or with read_illuminant each image's posterior
// mixture, illuminant_prior below), and the spectral reader's costs with the
// buffers' prior always (unet.cpp).
void define_prior_users(torch::jit::Module& m, const NetOptions& opt) {
  std::ostringstream w;
  if (!opt.read_illuminant) {
    w << "def sw_cube(self, image: Tensor) -> Tensor:\n"
      << "        return self.spectral_wiener(image, self.p_sw_mean.double(), self.p_sw_covariance.double(), self.sw_vq)\n"
      << "def reader_cost(self, image: Tensor, win: int) -> Tensor:\n"
      << "        return self.defocus_cost(image, win, self.p_sw_mean.double(), self.sw_vq)\n";
  } else {
    w << "def sw_cube(self, image: Tensor) -> Tensor:\n"
      << "        out: List[Tensor] = []\n"
      << "        for b in range(image.size(0)):\n"
      << "            x = image[b:b + 1]\n"
      << "            pr = self.illuminant_prior(x)\n"
      << "            out.append(self.spectral_wiener(x, pr[0], pr[1], pr[2]))\n"
      << "        return torch.cat(out, 0)\n"
      << "def reader_cost(self, image: Tensor, win: int) -> Tensor:\n"
      << "        return self.defocus_cost(image, win, self.p_sw_mean.double(), self.sw_vq)\n";
  }
  m.define(w.str());
}

// illuminant_prior(image [1, 3, H, W]) -> (μ_w, Σ_w, the factor Ω V of Σ_w):
// illuminant_log_likelihood, illuminant_posterior, illuminant_mixture_prior
// (illuminant_reader.cpp) and spectral_wiener_factor (spectral_wiener.cpp),
// line for line, with the network's illuminant moments as buffers.
void define_illuminant_reader(torch::jit::Module& m, HsdNet& net) {
  const IlluminantMoments& im = net->illuminant_moments();
  if (!im.mean.defined()) throw InputError("export: the network's illuminant moments are not set (load a checkpoint first)");
  const NetOptions& opt = net->options();
  m.register_buffer("il_mean", im.mean.to(torch::kFloat64).clone());
  m.register_buffer("il_second", im.second.to(torch::kFloat64).clone());
  m.register_buffer("il_grid", illuminant_intensity_grid(im.intensity_min, im.intensity_max));
  const double lo = im.intensity_min, hi = im.intensity_max;
  const double es = 0.5 * (lo + hi), es2 = (lo * lo + lo * hi + hi * hi) / 3.0;
  std::ostringstream w;
  w << "def illuminant_prior(self, image: Tensor) -> Tuple[Tensor, Tensor, Tensor]:\n"
    << "        x = image.double()\n        H = x.size(2)\n        W = x.size(3)\n"
    << "        bs = max(1, min(" << opt.illuminant_reader.block_px << ", min(H, W)))\n"
    << "        b = torch.avg_pool2d(x, [bs, bs], [bs, bs], [0, 0], False, True, None).flatten(2)[0].t()\n"
    << "        J = float(b.size(0))\n"
    << "        bm = b.mean(0)\n"
    << "        Q = torch.mm(b.t(), b) / J\n"
    << "        Om = self.p_sw_omega.double()\n"
    << "        G = Om * self.sw_psf.double().sum([2, 3]).mean(1).view([1, -1])\n"
    << "        mu = self.il_mean.double()\n"
    << "        R2 = self.il_second.double()\n"
    << "        C = R2 - mu.unsqueeze(2) * mu.unsqueeze(1)\n"
    << "        g = torch.mm(mu, G.t())\n"
    << "        A = torch.matmul(torch.matmul(G, C), G.t())\n"
    << "        s = self.il_grid.double()\n"
    << "        nv = float(self.p_sw_noise_var.item())\n"
    << "        tau2 = nv / float(bs * bs) + " << c10::str(kIlluminantModelFloor) << " * (float(Q.diagonal().mean().item()) + 1e-300)\n"
    << "        s2 = (s * s).view([1, -1, 1, 1])\n"
    << "        Sg = s2 * A.unsqueeze(1) + tau2 * torch.diag(g.new_ones([3]))\n"
    << "        Si = torch.linalg_inv(Sg)\n"
    << "        logdet = torch.linalg_slogdet(Sg)[1]\n"
    << "        cross = bm.view([1, 3, 1]) * g.unsqueeze(1) + g.unsqueeze(2) * bm.view([1, 1, 3])\n"
    << "        gg = g.unsqueeze(2) * g.unsqueeze(1)\n"
    << "        D = Q.view([1, 1, 3, 3]) - s.view([1, -1, 1, 1]) * cross.unsqueeze(1) + s2 * gg.unsqueeze(1)\n"
    << "        quad = (Si * D).sum([2, 3])\n"
    << "        ll = torch.max(-0.5 * J * (logdet + quad), 1)[0]\n"
    << "        Jn = float((H // bs) * (W // bs))\n"
    << "        wts = torch.softmax(ll * (" << c10::str(opt.illuminant_reader.effective_blocks) << " / max(Jn, 1.0)), 0)\n"
    << "        mw = " << c10::str(es) << " * torch.mv(mu.t(), wts)\n"
    << "        M = " << c10::str(es2) << " * (wts.view([-1, 1, 1]) * R2).sum(0)\n"
    << "        cov = M - torch.outer(mw, mw)\n"
    << "        cov = 0.5 * (cov + cov.t())\n"
    << "        L = cov.size(0)\n"
    << "        eg = torch.linalg_eigh(0.5 * (cov + cov.t()))\n"
    << "        e = eg[0]\n        U = eg[1]\n"
    << "        keep = torch.nonzero(e > 1e-14 * e.abs().max().clamp_min(1e-300)).flatten()\n"
    << "        V = torch.index_select(U * e.clamp_min(0.0).sqrt().view([1, L]), 1, keep)\n"
    << "        Vq = (Om.unsqueeze(2) * V.unsqueeze(0)).transpose(1, 2).reshape([-1, L]).contiguous()\n"
    << "        return (mw, cov, Vq)\n";
  m.define(w.str());
}

// box_mean and guided(guide, p, r, eps): guided_filter.cpp, line for line.
void define_guided_filter(torch::jit::Module& m) {
  m.define(
      "def box_mean(self, x: Tensor, r: int) -> Tensor:\n"
      "        if r == 0:\n            return x\n"
      "        return torch.avg_pool2d(x, [2 * r + 1, 2 * r + 1], [1, 1], [r, r], False, False)\n"
      "def guided(self, I: Tensor, p: Tensor, r: int, eps: float) -> Tensor:\n"
      "        mI = self.box_mean(I, r)\n        mp = self.box_mean(p, r)\n"
      "        var = (self.box_mean(I * I, r) - mI * mI).clamp_min(0.0)\n"
      "        cov = self.box_mean(I * p, r) - mI * mp\n"
      "        a = cov / (var + eps)\n        b = mp - a * mI\n"
      "        return self.box_mean(a, r) * I + self.box_mean(b, r)\n");
}

// forward(image) -> (hs, depth): HsdNetImpl::forward (unet.cpp) as TorchScript
// source, for the network's levels, normalisation and residual.
std::string forward_source(const NetOptions& opt) {
  if (opt.defocus_cost == DefocusCost::grey)
    throw InputError("export: model.defocus_cost = \"grey\" (an experimental input) has no TorchScript form; train without it to export");
  const int64_t L = opt.levels, mult = int64_t(1) << L;
  const bool pre = opt.preinverse_layers > 0;
  std::ostringstream o;
  o << "def forward(self, image: Tensor) -> Tuple[Tensor, Tensor]:\n"
    << "        B = image.size(0)\n        C = image.size(1)\n        H = image.size(2)\n        W = image.size(3)\n"
    << "        ph = (" << mult << " - H % " << mult << ") % " << mult << "\n"
    << "        pw = (" << mult << " - W % " << mult << ") % " << mult << "\n"
    // The network runs in the dtype of its weights (float32 as exported; bfloat16
    // after set_reconstructor_precision), in the input's memory format (`to`
    // keeps it; run_reconstructor passes channels-last); the outputs are float32.
    << "        x = image\n"
    << "        base = image.float()\n";  // the cube residual's base (unet.cpp)
  if (opt.residual_spectral_wiener) o << "        sw_base = self.sw_cube(image.float())\n";
  if (pre) {
    o << "        pin = self.preinverse(image.float())\n"
      << "        x = torch.cat([image, pin.to(image.dtype)], 1)\n";
    if (opt.residual_preinverse)
      o << "        base = pin.reshape([B, " << opt.preinverse_layers << ", C, H, W]).mean(1)\n";
  }
  // The cube the residual is added to, cb [B, L, H, W] float32 (unet.cpp's cube_base).
  if (opt.residual_spectral_wiener)
    o << "        cb = sw_base\n";
  else
    o << "        Lb = self.p_upsampling_weights.size(0)\n"
      << "        up = torch.mm(self.p_upsampling_weights.float(), base.permute([1, 0, 2, 3]).reshape([C, B * H * W]))\n"
      << "        cb = up.reshape([Lb, B, H, W]).permute([1, 0, 2, 3])\n";
  if (opt.base_as_input) o << "        x = torch.cat([x, cb.to(x.dtype)], 1)\n";
  if (opt.defocus_cost == DefocusCost::spectral)
    o << "        x = torch.cat([x, self.reader_cost(image.float(), " << kDefocusInputWindowPx << ").to(x.dtype)], 1)\n";
  o
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
    << "        d = torch.conv2d(y_depth, self.p_head_depth_weight, self.p_head_depth_bias, [1, 1], [0, 0], [1, 1], 1)\n"
    << "        hs = hs[:, :, 0:H, 0:W].float().contiguous()\n"
    << "        d = d[:, :, 0:H, 0:W].float().contiguous()\n";
  if (opt.depth_bins >= 2)  // the soft argmax over the bins' centres k/(N-1) (unet.cpp)
    o << "        t = (torch.cumsum(d.new_ones([" << opt.depth_bins << "]), 0) - 1.0) / " << c10::str(double(opt.depth_bins - 1))
      << "\n"
      << "        d = (torch.softmax(d, 1) * t.view([1, " << opt.depth_bins << ", 1, 1])).sum(1, keepdim=True)\n";
  else
    o << "        d = torch.sigmoid(d)\n";
  o << "        hs = hs + cb\n"
    << "        inv_far = 1.0 / " << c10::str(opt.depth_max_m) << "\n"
    << "        inv_near = 1.0 / " << c10::str(opt.depth_min_m) << "\n"
    << "        depth = 1.0 / (inv_far + d * (inv_near - inv_far))\n";
  if (opt.fuse_defocus_reader) {  // the spectral reader's depth, fused in metres (depth_fusion.h)
    const FusionSettings& fs = opt.fusion;
    const std::string eps = "float(" + c10::str(fs.guide_eps) + ")";
    o << "        g = hs.mean(1, keepdim=True)\n"
      << "        g = g / g.abs().mean([2, 3], keepdim=True).clamp_min(1e-12)\n"
      << "        c = self.guided(g, self.reader_cost(image.float(), " << fs.reader_box_px << "), " << fs.cost_radius_px
      << ", " << eps << ")\n"
      << "        least, _ = torch.min(c, 1, True)\n"  // defocus_layer_depth: tied layers averaged
      << "        tie = (c <= least + " << c10::str(kLayerTieNats) << ").float()\n"
      << "        zk = self.layer_depths_m.float().view([1, -1, 1, 1])\n"
      << "        zr = (tie * zk).sum(1, keepdim=True) / tie.sum(1, keepdim=True)\n"
      << "        depth = self.guided(g, 0.5 * (depth + zr), " << fs.depth_radius_px << ", " << eps << ")\n"
      << "        depth = depth.clamp(" << c10::str(opt.depth_min_m) << ", " << c10::str(opt.depth_max_m) << ")\n";
  }
  o << "        return (hs, depth)\n";
  return o.str();
}

}  // namespace

torch::jit::Module export_torchscript(HsdNet& net, const ExportMetadata& meta) {
  if (net->options().edge_prior.weight > 0)
    throw InputError("export: model.edge_prior_weight > 0 (an evaluation-time experiment, docs/learning.md) has no "
                     "TorchScript form; export with --set model.edge_prior_weight=0");
  if (net->options().project_residual)
    throw InputError("export: model.project_residual (an experiment, docs/learning.md) has no TorchScript form; train "
                     "without it to export");
  if (net->options().refine_width > 0)
    throw InputError("export: model.refine_width > 0 (a second stage for the cube, an experiment, docs/learning.md) has "
                     "no TorchScript form; train without it to export");
  torch::jit::Module m("HsdReconstructor");
  torch::NoGradGuard no_grad;
  register_weights(m, net, meta);
  if (net->options().preinverse_layers > 0 || net->options().residual_spectral_wiener) define_fast_fft_size(m);
  if (net->options().preinverse_layers > 0) define_preinverse(m, net);
  if (net->options().residual_spectral_wiener) {
    define_spectral_wiener(m, net);
    define_spectral_defocus(m);
    if (net->options().read_illuminant) define_illuminant_reader(m, net);
    define_prior_users(m, net->options());
  }
  if (net->options().fuse_defocus_reader) {
    m.register_buffer("layer_depths_m", torch::tensor(net->options().layer_depths_m, torch::kFloat64));
    define_guided_filter(m);
  }
  m.define(forward_source(net->options()));
  m.eval();
  return m;
}

void set_reconstructor_precision(torch::jit::Module& m, c10::ScalarType dtype) {
  if (dtype != torch::kFloat32 && dtype != torch::kBFloat16)
    throw InputError("reconstructor precision must be float32 or bfloat16");
  torch::NoGradGuard ng;
  auto convert = [&](const std::string& name, torch::Tensor t) {
    if (name.find("upsampling") != std::string::npos || name.find("preinverse") != std::string::npos ||
        name.find("sw_") != std::string::npos || name.rfind("il_", 0) == 0 ||
        !t.is_floating_point())
      return;  // the residual, the pre-inversion, the spectral Wiener base and the illuminant reader keep their dtype
    torch::Tensor v = t.detach().to(dtype);
    if (v.dim() == 4) v = v.contiguous(at::MemoryFormat::ChannelsLast);
    t.set_data(v);
  };
  for (const auto& p : m.named_parameters(false)) convert(p.name, p.value);
  for (const auto& b : m.named_buffers(false)) convert(b.name, b.value);
}

namespace {

// (hs, depth) from a forward's result, checked against the input x [B, 3, H, W]
// and the module's L bands; `who` names the model in the error.
std::pair<torch::Tensor, torch::Tensor> checked_outputs(const c10::IValue& r, const torch::Tensor& x, int64_t L,
                                                        const std::string& who) {
  auto bad = [&](const std::string& what) -> std::pair<torch::Tensor, torch::Tensor> {
    throw InputError(who + ": not an hsd reconstructor: " + what + " (make it with hsd_export)");
  };
  if (!r.isTuple() || r.toTupleRef().elements().size() != 2) return bad("forward must return a pair (hs, depth)");
  const auto& e = r.toTupleRef().elements();
  if (!e[0].isTensor() || !e[1].isTensor()) return bad("forward must return two tensors");
  const torch::Tensor hs = e[0].toTensor(), depth = e[1].toTensor();
  const int64_t B = x.size(0), H = x.size(2), W = x.size(3);
  auto shape = [](const torch::Tensor& t) { return c10::str(t.sizes()); };
  if (hs.sizes() != c10::IntArrayRef{B, L, H, W})
    return bad("its cube is " + shape(hs) + " for an input " + shape(x) + " (expected [" + std::to_string(B) + ", " +
               std::to_string(L) + ", " + std::to_string(H) + ", " + std::to_string(W) + "])");
  if (depth.sizes() != c10::IntArrayRef{B, 1, H, W})
    return bad("its depth map is " + shape(depth) + " for an input " + shape(x));
  return {hs, depth};
}

int64_t band_count(const torch::jit::Module& m) { return m.attr("wavelengths_m").toTensor().numel(); }

}  // namespace

torch::jit::Module load_reconstructor(const std::string& path) {
  std::error_code ec;
  if (!std::filesystem::exists(path, ec)) throw InputError(path + ": no such file (an exported reconstructor.pt)");
  if (!std::filesystem::is_regular_file(path, ec)) throw InputError(path + ": not a file (an exported reconstructor.pt)");
  torch::jit::Module m;
  try {
    m = torch::jit::load(path);
  } catch (const c10::Error& e) {
    std::string why = e.what_without_backtrace();
    why = why.substr(0, why.find('\n'));
    throw InputError(path + ": not a TorchScript module (" + why.substr(0, 160) + ")");
  } catch (const std::exception& e) {
    std::string why = e.what();
    throw InputError(path + ": not a TorchScript module (" + why.substr(0, why.find('\n')).substr(0, 160) + ")");
  }
  if (!m.hasattr("wavelengths_m") || !m.hasattr("depth_range_m") || !m.find_method("forward"))
    throw InputError(path + ": is not an hsd reconstructor (needs forward, wavelengths_m and depth_range_m; make it with hsd_export)");
  const c10::IValue wl = m.attr("wavelengths_m"), range = m.attr("depth_range_m");
  if (!wl.isTensor() || wl.toTensor().dim() != 1 || wl.toTensor().numel() < 1 || !first_nonfinite(wl.toTensor()).empty() ||
      !(wl.toTensor().min().item<double>() > 0))
    throw InputError(path + ": attribute wavelengths_m must be a 1-D tensor of finite positive wavelengths");
  if (!range.isTensor() || range.toTensor().numel() != 2 || !first_nonfinite(range.toTensor()).empty() ||
      !(range.toTensor()[0].item<double>() > 0 && range.toTensor()[1].item<double>() > range.toTensor()[0].item<double>()))
    throw InputError(path + ": attribute depth_range_m must be two finite depths, near < far");
  for (const auto& a : m.named_attributes(/*recurse=*/true))
    if (a.value.isTensor()) {
      const std::string bad = first_nonfinite(a.value.toTensor());
      if (!bad.empty()) throw InputError(path + ": tensor " + a.name + " holds " + bad);
    }
  m.eval();
  // A probe: 1 x 3 x 32 x 32 zeros must give a cube and a depth map of that size.
  {
    torch::NoGradGuard ng;
    const torch::Tensor probe = torch::zeros({1, 3, 32, 32});
    c10::IValue r;
    try {
      r = m.forward({probe});
    } catch (const std::exception& e) {
      std::string why = e.what();
      throw InputError(path + ": its forward fails on a 1x3x32x32 image (" + why.substr(0, why.find('\n')).substr(0, 160) + ")");
    }
    const auto [hs, depth] = checked_outputs(r, probe, band_count(m), path);
    for (const auto& [t, what] : {std::pair<const torch::Tensor&, const char*>{hs, "cube"}, {depth, "depth map"}}) {
      const std::string bad = first_nonfinite(t);
      if (!bad.empty()) throw InputError(path + ": its " + what + " for a black 32x32 image holds " + bad);
    }
  }
  return m;
}

std::pair<torch::Tensor, torch::Tensor> run_reconstructor(torch::jit::Module& m, const torch::Tensor& x) {
  // channels-last: oneDNN's convolutions run about 1.3x faster than in NCHW
  const c10::IValue r = m.forward({x.dim() == 4 ? x.contiguous(at::MemoryFormat::ChannelsLast) : x});
  return checked_outputs(r, x, band_count(m), "the reconstructor");
}

}  // namespace hsd::model
