// Keeping freed memory in the process for reuse (pipeline.heap_retain_mb, docs/realtime.md,
// "Freed memory kept for reuse").
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

}  // namespace artex
