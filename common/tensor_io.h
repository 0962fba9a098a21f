// .pt files as in docs/formats.md: torch pickles (torch::pickle_save) of a dict
// from string to tensor, readable by Python's torch.load. Scalars are stored as
// 0-dim tensors.
#pragma once
#include <map>
#include <string>

#include <torch/types.h>

namespace hsd {

using TensorDict = std::map<std::string, torch::Tensor>;
using StringDict = std::map<std::string, std::string>;

// Writes atomically (temp file + rename). Tensors are moved to CPU first.
// `strings`: text entries stored beside the tensors in the same dict (e.g.
// psf.pt's source = "measured"); Python's torch.load reads them as str.
void save_tensor_dict(const std::string& path, const TensorDict& dict, const StringDict& strings = {});
// InputError naming the file if it is missing, not a torch pickle or not a dict of tensors.
// Text entries go to *strings when given (ignored otherwise).
TensorDict load_tensor_dict(const std::string& path, StringDict* strings = nullptr);
// The entry `key` of a loaded dict; InputError naming file and key if missing.
torch::Tensor dict_get(const TensorDict& d, const std::string& key, const std::string& file);

}  // namespace hsd
