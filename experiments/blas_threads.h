// The BLAS library's own threads (pipeline.blas_threads, docs/realtime.md). Debian's OpenCV,
// SuiteSparse and LAPACK link the system BLAS, which is OpenBLAS where it is installed: when it
// is loaded it starts a pool of threads (one per core beyond the first) that spin, yielding the
// core, for about 0.1-0.25 s waiting for work before they sleep, which an `artex track` start
// pays while its set-up runs on both cores. artex's parallel loops are oneTBB's, and none of
// its default paths calls BLAS.
#pragma once

namespace artex {

// Where the process has OpenBLAS (its functions are looked up at run time; other BLAS libraries
// are left alone): sets its thread count to `threads` and, for 1, ends its pool (the threads
// exit; a later BLAS call runs on the calling thread). Process-wide, kept after the call.
// Returns whether OpenBLAS was found. threads <= 0: nothing, false. Not to be called while
// another thread of the process is inside a BLAS call.
bool LimitBlasThreads(int threads);

// OpenBLAS's thread count in this process; 0 without OpenBLAS.
int BlasThreads();

}  // namespace artex
