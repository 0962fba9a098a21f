// A gradient scale: the identity in the forward pass, k times the gradient in
// the backward pass. The trainer puts it on the spectral Wiener base's path
// (train.base_doe_gradient_scale), so that the cube term reaches the DOE
// through the linear estimate k times as strongly as through the U-Net, while
// the network's parameters, on which the base does not depend, train as
// before. Not an equation of the paper: a re-weighting of one path of its
// Eq. 7 loss's gradient into the height map.
#pragma once
#include <torch/torch.h>

namespace hsd::train {

// x: any tensor. Returns x itself when k == 1 or x has no gradient (bitwise
// the same graph as without the scale); otherwise a tensor equal to x whose
// backward multiplies the incoming gradient by k. k must be finite.
torch::Tensor scale_gradient(const torch::Tensor& x, double k);

}  // namespace hsd::train
