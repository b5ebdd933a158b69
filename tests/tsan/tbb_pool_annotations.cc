// ThreadSanitizer support for oneTBB (docs/reliability.md "ThreadSanitizer"): task memory reuse.
//
// oneTBB's headers allocate task objects (the parallel_for range splits, parallel_invoke
// invokers) from libtbb's small-object pool: a block freed by one worker is handed to the next
// task, maybe on another thread, through synchronisation inside the uninstrumented libtbb. TSan
// then sees the new task's constructor race with the old task's last accesses. These
// definitions interpose tbb::detail::r1::allocate / deallocate for the code of the executable
// they are linked into (the headers call them through the PLT): deallocate releases the block,
// allocate acquires it, then both call libtbb's own function (dlsym RTLD_NEXT).
//
// The same file closes one more gap, in the waits on a wait_context (execute_and_wait, wait):
// a task's completion notifies "releasing" before its atomic decrement of the reference count
// (wait_context::add_reference), and libtbb's wait observes the count reach zero in its own,
// uninstrumented code, so TSan sees the last decrement unordered with whatever the waiting thread
// does next, typically reusing the stack slot of the finished wait_context. The interposed waits
// call libtbb's, then acquire on the reference count itself, the address the instrumented
// decrement released on: the acquire libtbb's load did.
//
// Contract: linked only into the executables of a -fsanitize=thread build; behaviour otherwise
// unchanged (same pool, same blocks, same waits).
#include <dlfcn.h>
#include <oneapi/tbb/detail/_task.h>

#include <atomic>
#include <cstddef>
#include <cstdint>
#include <cstdio>
#include <cstdlib>

extern "C" void __tsan_acquire(void* addr);
extern "C" void __tsan_release(void* addr);

namespace {
template <typename F>
F Real(const char* mangled) {
  void* f = dlsym(RTLD_NEXT, mangled);
  if (!f) {
    std::fprintf(stderr, "artex tsan support: %s not found in libtbb\n", mangled);
    std::abort();
  }
  return reinterpret_cast<F>(f);
}
// oneTBB's wait_context (detail/_task.h): its version word, then the atomic reference count,
// both private; the layout is checked against the header's size.
struct WaitContextLayout {
  std::uint64_t version_and_traits;
  std::atomic<std::uint64_t> ref_count;
};
static_assert(sizeof(WaitContextLayout) == sizeof(tbb::detail::d1::wait_context),
              "oneTBB's wait_context layout changed");

void AcquireRefCount(tbb::detail::d1::wait_context& w) {
  __tsan_acquire(&reinterpret_cast<WaitContextLayout*>(&w)->ref_count);
}
}  // namespace

namespace tbb {
namespace detail {
namespace d1 {
class small_object_pool;
}  // namespace d1
namespace r1 {

void execute_and_wait(d1::task& t, d1::task_group_context& t_ctx, d1::wait_context& w,
                      d1::task_group_context& w_ctx) {
  using F = void (*)(d1::task&, d1::task_group_context&, d1::wait_context&,
                     d1::task_group_context&);
  static const F real = Real<F>(
      "_ZN3tbb6detail2r116execute_and_waitERNS0_2d14taskERNS2_18task_group_contextERNS2_"
      "12wait_contextES6_");
  real(t, t_ctx, w, w_ctx);
  AcquireRefCount(w);
}

void wait(d1::wait_context& w, d1::task_group_context& ctx) {
  using F = void (*)(d1::wait_context&, d1::task_group_context&);
  static const F real =
      Real<F>("_ZN3tbb6detail2r14waitERNS0_2d112wait_contextERNS2_18task_group_contextE");
  real(w, ctx);
  AcquireRefCount(w);
}

void* allocate(d1::small_object_pool*& pool, std::size_t bytes, const d1::execution_data& ed) {
  using F = void* (*)(d1::small_object_pool*&, std::size_t, const d1::execution_data&);
  static const F real = Real<F>(
      "_ZN3tbb6detail2r18allocateERPNS0_2d117small_object_poolEmRKNS2_14execution_dataE");
  void* p = real(pool, bytes, ed);
  __tsan_acquire(p);
  return p;
}

void* allocate(d1::small_object_pool*& pool, std::size_t bytes) {
  using F = void* (*)(d1::small_object_pool*&, std::size_t);
  static const F real = Real<F>("_ZN3tbb6detail2r18allocateERPNS0_2d117small_object_poolEm");
  void* p = real(pool, bytes);
  __tsan_acquire(p);
  return p;
}

void deallocate(d1::small_object_pool& pool, void* p, std::size_t bytes,
                const d1::execution_data& ed) {
  using F = void (*)(d1::small_object_pool&, void*, std::size_t, const d1::execution_data&);
  static const F real = Real<F>(
      "_ZN3tbb6detail2r110deallocateERNS0_2d117small_object_poolEPvmRKNS2_14execution_dataE");
  __tsan_release(p);
  real(pool, p, bytes, ed);
}

void deallocate(d1::small_object_pool& pool, void* p, std::size_t bytes) {
  using F = void (*)(d1::small_object_pool&, void*, std::size_t);
  static const F real = Real<F>("_ZN3tbb6detail2r110deallocateERNS0_2d117small_object_poolEPvm");
  __tsan_release(p);
  real(pool, p, bytes);
}

}  // namespace r1
}  // namespace detail
}  // namespace tbb
