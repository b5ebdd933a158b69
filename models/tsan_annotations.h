// Happens-before annotations for ThreadSanitizer (docs/reliability.md "ThreadSanitizer") where
// the synchronisation happens inside an uninstrumented library that reports none of it: oneTBB's
// parallel_pipeline hands tokens between its stages, runs a serial stage's invocations one after
// the other (maybe on different threads) and returns after the last, all inside libtbb.
// No-ops unless compiled with -fsanitize=thread. They state what the library guarantees; they
// are no locks and never change behaviour.
#pragma once

#if defined(__SANITIZE_THREAD__)
#define ARTEX_TSAN_ANNOTATIONS 1
#elif defined(__has_feature)
#if __has_feature(thread_sanitizer)
#define ARTEX_TSAN_ANNOTATIONS 1
#endif
#endif

#ifdef ARTEX_TSAN_ANNOTATIONS
extern "C" void __tsan_acquire(void* addr);
extern "C" void __tsan_release(void* addr);
#endif

namespace artex {

// Everything this thread did before TsanRelease(sync) happens before what a thread does after
// a later TsanAcquire(sync).
inline void TsanAcquire(const void* sync) {
#ifdef ARTEX_TSAN_ANNOTATIONS
  __tsan_acquire(const_cast<void*>(sync));
#else
  (void)sync;
#endif
}
inline void TsanRelease(const void* sync) {
#ifdef ARTEX_TSAN_ANNOTATIONS
  __tsan_release(const_cast<void*>(sync));
#else
  (void)sync;
#endif
}

// One invocation of a serial pipeline stage: ordered after the stage's previous invocation.
// TsanAcquire(sync) after the pipeline orders the caller after the stage's last invocation.
class TsanSerialStage {
 public:
  explicit TsanSerialStage(const void* sync) : sync_(sync) { TsanAcquire(sync_); }
  ~TsanSerialStage() { TsanRelease(sync_); }
  TsanSerialStage(const TsanSerialStage&) = delete;
  TsanSerialStage& operator=(const TsanSerialStage&) = delete;

 private:
  const void* sync_;
};

}  // namespace artex
