// CPU time of the process and of the calling thread (s), for the pipeline's stage timings
// (experiments/pipeline_schedule.cc) and the background evaluation's
// (experiments/ground_truth_evaluation.cc).
#pragma once

#include <sys/resource.h>
#include <time.h>

namespace artex {

// User plus system time of the whole process.
inline double ProcessCpuSeconds() {
  rusage usage{};
  getrusage(RUSAGE_SELF, &usage);
  return usage.ru_utime.tv_sec + 1e-6 * usage.ru_utime.tv_usec + usage.ru_stime.tv_sec +
         1e-6 * usage.ru_stime.tv_usec;
}

// CPU time of the calling thread.
inline double ThreadCpuSeconds() {
  timespec t{};
  clock_gettime(CLOCK_THREAD_CPUTIME_ID, &t);
  return t.tv_sec + 1e-9 * t.tv_nsec;
}

}  // namespace artex
