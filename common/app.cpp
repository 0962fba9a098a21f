#include "common/app.h"

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <iostream>
#include <thread>
#include <unistd.h>
#ifdef __GLIBC__
#include <malloc.h>
#endif

#include <torch/torch.h>

#include "common/atomic_file.h"
#include "common/error.h"
#include "common/log.h"

namespace hsd {

std::string AppArgs::option(const std::string& flag, const std::string& fallback) const {
  auto it = options.find(flag);
  return it == options.end() ? fallback : it->second;
}

double AppArgs::number(const std::string& flag, double fallback) const {
  auto it = options.find(flag);
  if (it == options.end()) return fallback;
  char* end = nullptr;
  const double v = std::strtod(it->second.c_str(), &end);
  if (end == it->second.c_str() || *end != '\0' || !std::isfinite(v))
    input_error(flag, "expected a number, got \"" + it->second + "\"");
  return v;
}

int64_t AppArgs::integer(const std::string& flag, int64_t fallback) const {
  auto it = options.find(flag);
  if (it == options.end()) return fallback;
  try {
    size_t pos = 0;
    const long long v = std::stoll(it->second, &pos);
    if (pos != it->second.size()) throw std::invalid_argument("trailing");
    return v;
  } catch (const std::exception&) {
    input_error(flag, "expected an integer, got \"" + it->second + "\"");
  }
}

AppArgs parse_args(const AppSpec& spec, int argc, char** argv) {
  AppArgs a;
  auto takes_value = [&](const std::string& f) {
    return std::find(spec.value_flags.begin(), spec.value_flags.end(), f) != spec.value_flags.end();
  };
  auto is_switch = [&](const std::string& f) {
    return std::find(spec.switch_flags.begin(), spec.switch_flags.end(), f) != spec.switch_flags.end();
  };
  std::map<std::string, bool> seen;
  auto once = [&](const std::string& f) {
    if (seen[f]) input_error(f, "given twice (each flag but --set takes one value)");
    seen[f] = true;
  };
  for (int i = 1; i < argc; ++i) {
    std::string f = argv[i];
    std::string value;
    bool inline_value = false;
    if (f.rfind("--", 0) == 0) {
      const auto eq = f.find('=');
      if (eq != std::string::npos && f != "--set") {
        value = f.substr(eq + 1);
        f = f.substr(0, eq);
        inline_value = true;
      }
    }
    auto next = [&]() -> std::string {
      if (inline_value) return value;
      if (i + 1 >= argc) input_error(f, "needs a value");
      return argv[++i];
    };
    if (f == "--help" || f == "-h") {
      a.switches["--help"] = true;
    } else if (f == "--config") {
      once(f);
      a.config_path = next();
    } else if (f == "--set") {
      a.overrides.push_back(next());
    } else if (f == "--out") {
      once(f);
      a.out_dir = next();
    } else if (takes_value(f)) {
      once(f);
      a.options[f] = next();
    } else if (is_switch(f)) {
      if (inline_value) input_error(f, "takes no value (got \"" + value + "\")");
      once(f);
      a.switches[f] = true;
    } else if (f.rfind("-", 0) == 0) {
      input_error(f, "unknown flag (see " + spec.name + " --help)");
    } else if (int(a.positional.size()) < spec.max_positional) {
      a.positional.push_back(f);
    } else {
      input_error(f, a.positional.empty() ? "unexpected argument (every value follows its flag: --set key=VALUE, one --set per value; see " + spec.name + " --help)"
                                          : "unexpected extra argument (see " + spec.name + " --help)");
    }
  }
  if (a.switches.count("--help")) return a;
  if (spec.needs_config && a.config_path.empty()) input_error("--config", "required (a JSON config file)");
  if (spec.needs_out && a.out_dir.empty()) input_error("--out", "required (output folder)");
  return a;
}

void use_passive_openmp(char** argv) {
  if (std::getenv("OMP_WAIT_POLICY") != nullptr) return;
  ::setenv("OMP_WAIT_POLICY", "PASSIVE", 1);
  ::execv("/proc/self/exe", argv);  // returns only on failure: carry on as we are
}

void keep_freed_memory(int64_t trim_threshold_mib, bool large_blocks_too) {
#ifdef __GLIBC__
  mallopt(M_MMAP_THRESHOLD, 32 << 20);
  mallopt(M_MMAP_MAX, large_blocks_too ? 0 : 65536);  // 0: no block is mmapped (65536 is glibc's default)
  mallopt(M_TRIM_THRESHOLD, int(std::min<int64_t>(trim_threshold_mib, 2047) << 20));
#else
  (void)trim_threshold_mib, (void)large_blocks_too;
#endif
}

void release_freed_memory() {
#ifdef __GLIBC__
  malloc_trim(0);
#endif
}

namespace {

// One line, whatever a library appends: LibTorch's "Exception raised from ..."
// and its backtrace are cut, other line breaks become "; ".
std::string one_line(std::string m) {
  const auto raised = m.find("Exception raised from");
  if (raised != std::string::npos) m.erase(raised);
  std::string out;
  bool pending = false;
  for (char c : m) {
    if (c == '\n' || c == '\r') {
      pending = !out.empty();
      continue;
    }
    if (pending) out += "; ", pending = false;
    out += c;
  }
  while (!out.empty() && (out.back() == ' ' || out.back() == ';')) out.pop_back();
  return out;
}

}  // namespace

namespace {

int run_body(const AppSpec& spec, int argc, char** argv, const std::function<int(const AppArgs&)>& body) {
  try {
    AppArgs args = parse_args(spec, argc, argv);
    if (args.switches.count("--help")) {
      std::printf("%s\n", spec.usage.c_str());
      return 0;
    }
    return body(args);
  } catch (const InputError& e) {
    std::fprintf(stderr, "%s: error: %s\n", spec.name.c_str(), one_line(e.what()).c_str());
    return 2;
  } catch (const NumericalError& e) {
    std::fprintf(stderr, "%s: numerical error: %s\n", spec.name.c_str(), one_line(e.what()).c_str());
    return 3;
  } catch (const DistributedError& e) {
    std::fprintf(stderr, "%s: distributed training failed: %s\n", spec.name.c_str(), one_line(e.what()).c_str());
    return 4;
  } catch (const c10::Error& e) {
    std::fprintf(stderr, "%s: internal error (torch): %s\n", spec.name.c_str(), one_line(e.what_without_backtrace()).c_str());
    return 1;
  } catch (const std::exception& e) {
    std::fprintf(stderr, "%s: internal error: %s\n", spec.name.c_str(), one_line(e.what()).c_str());
    return 1;
  }
}

}  // namespace

int run_app(const AppSpec& spec, int argc, char** argv, const std::function<int(const AppArgs&)>& body) {
  use_passive_openmp(argv);
  keep_freed_memory(1024, spec.heap_for_large_blocks);
  const int rc = run_body(spec, argc, argv, body);
  // The body's objects are gone and its files closed (atomic_file.h: renamed
  // into place when complete). What is left at exit is the libraries' static
  // destructors: LibTorch's deregister its ~2,000 operators, ~0.03 s, 10% of
  // a --help run. Flush the streams and end the process without them.
  std::cout.flush();
  std::cerr.flush();
  std::fflush(nullptr);
  std::_Exit(rc);
}

int setup_threads(int64_t requested, bool print) {
  int n = int(requested);
  if (n <= 0) n = int(std::max(1u, std::thread::hardware_concurrency()));
  torch::set_num_threads(n);
  if (print) log::info("threads: " + std::to_string(torch::get_num_threads()));
  return torch::get_num_threads();
}

torch::Device resolve_device(ComputeDevice device) {
  if (device == ComputeDevice::cuda) {
    if (!torch::cuda::is_available())
      input_error("config key device", "\"cuda\" requested but this LibTorch build has no usable CUDA device");
    return torch::Device(torch::kCUDA);
  }
  return torch::Device(torch::kCPU);
}

void write_resolved_config(const Config& cfg, const std::string& out_dir) {
  write_text_file(out_dir + "/config.json", cfg.resolved.dump(2) + "\n");
}

}  // namespace hsd
