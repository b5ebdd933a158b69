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
// Contract: linked only into the executables of a -fsanitize=thread build; behaviour otherwise
// unchanged (same pool, same blocks).
#include <dlfcn.h>

#include <cstddef>
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
}  // namespace

namespace tbb {
namespace detail {
namespace d1 {
class small_object_pool;
struct execution_data;
}  // namespace d1
namespace r1 {

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
