#include "experiments/heap_retention.h"

#include <algorithm>
#include <cstddef>

#if defined(__GLIBC__)
#include <malloc.h>
#endif

namespace artex {

bool RetainFreedHeap(int megabytes) {
  if (megabytes <= 0) return false;
#if defined(__GLIBC__)
  constexpr int kMb = 1 << 20;
  // 32 MB: glibc refuses an mmap threshold above half its 64 MB heap size on 64-bit systems.
  const int mmap_threshold = 32 * kMb;
  const long long trim = static_cast<long long>(megabytes) * kMb;
  const int trim_threshold = static_cast<int>(std::min<long long>(trim, 1 << 30));
  const int top_pad = std::min(megabytes, 64) * kMb;
  // mallopt returns 1 on success; the sanitizers' allocators return 0 for every call.
  return mallopt(M_MMAP_THRESHOLD, mmap_threshold) == 1 &&
         mallopt(M_TRIM_THRESHOLD, trim_threshold) == 1 && mallopt(M_TOP_PAD, top_pad) == 1;
#else
  return false;
#endif
}

}  // namespace artex
