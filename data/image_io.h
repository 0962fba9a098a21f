// Image files: reading any raster a user gives (checked before decoding), and
// preview pictures: linear RGB -> sRGB-encoded 8-bit PNG (IEC 61966-2-1
// transfer curve), written atomically.
#pragma once
#include <string>

#include <opencv2/core/mat.hpp>

#include <torch/types.h>

namespace hsd::data {

// The IEC 61966-2-1 decoding: sRGB-encoded values in [0, 1] -> linear, any shape.
torch::Tensor srgb_to_linear(const torch::Tensor& encoded);

// cv::imread(path, flags) with every failure an InputError naming the file
// (exit 2): a missing file, a PNG whose header is not a PNG's, claims a size
// of 0 or over 2^28 pixels, or whose file is cut before its end chunk (checked
// before decoding, so no decoder prints its own lines), an image OpenCV cannot
// decode or refuses. `what` names the flag or key the path came from.
cv::Mat read_image(const std::string& path, int flags, const std::string& what);

// rgb float [3, H, W], linear; values are clipped to [0, white] and scaled by 1/white.
void write_srgb_png(const std::string& path, const torch::Tensor& rgb, double white = 1.0);

}  // namespace hsd::data
