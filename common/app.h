// What every hsd app shares: the contract's command-line conventions
// (--help, --config, --set k=v, --out), thread and device setup, and the
// mapping of errors to exit codes (0 ok, 1 bug, 2 bad input, 3 numerical).
#pragma once
#include <functional>
#include <map>
#include <string>
#include <vector>

#include <torch/types.h>

#include "common/config.h"

namespace hsd {

struct AppArgs {
  std::string config_path;
  std::vector<std::string> overrides;      // --set values, in order
  std::string out_dir;
  std::vector<std::string> positional;     // e.g. hsd_bench NAME
  std::map<std::string, std::string> options;  // other --flag VALUE pairs
  std::map<std::string, bool> switches;        // other --flag (no value)

  bool has(const std::string& flag) const { return options.count(flag) || switches.count(flag); }
  std::string option(const std::string& flag, const std::string& fallback) const;
  int64_t integer(const std::string& flag, int64_t fallback) const;
  double number(const std::string& flag, double fallback) const;  // finite; InputError naming the flag
};

struct AppSpec {
  std::string name;
  std::string usage;                          // printed by --help
  std::vector<std::string> value_flags;       // app-specific flags that take a value (e.g. "--scene")
  std::vector<std::string> switch_flags;      // app-specific flags without a value (e.g. "--json")
  bool needs_config = true;
  bool needs_out = true;
  int max_positional = 0;                     // arguments without a flag (hsd_bench NAME); more are refused
  bool heap_for_large_blocks = false;         // keep_freed_memory's large_blocks_too (the training apps)
};

// Parses argv per the contract; InputError (exit 2) for unknown flags, missing
// values, a flag given twice (other than --set) and stray arguments: nothing
// on the command line is ignored.
AppArgs parse_args(const AppSpec& spec, int argc, char** argv);

// LibTorch's OpenMP workers spin-wait after each parallel region while
// OpenBLAS's own threads run the next matrix product, so on few cores the two
// pools fight (measured: PSF forward+backward 1.7x slower). libgomp reads
// OMP_WAIT_POLICY only when it loads, so if the variable is unset this sets it
// to PASSIVE and re-executes the program (/proc/self/exe) once. A value the
// user set is kept. Returns only if no re-exec happened.
void use_passive_openmp(char** argv);

// glibc hands blocks above a (dynamic) threshold straight back to the kernel,
// so each training step's large temporaries arrive as fresh pages: about 45,000
// page faults (~180 MiB zeroed by the kernel) per PSF + sensor step, 20% of its
// time. This keeps blocks up to 32 MiB in the heap and trims it only above
// trim_threshold_mib (1 GiB) of free space; peak memory is unchanged. With
// large_blocks_too (the training apps: AppSpec::heap_for_large_blocks, and
// hsd_bench train), blocks above 32 MiB come from the main thread's heap as
// well (M_MMAP_MAX = 0): the study config's OTFs and spectral Wiener
// temporaries (25 bands x 7 layers on a 240-px grid, 44-78 MiB each) were
// page-faulted in afresh every step, which on a paravirtualised guest took a
// third of its step (docs/benchmarks.md, "Large blocks from the heap"); the
// heap then holds ~250 MiB more at its peak. No-op off glibc.
void keep_freed_memory(int64_t trim_threshold_mib = 1024, bool large_blocks_too = false);
// Returns the heap's free memory to the kernel now (malloc_trim). No-op off glibc.
void release_freed_memory();

// Runs body(args) and maps exceptions to exit codes with one line on stderr.
// Calls use_passive_openmp and keep_freed_memory first. Does not return: it
// flushes stdout and stderr and ends the process with the exit code, skipping
// the libraries' exit-time destructors (for apps' main only).
[[noreturn]] int run_app(const AppSpec& spec, int argc, char** argv, const std::function<int(const AppArgs&)>& body);

// Sets torch's intra-op threads (0 = all cores) and prints "threads: N".
int setup_threads(int64_t requested, bool print = true);
// The config's device -> torch::Device; InputError if CUDA is asked for but absent.
torch::Device resolve_device(ComputeDevice device);

// Writes DIR/config.json (the fully resolved config) atomically.
void write_resolved_config(const Config& cfg, const std::string& out_dir);

}  // namespace hsd
