// Output files appear whole or not at all: write to "<path>.tmp.<pid>", then
// rename over the final name (atomic on POSIX file systems).
#pragma once
#include <functional>
#include <string>
#include <vector>

namespace hsd {

// Calls write(tmp_path) and renames tmp_path to `path`. If write throws, the
// temporary file is removed and the exception propagates; `path` is untouched.
void write_atomically(const std::string& path, const std::function<void(const std::string&)>& write);

void write_text_file(const std::string& path, const std::string& text);
void write_binary_file(const std::string& path, const std::vector<char>& bytes);
// Reads a whole file; InputError naming the file if it cannot be read.
std::vector<char> read_binary_file(const std::string& path);
std::string read_text_file(const std::string& path);
// mkdir -p; InputError naming the folder if it cannot be created, is a file
// or is not writable, with the OS's reason.
void make_dirs(const std::string& dir);
// Before long work: InputError naming the first path that is a folder, or
// whose existing parent is not a writable folder (the outputs an app will write).
void check_output_paths(const std::vector<std::string>& paths);

}  // namespace hsd
