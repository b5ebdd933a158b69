// Keeping freed memory in the process for reuse (pipeline.heap_retain_mb,
// docs/realtime-measurements.md, "Freed memory kept for reuse").
//
// A tracking run allocates and frees the same large buffers every frame: decoded images
// (2.4 MB of colour), the PNG's inflated rows, raster and visibility buffers, atlases. With
// glibc's defaults a block above 128 KB is mapped from the kernel on allocation and unmapped on
// free (the threshold adapts upwards, but the heap's top is trimmed back to the kernel above
// twice that), so every frame touches fresh pages: about 2400 page faults per frame on the
// default walk, a fifth of the run's CPU time in the kernel and in memset of new pages.
#pragma once

namespace artex {

// Makes glibc's allocator serve blocks up to 32 MB (the largest threshold it accepts) from its
// heap, keep up to `megabytes` of freed memory at the heap's top instead of returning it, and
// grow the heap in steps of min(megabytes, 64) MB (untouched pages cost no memory). Process-
// wide and not undone (glibc cannot report its settings back); megabytes 0 leaves the
// allocator as it is. Returns false when nothing was applied: megabytes 0, not glibc, or an
// allocator that ignores mallopt (the sanitizers'), or a value glibc refused.
bool RetainFreedHeap(int megabytes);

// At most `arenas` glibc malloc arenas for the threads that allocate from now on
// (pipeline.heap_arenas, docs/realtime-later-rounds.md, "One heap for all threads"): glibc gives
// threads arenas of their own (up to 8 per core), and with the freed memory kept
// (RetainFreedHeap) each arena keeps its own peak, while a frame's buffers are allocated by
// one stage's thread and freed by another's. Takes effect only where no thread other than the
// first has needed an arena yet (glibc fixes the limit then). Process-wide and not undone;
// arenas 0 leaves glibc's default. Returns false when nothing was applied: arenas 0, not glibc,
// or an allocator that ignores mallopt (the sanitizers').
bool LimitHeapArenas(int arenas);

// Transparent huge pages for glibc's heap (pipeline.huge_pages, docs/realtime-measurements.md,
// "Huge pages for the heap"). The heap's first touch of the pool's images, colours and raster
// buffers costs ~95,000 page faults over the first 60 frames of the default walk with 4 KB pages;
// glibc's tunable glibc.malloc.hugetlb=1 (glibc >= 2.35) makes the allocator advise the kernel
// to back its heaps with 2 MB pages where the kernel's transparent_hugepage mode is `madvise`.
// Tunables are read when the process starts, so this re-executes the running program (its
// own path, read from /proc/self/exe, so that the process keeps its name; `argv`) with
// GLIBC_TUNABLES extended by it. It returns (nothing changed) when the tunable is already set,
// the C library is not glibc 2.35 or later, the kernel's mode is `always` (huge pages already)
// or `never`, the process runs under a sanitizer (its allocator ignores the tunable), or the
// exec fails; on success it does not return. Flushes stdout and stderr first.
void ReexecWithHugePageHeap(char** argv);

// Whether glibc's heap is on transparent huge pages in this process: the kernel's mode is
// `always`, or it is `madvise` and glibc.malloc.hugetlb is set (glibc >= 2.35, no sanitizer).
bool HugePageHeapActive();
// Whether ReexecWithHugePageHeap can make it so (or it is so already).
bool HugePageHeapAvailable();

// The program's argv for ReexecWithHugePageHeap from within a subcommand (set by main).
void RememberProgramArguments(char** argv);
char** ProgramArguments();  // null before RememberProgramArguments

}  // namespace artex
