#include "experiments/blas_threads.h"

#include <dlfcn.h>

#include <mutex>

namespace artex {
namespace {

template <class F>
F Find(const char* name) {
  return reinterpret_cast<F>(dlsym(RTLD_DEFAULT, name));
}

}  // namespace

bool LimitBlasThreads(int threads) {
  if (threads <= 0) return false;
  const auto set_threads = Find<void (*)(int)>("openblas_set_num_threads");
  if (set_threads == nullptr) return false;
  static std::mutex mutex;
  static bool pool_ended = false;  // by an earlier call (setting the count again restarts it)
  std::lock_guard<std::mutex> lock(mutex);
  if (BlasThreads() == threads && (threads != 1 || pool_ended)) return true;
  set_threads(threads);
  if (threads == 1) {
    // OpenBLAS ends its pool (the threads leave their wait loop and are joined); with one
    // thread set, a later call does not start it again.
    if (const auto shutdown = Find<int (*)()>("blas_thread_shutdown_")) shutdown();
    pool_ended = true;
  } else {
    pool_ended = false;
  }
  return true;
}

int BlasThreads() {
  const auto get_threads = Find<int (*)()>("openblas_get_num_threads");
  return get_threads ? get_threads() : 0;
}

}  // namespace artex
