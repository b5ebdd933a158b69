#include "experiments/heap_retention.h"

#include <gtest/gtest.h>
#include <sys/resource.h>

#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <string>
#include <thread>

#if defined(__GLIBC__)
#include <malloc.h>
#endif

namespace artex {
namespace {

long MinorFaults() {
  rusage usage{};
  getrusage(RUSAGE_SELF, &usage);
  return usage.ru_minflt;
}

// `rounds` rounds of a frame-like pattern: three 10 MB blocks allocated and written, then freed
// together. The page faults it took.
long FaultsOfRepeatedBlocks(int rounds) {
  constexpr std::size_t kBytes = std::size_t{10} << 20;
  const long before = MinorFaults();
  for (int r = 0; r < rounds; ++r) {
    unsigned char* blocks[3];
    for (unsigned char*& block : blocks) {
      block = static_cast<unsigned char*>(std::malloc(kBytes));
      if (!block) return -1;
      std::memset(block, r + 1, kBytes);
    }
    volatile unsigned char sink = blocks[0][1] + blocks[2][kBytes - 1];  // keep the stores
    (void)sink;
    for (unsigned char* block : blocks) std::free(block);
  }
  return MinorFaults() - before;
}

TEST(HeapRetentionTest, ZeroLeavesTheAllocatorAlone) { EXPECT_FALSE(RetainFreedHeap(0)); }

// With the heap retained, the freed blocks are reused by the next round: their pages stay
// mapped, so writing them again takes no page faults. With glibc's defaults the 30 MB freed at
// the heap's top exceed its trim threshold (twice the largest block it has mapped, 20 MB) and
// go back to the kernel: each round faults its 7680 pages in anew (61216 faults for the 8
// rounds, measured on Debian 12).
TEST(HeapRetentionTest, AFreedBlockIsReusedWithoutPageFaults) {
  if (!RetainFreedHeap(512)) GTEST_SKIP() << "the allocator ignores mallopt (not glibc's)";
  ASSERT_GE(FaultsOfRepeatedBlocks(1), 0);  // the first round grows the heap: faults expected
  const long faults = FaultsOfRepeatedBlocks(8);
  ASSERT_GE(faults, 0) << "allocation failed";
  EXPECT_LT(faults, 1024) << "page faults of 8 rounds of three 10 MB blocks";
}

TEST(HeapArenasTest, ZeroLeavesTheAllocatorAlone) { EXPECT_FALSE(LimitHeapArenas(0)); }

// With one arena, a thread started afterwards allocates from the first thread's heap: glibc's
// malloc_info lists one heap. With its default a new thread that allocates gets an arena (a
// heap) of its own. (No thread of this test program allocated before this test: glibc fixes
// the limit when a second thread first needs an arena.)
TEST(HeapArenasTest, ThreadsStartedAfterwardsShareOneHeap) {
#if defined(__GLIBC__)
  if (!LimitHeapArenas(1)) GTEST_SKIP() << "the allocator ignores mallopt (not glibc's)";
  std::thread([] {
    void* block = std::malloc(std::size_t{1} << 20);
    std::memset(block, 1, std::size_t{1} << 20);
    std::free(block);
  }).join();
  char* text = nullptr;
  std::size_t size = 0;
  FILE* out = open_memstream(&text, &size);
  ASSERT_NE(out, nullptr);
  ASSERT_EQ(malloc_info(0, out), 0);
  std::fclose(out);
  const std::string info(text, size);
  std::free(text);
  int heaps = 0;
  for (std::size_t at = info.find("<heap nr="); at != std::string::npos;
       at = info.find("<heap nr=", at + 1))
    ++heaps;
  EXPECT_EQ(heaps, 1) << info.substr(0, 2000);
#else
  GTEST_SKIP() << "not glibc";
#endif
}

}  // namespace
}  // namespace artex
