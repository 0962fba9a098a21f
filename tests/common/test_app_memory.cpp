// keep_freed_memory (common/app.h): with large blocks kept, a block above
// glibc's 32 MiB mmap ceiling comes from the heap, and a freed one is reused;
// without, it is mapped afresh. The suite's own setting is restored after.
#include <catch2/catch.hpp>

#include <cstdlib>
#include <cstring>

#include "common/app.h"

#ifdef __GLIBC__
#include <malloc.h>

namespace {

// Bytes glibc holds in mmapped blocks now.
size_t mapped_bytes() { return mallinfo2().hblkhd; }

// Allocates and touches a 64 MiB block; returns how much of it was mapped.
size_t mapped_by_large_block() {
  const size_t before = mapped_bytes();
  void* p = std::malloc(size_t(64) << 20);
  REQUIRE(p != nullptr);
  std::memset(p, 1, 4096);
  const size_t during = mapped_bytes();
  std::free(p);
  return during > before ? during - before : 0;
}

}  // namespace

TEST_CASE("app memory: with large blocks kept, a 64 MiB block comes from the heap, else it is mapped", "[app]") {
  hsd::keep_freed_memory(1024, false);
  CHECK(mapped_by_large_block() >= (size_t(64) << 20));
  hsd::keep_freed_memory(1024, true);
  CHECK(mapped_by_large_block() == 0);
  // freed and asked for again: the same heap block, no new mapping
  void* a = std::malloc(size_t(64) << 20);
  std::free(a);
  void* b = std::malloc(size_t(64) << 20);
  CHECK(a == b);
  std::free(b);
  hsd::keep_freed_memory();  // the suite's setting (tests/test_main.cpp)
}
#endif
