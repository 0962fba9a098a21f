#include "common/atomic_file.h"

#include <cstdio>
#include <filesystem>
#include <fstream>
#include <iterator>
#include <unistd.h>

#include "common/error.h"

namespace hsd {
namespace fs = std::filesystem;

void write_atomically(const std::string& path, const std::function<void(const std::string&)>& write) {
  const std::string tmp = path + ".tmp." + std::to_string(::getpid());
  try {
    write(tmp);
  } catch (...) {
    std::error_code ec;
    fs::remove(tmp, ec);
    throw;
  }
  std::error_code ec;
  fs::rename(tmp, path, ec);
  if (ec) {
    fs::remove(tmp, ec);
    input_error(path, "cannot write output file (" + ec.message() + ")");
  }
}

void write_binary_file(const std::string& path, const std::vector<char>& bytes) {
  write_atomically(path, [&](const std::string& tmp) {
    std::ofstream f(tmp, std::ios::binary);
    if (!f) input_error(path, "cannot open for writing");
    f.write(bytes.data(), std::streamsize(bytes.size()));
    f.close();
    if (!f) input_error(path, "write failed (disk full?)");
  });
}

void write_text_file(const std::string& path, const std::string& text) {
  write_binary_file(path, std::vector<char>(text.begin(), text.end()));
}

std::vector<char> read_binary_file(const std::string& path) {
  std::error_code ec;
  if (!fs::is_regular_file(path, ec)) input_error(path, "no such file");
  std::ifstream f(path, std::ios::binary);
  if (!f) input_error(path, "cannot open for reading");
  return std::vector<char>(std::istreambuf_iterator<char>(f), std::istreambuf_iterator<char>());
}

std::string read_text_file(const std::string& path) {
  auto b = read_binary_file(path);
  return std::string(b.begin(), b.end());
}

void make_dirs(const std::string& dir) {
  std::error_code ec;
  fs::create_directories(dir, ec);
  if (ec || !fs::is_directory(dir)) input_error(dir, "cannot create output folder (" + ec.message() + ")");
}

}  // namespace hsd
