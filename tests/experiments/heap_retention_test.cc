#include "experiments/heap_retention.h"

#include <gtest/gtest.h>
#include <sys/resource.h>

#include <cstdlib>
#include <cstring>

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

}  // namespace
}  // namespace artex
