// ThreadSanitizer support for oneTBB (docs/reliability.md "ThreadSanitizer"): an ITT collector.
//
// Debian's libtbb is not built with ThreadSanitizer, so TSan cannot see the synchronisation
// inside it (task spawn, steal, completion) and reports every hand-over of data to a worker
// thread as a race. libtbb reports its synchronisation points through the ITT notification API
// (for Intel's threading tools): with INTEL_LIBITTNOTIFY64 pointing at this library and
// INTEL_ITTNOTIFY_GROUPS=sync, libtbb loads it and calls __itt_sync_releasing / _acquired on the
// objects it hands over; they become TSan release / acquire annotations, the happens-before
// edges TSan misses. The headers' own notifications (task spawn, wait_context, partitioner
// tree) are compiled in with TBB_USE_PROFILING_TOOLS=2 (cmake/ArtexThreadSanitizer.cmake).
//
// Contract: built and used only in a -fsanitize=thread build (the __tsan_* symbols come from the
// process's TSan runtime). Exports the ITT "version 1" interface: __itt_api_version plus the
// sync functions; every other ITT function stays libtbb's no-op.

extern "C" {
void __tsan_acquire(void* addr);
void __tsan_release(void* addr);

__attribute__((visibility("default"))) const char* __itt_api_version() { return "artex-tsan"; }
__attribute__((visibility("default"))) void __itt_sync_acquired(void* addr) { __tsan_acquire(addr); }
__attribute__((visibility("default"))) void __itt_sync_releasing(void* addr) { __tsan_release(addr); }
__attribute__((visibility("default"))) void __itt_sync_prepare(void*) {}
__attribute__((visibility("default"))) void __itt_sync_cancel(void*) {}
__attribute__((visibility("default"))) void __itt_sync_create(void*, const char*, const char*, int) {}
__attribute__((visibility("default"))) void __itt_sync_rename(void*, const char*) {}
__attribute__((visibility("default"))) void __itt_sync_destroy(void*) {}
}
