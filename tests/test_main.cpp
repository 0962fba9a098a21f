// Catch2 main for hsd_tests: two threads and quiet info output, so timings and
// logs do not depend on the machine.
#define CATCH_CONFIG_RUNNER
#include <catch2/catch.hpp>
#include <torch/torch.h>

#include "common/app.h"
#include "common/log.h"

int main(int argc, char** argv) {
  hsd::use_passive_openmp(argv);  // see common/app.h
  hsd::keep_freed_memory();
  torch::set_num_threads(2);
  hsd::log::set_quiet(true);
  return Catch::Session().run(argc, argv);
}
