#include "common/atomic_file.h"

#include <cerrno>
#include <cstdio>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <iterator>
#include <unistd.h>

#include "common/error.h"

namespace hsd {
namespace fs = std::filesystem;

void write_atomically(const std::string& path, const std::function<void(const std::string&)>& write) {
  check_output_paths({path});
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
    input_error(path, "cannot write the output file (" + ec.message() + ")");
  }
}

void write_binary_file(const std::string& path, const std::vector<char>& bytes) {
  write_atomically(path, [&](const std::string& tmp) {
    std::ofstream f(tmp, std::ios::binary);
    if (!f) input_error(path, std::string("cannot open for writing (") + std::strerror(errno) + ")");
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
  if (!f) input_error(path, std::string("cannot open for reading (") + std::strerror(errno) + ")");
  return std::vector<char>(std::istreambuf_iterator<char>(f), std::istreambuf_iterator<char>());
}

std::string read_text_file(const std::string& path) {
  auto b = read_binary_file(path);
  return std::string(b.begin(), b.end());
}

void make_dirs(const std::string& dir) {
  std::error_code ec;
  if (dir.empty()) input_error("--out", "empty folder name");
  if (fs::exists(dir, ec) && !fs::is_directory(dir, ec)) input_error(dir, "exists and is not a folder (wanted an output folder)");
  fs::create_directories(dir, ec);
  if (ec) input_error(dir, "cannot create the output folder (" + ec.message() + ")");
  if (!fs::is_directory(dir, ec)) input_error(dir, "cannot create the output folder");
  if (::access(dir.c_str(), W_OK | X_OK) != 0) input_error(dir, std::string("output folder not writable (") + std::strerror(errno) + ")");
}

void check_output_paths(const std::vector<std::string>& paths) {
  std::error_code ec;
  for (const auto& p : paths) {
    if (fs::is_directory(p, ec)) input_error(p, "is a folder; an output file of this name cannot be written");
    const fs::path parent = fs::path(p).parent_path();
    if (parent.empty()) continue;
    if (fs::exists(parent, ec)) {
      if (!fs::is_directory(parent, ec)) input_error(parent.string(), "exists and is not a folder (needed for " + p + ")");
      if (::access(parent.c_str(), W_OK | X_OK) != 0)
        input_error(parent.string(), std::string("folder not writable (") + std::strerror(errno) + ")");
    }
  }
}

}  // namespace hsd
