// The config's choices among named values (optics.aperture_shape,
// optics.pupil_cell_integration, sensor.compositing, model.norm,
// fisher.basis and every other key of a fixed set of words): each parsed once, at the edge, into an enum class, so the
// libraries compare types, never strings. choice_names(E{}) lists an enum's
// (value, name) pairs in the order the docs give them; choice_name(e) is the
// config's word for e; read_choice reads a key (InputError naming the key and
// the choices for any other word).
#pragma once
#include <array>
#include <cstddef>
#include <string>
#include <utility>
#include <vector>

#include "common/json_reader.h"

namespace hsd {

enum class ApertureShape { circle, square };
// How each DOE cell is integrated (optics/fresnel_mft.h): the smooth phases'
// linear part across the cell with the cross term, without it, or cell centres.
enum class CellIntegration { sinc_cross, sinc, midpoint };
// Depth layers into one image: the paper's linear sum, or Ikoma et al.'s occlusion.
enum class Compositing { linear, occlusion };
enum class NormKind { batch, group, none };
// The Fisher design's parameters: Zernike coefficients or every DOE sample.
enum class FisherBasis { zernike, freeform };
// optics.precision: the PSF's arithmetic (phases are always built in float64).
enum class FloatPrecision { float32, float64 };
// optics.psf_backward: keep every band's intermediates, or recompute them in the backward pass.
enum class PsfBackward { store, recompute };
// fisher.start: the design's start, the unwrapped Fresnel lens or a flat plate.
enum class FisherStart { fresnel, flat };
// fisher.aggregate: how the CRLB's grid points are summed up (optics/fisher.h).
enum class CrlbAggregate { capped_mean, median, mean };
// fisher.model: the CRLB of a point source or of a textured scene.
enum class FisherModel { point, scene };
// model.head_init: the output heads start at the baselines or at torch's initialisation.
enum class HeadInit { baselines, random };
// model.preinverse: the network's input beside the image.
enum class Preinverse { none, wiener };
// model.residual: what the cube head's output is added to.
enum class ResidualBase { image, preinverse, spectral_wiener };
// model.defocus_cost: a classical depth-from-defocus cost volume as more input
// (model/defocus_likelihood.h): none, the grey per-channel reader, or the
// reader with the spectral Wiener cube's spectral prior.
enum class DefocusCost { none, grey, spectral };
// model.spectral_map: the residual's RGB -> bands map fixed (the paper's) or learned.
enum class SpectralMap { fixed, learned };
// train.decay: the learning rate after the warm-up.
enum class LrDecay { cosine, none };
// train.depth_loss: the depth term in inverse depth or in metres.
enum class DepthLoss { inverse_l1, metric_l1, metric_l2 };
// train.hs_loss: the cube term's absolute error (the paper) or squared error (PSNR's).
enum class HsLoss { l1, l2 };
// train.precision: the network's training arithmetic ("auto": by the CPU's flags).
enum class TrainPrecision { float32, bfloat16, automatic };
// calibration.registration and calibration.background (hsd_calibrate).
enum class Registration { automatic, centroid, axis };
enum class CaptureBackground { automatic, dark, ring };
// device: where tensors live (a CUDA build of LibTorch for "cuda").
enum class ComputeDevice { cpu, cuda };
// data.generator.layouts: the scene layouts (data/textured_scene.h).
enum class SceneLayout { tabletop, dead_leaves, classic_tabletop };
// data.generator.texture_filter: a photo read once per scene pixel, or averaged over its footprint.
enum class TextureFilter { point, area };
// fisher.nuisance lists parameters unknown besides (1/z, λ): the source's
// position x, y and its brightness N (optics/fisher.h).
enum class NuisanceParam { x, y, N };
// Choices whose last value names a file, written "file:PATH" (read_choice_or_file):
// optics.doe.init, a height-map family or a height-map file;
enum class DoeFamily { fresnel, spiral, fisher, flat, random, file };
// optics.psf_source, the DOE's simulated PSFs, the all-in-focus control or a PSF file.
enum class PsfSource { simulator, all_in_focus, file };

template <class E, size_t N>
using ChoiceTable = std::array<std::pair<E, const char*>, N>;

constexpr ChoiceTable<ApertureShape, 2> choice_names(ApertureShape) {
  return {{{ApertureShape::circle, "circle"}, {ApertureShape::square, "square"}}};
}
constexpr ChoiceTable<CellIntegration, 3> choice_names(CellIntegration) {
  return {{{CellIntegration::sinc_cross, "sinc_cross"}, {CellIntegration::sinc, "sinc"}, {CellIntegration::midpoint, "midpoint"}}};
}
constexpr ChoiceTable<Compositing, 2> choice_names(Compositing) {
  return {{{Compositing::linear, "linear"}, {Compositing::occlusion, "occlusion"}}};
}
constexpr ChoiceTable<NormKind, 3> choice_names(NormKind) {
  return {{{NormKind::batch, "batch"}, {NormKind::group, "group"}, {NormKind::none, "none"}}};
}
constexpr ChoiceTable<TextureFilter, 2> choice_names(TextureFilter) {
  return {{{TextureFilter::point, "point"}, {TextureFilter::area, "area"}}};
}
constexpr ChoiceTable<FisherBasis, 2> choice_names(FisherBasis) {
  return {{{FisherBasis::zernike, "zernike"}, {FisherBasis::freeform, "freeform"}}};
}

constexpr ChoiceTable<FloatPrecision, 2> choice_names(FloatPrecision) {
  return {{{FloatPrecision::float32, "float32"}, {FloatPrecision::float64, "float64"}}};
}
constexpr ChoiceTable<PsfBackward, 2> choice_names(PsfBackward) {
  return {{{PsfBackward::store, "store"}, {PsfBackward::recompute, "recompute"}}};
}
constexpr ChoiceTable<FisherStart, 2> choice_names(FisherStart) {
  return {{{FisherStart::fresnel, "fresnel"}, {FisherStart::flat, "flat"}}};
}
constexpr ChoiceTable<CrlbAggregate, 3> choice_names(CrlbAggregate) {
  return {{{CrlbAggregate::capped_mean, "capped_mean"}, {CrlbAggregate::median, "median"}, {CrlbAggregate::mean, "mean"}}};
}
constexpr ChoiceTable<FisherModel, 2> choice_names(FisherModel) {
  return {{{FisherModel::point, "point"}, {FisherModel::scene, "scene"}}};
}
constexpr ChoiceTable<HeadInit, 2> choice_names(HeadInit) {
  return {{{HeadInit::baselines, "baselines"}, {HeadInit::random, "random"}}};
}
constexpr ChoiceTable<Preinverse, 2> choice_names(Preinverse) {
  return {{{Preinverse::none, "none"}, {Preinverse::wiener, "wiener"}}};
}
constexpr ChoiceTable<ResidualBase, 3> choice_names(ResidualBase) {
  return {{{ResidualBase::image, "image"}, {ResidualBase::preinverse, "preinverse"},
           {ResidualBase::spectral_wiener, "spectral_wiener"}}};
}
constexpr ChoiceTable<DefocusCost, 3> choice_names(DefocusCost) {
  return {{{DefocusCost::none, "none"}, {DefocusCost::grey, "grey"}, {DefocusCost::spectral, "spectral"}}};
}
constexpr ChoiceTable<SpectralMap, 2> choice_names(SpectralMap) {
  return {{{SpectralMap::fixed, "fixed"}, {SpectralMap::learned, "learned"}}};
}
constexpr ChoiceTable<LrDecay, 2> choice_names(LrDecay) {
  return {{{LrDecay::cosine, "cosine"}, {LrDecay::none, "none"}}};
}
constexpr ChoiceTable<DepthLoss, 3> choice_names(DepthLoss) {
  return {{{DepthLoss::inverse_l1, "inverse_l1"}, {DepthLoss::metric_l1, "metric_l1"}, {DepthLoss::metric_l2, "metric_l2"}}};
}
constexpr ChoiceTable<HsLoss, 2> choice_names(HsLoss) {
  return {{{HsLoss::l1, "l1"}, {HsLoss::l2, "l2"}}};
}
constexpr ChoiceTable<TrainPrecision, 3> choice_names(TrainPrecision) {
  return {{{TrainPrecision::float32, "float32"}, {TrainPrecision::bfloat16, "bfloat16"}, {TrainPrecision::automatic, "auto"}}};
}
constexpr ChoiceTable<Registration, 3> choice_names(Registration) {
  return {{{Registration::automatic, "auto"}, {Registration::centroid, "centroid"}, {Registration::axis, "axis"}}};
}
constexpr ChoiceTable<CaptureBackground, 3> choice_names(CaptureBackground) {
  return {{{CaptureBackground::automatic, "auto"}, {CaptureBackground::dark, "dark"}, {CaptureBackground::ring, "ring"}}};
}
constexpr ChoiceTable<ComputeDevice, 2> choice_names(ComputeDevice) {
  return {{{ComputeDevice::cpu, "cpu"}, {ComputeDevice::cuda, "cuda"}}};
}
constexpr ChoiceTable<SceneLayout, 3> choice_names(SceneLayout) {
  return {{{SceneLayout::tabletop, "tabletop"}, {SceneLayout::dead_leaves, "dead_leaves"},
           {SceneLayout::classic_tabletop, "classic_tabletop"}}};
}
constexpr ChoiceTable<NuisanceParam, 3> choice_names(NuisanceParam) {
  return {{{NuisanceParam::x, "x"}, {NuisanceParam::y, "y"}, {NuisanceParam::N, "N"}}};
}
constexpr ChoiceTable<DoeFamily, 6> choice_names(DoeFamily) {
  return {{{DoeFamily::fresnel, "fresnel"}, {DoeFamily::spiral, "spiral"}, {DoeFamily::fisher, "fisher"},
           {DoeFamily::flat, "flat"}, {DoeFamily::random, "random"}, {DoeFamily::file, "file:PATH"}}};
}
constexpr ChoiceTable<PsfSource, 3> choice_names(PsfSource) {
  return {{{PsfSource::simulator, "simulator"}, {PsfSource::all_in_focus, "all_in_focus"}, {PsfSource::file, "file:PATH"}}};
}

// The config's word for e.
template <class E>
std::string choice_name(E e) {
  for (const auto& [v, name] : choice_names(E{}))
    if (v == e) return name;
  return "?";
}

// "\"a\", \"b\" or \"c\"": the words a key accepts, for messages.
template <class E>
std::string choice_list() {
  const auto t = choice_names(E{});
  std::string s;
  for (size_t i = 0; i < t.size(); ++i) s += std::string(i == 0 ? "" : i + 1 == t.size() ? " or " : ", ") + "\"" + t[i].second + "\"";
  return s;
}

// The choice a word names; false when it names none.
template <class E>
bool choice_of(const std::string& word, E* out) {
  for (const auto& [v, name] : choice_names(E{}))
    if (word == name) return *out = v, true;
  return false;
}

// The choice at `key` (fallback when absent); InputError naming the key otherwise.
template <class E>
E read_choice(const JsonReader& r, const std::string& key, E fallback) {
  const std::string word = r.get_string(key, choice_name(fallback));
  E v;
  if (!choice_of(word, &v)) r.fail(key, "expected " + choice_list<E>() + ", got \"" + word + "\"");
  return v;
}

// A list of distinct choices at `key` (fallback when absent); InputError
// naming the key for an unknown or repeated word.
template <class E>
std::vector<E> read_choice_list(const JsonReader& r, const std::string& key, const std::vector<E>& fallback) {
  if (!r.has(key)) return fallback;
  std::vector<E> out;
  for (const std::string& word : r.get_string_array(key)) {
    E v;
    if (!choice_of(word, &v)) r.fail(key, "\"" + word + "\" is not one of " + choice_list<E>());
    for (E u : out)
      if (u == v) r.fail(key, "lists \"" + word + "\" twice");
    out.push_back(v);
  }
  return out;
}

// The config's word for a choice with a file: "file:" + path for E::file.
template <class E>
std::string choice_word(E e, const std::string& path) {
  return e == E::file ? "file:" + path : choice_name(e);
}

// A choice whose value E::file is written "file:PATH": the value at `key`
// (fallback and fallback_path when absent), its path in *path (empty unless
// E::file); InputError naming the key for any other word or an empty path.
template <class E>
E read_choice_or_file(const JsonReader& r, const std::string& key, E fallback, const std::string& fallback_path,
                      std::string* path) {
  const std::string word = r.get_string(key, choice_word(fallback, fallback_path));
  path->clear();
  if (word.rfind("file:", 0) == 0) {
    if (word.size() == 5) r.fail(key, "\"file:\" needs a path after the colon");
    *path = word.substr(5);
    return E::file;
  }
  for (const auto& [v, name] : choice_names(E{}))
    if (v != E::file && word == name) return v;
  r.fail(key, "expected " + choice_list<E>() + ", got \"" + word + "\"");
}

}  // namespace hsd
