// PSFs shared out over data-parallel ranks. Each rank needs the PSFs of the
// bands and depth layers its slice of the batch occupies; computing them all
// on every rank repeats the same work W times (on the paper config the PSFs
// are a fifth of a step, whatever a rank's share of the batch). Here the union
// of what the ranks need (one small sum) is split by bands: rank r computes a
// contiguous share of the union's bands for the union's layers, one sum
// assembles the whole set on every rank, and in backward one sum gathers all
// ranks' gradients for the PSFs, so each rank backpropagates its own bands
// into the height map. A rank's height gradient then holds its bands' part of
// ∂(Σ_r L_r)/∂h; averaging gradients over ranks (as for every parameter)
// gives ∂(mean loss)/∂h, which is what one process computes.
#pragma once
#include <memory>

#include "model/replica_group.h"
#include "optics/psf.h"
#include "optics/sensor.h"

namespace hsd::train {

// A provider for optics::simulate_sensor: (height [N, N], layers, bands) ->
// PSFs [bands, layers, P, P] equal to sim.compute(height, layers, {}, bands).psf.
// Every rank must call it the same number of times (simulate_sensor does,
// once per call); `sim` and `group` must outlive it.
optics::PsfProvider make_shared_psf_provider(const optics::PsfSimulator& sim, std::shared_ptr<model::ReplicaGroup> group);

}  // namespace hsd::train
