// keep_freed_memory (common/app.h): with large blocks kept (the training
// apps), a block above glibc's 32 MiB mmap ceiling comes from the heap, and a
// freed one is reused without the heap growing; by default it is mapped
// afresh. The suite's own setting is restored however the test ends.
#include <catch2/catch.hpp>

#include <cstdlib>
#include <cstring>

#include "common/app.h"

#ifdef __GLIBC__
#include <malloc.h>

namespace {

struct RestoreSuiteSetting {
  ~RestoreSuiteSetting() { hsd::keep_freed_memory(); }  // tests/test_main.cpp's
};

struct Held {
  size_t mapped, arena;  // bytes in mmapped blocks, bytes of the main heap
};
Held held() {
  const struct mallinfo2 m = mallinfo2();
  return {m.hblkhd, m.arena};
}

// Allocates and touches a 64 MiB block; returns what glibc held while it was live.
Held while_large_block_lives() {
  void* p = std::malloc(size_t(64) << 20);
  REQUIRE(p != nullptr);
  std::memset(p, 1, 4096);
  const Held h = held();
  std::free(p);
  return h;
}

}  // namespace

TEST_CASE("app memory: with large blocks kept, a 64 MiB block comes from the heap and is reused, else it is mapped", "[app]") {
  RestoreSuiteSetting restore;
  const size_t mib64 = size_t(64) << 20;
  hsd::keep_freed_memory(1024, false);
  const Held before = held();
  CHECK(while_large_block_lives().mapped >= before.mapped + mib64);
  hsd::keep_freed_memory(1024, true);
  const Held first = while_large_block_lives();
  CHECK(first.mapped < before.mapped + mib64);  // not mapped: the heap holds it
  CHECK(first.arena >= mib64);
  const Held second = while_large_block_lives();
  CHECK(second.arena == first.arena);  // the freed block reused: the heap did not grow
  CHECK(second.mapped == first.mapped);
}
#endif
