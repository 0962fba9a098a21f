#include "common/tensor_io.h"

#include <torch/torch.h>

#include "common/atomic_file.h"
#include "common/error.h"

namespace hsd {

void save_tensor_dict(const std::string& path, const TensorDict& dict, const StringDict& strings) {
  std::vector<char> bytes;
  if (strings.empty()) {
    c10::Dict<std::string, at::Tensor> d;
    for (const auto& [k, v] : dict) d.insert(k, v.detach().cpu().contiguous());
    bytes = torch::pickle_save(c10::IValue(d));
  } else {
    c10::impl::GenericDict d(c10::StringType::get(), c10::AnyType::get());
    for (const auto& [k, v] : dict) d.insert(k, v.detach().cpu().contiguous());
    for (const auto& [k, v] : strings) d.insert(k, v);
    bytes = torch::pickle_save(c10::IValue(d));
  }
  write_binary_file(path, bytes);
}

TensorDict load_tensor_dict(const std::string& path, StringDict* strings) {
  const std::vector<char> bytes = read_binary_file(path);
  c10::IValue v;
  try {
    v = torch::pickle_load(bytes);
  } catch (const std::exception& e) {
    input_error(path, "not a readable torch pickle (.pt) file");
  }
  if (!v.isGenericDict()) input_error(path, "expected a dict of tensors");
  TensorDict out;
  for (const auto& item : v.toGenericDict()) {
    if (!item.key().isString()) input_error(path, "dict keys must be strings");
    const std::string k = item.key().toStringRef();
    const c10::IValue& val = item.value();
    if (val.isTensor()) out[k] = val.toTensor();
    else if (val.isDouble()) out[k] = torch::tensor(val.toDouble(), torch::kFloat64);
    else if (val.isInt()) out[k] = torch::tensor(val.toInt(), torch::kInt64);
    else if (val.isString() && strings) (*strings)[k] = val.toStringRef();
    // other values (lists, ...) are metadata; ignored here
  }
  return out;
}

torch::Tensor dict_get(const TensorDict& d, const std::string& key, const std::string& file) {
  auto it = d.find(key);
  if (it == d.end()) input_error(file, "missing entry '" + key + "'");
  return it->second;
}

}  // namespace hsd
