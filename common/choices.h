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
enum class ResidualBase { image, preinverse };
// train.decay: the learning rate after the warm-up.
enum class LrDecay { cosine, none };
// train.depth_loss: the depth term in inverse depth or in metres.
enum class DepthLoss { inverse_l1, metric_l1 };
// train.precision: the network's training arithmetic ("auto": by the CPU's flags).
enum class TrainPrecision { float32, bfloat16, automatic };
// calibration.registration and calibration.background (hsd_calibrate).
enum class Registration { automatic, centroid, axis };
enum class CaptureBackground { automatic, dark, ring };

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
constexpr ChoiceTable<ResidualBase, 2> choice_names(ResidualBase) {
  return {{{ResidualBase::image, "image"}, {ResidualBase::preinverse, "preinverse"}}};
}
constexpr ChoiceTable<LrDecay, 2> choice_names(LrDecay) {
  return {{{LrDecay::cosine, "cosine"}, {LrDecay::none, "none"}}};
}
constexpr ChoiceTable<DepthLoss, 2> choice_names(DepthLoss) {
  return {{{DepthLoss::inverse_l1, "inverse_l1"}, {DepthLoss::metric_l1, "metric_l1"}}};
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

// The choice at `key` (fallback when absent); InputError naming the key otherwise.
template <class E>
E read_choice(const JsonReader& r, const std::string& key, E fallback) {
  const std::string word = r.get_string(key, choice_name(fallback));
  for (const auto& [v, name] : choice_names(E{}))
    if (word == name) return v;
  r.fail(key, "expected " + choice_list<E>() + ", got \"" + word + "\"");
}

}  // namespace hsd
