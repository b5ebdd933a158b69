// An allocator whose value-initialisation (std::vector::resize, the size constructor) leaves
// trivial elements uninitialised, as `new T` would. For buffers sized for a worst case of which
// each use writes only the first part: zero-filling the rest touches, and so faults in, memory
// that is never read (the depth mesher's per-node buffers: 6 MB for a 640x480 frame of which a
// subject uses about a tenth). Elements constructed with arguments are constructed as usual.
#pragma once

#include <memory>
#include <new>
#include <utility>

namespace artex {

template <typename T, typename Base = std::allocator<T>>
struct DefaultInitAllocator : Base {
  template <typename U>
  struct rebind {
    using other =
        DefaultInitAllocator<U, typename std::allocator_traits<Base>::template rebind_alloc<U>>;
  };
  DefaultInitAllocator() = default;
  template <typename U, typename B>
  DefaultInitAllocator(const DefaultInitAllocator<U, B>& other)  // NOLINT(runtime/explicit)
      : Base(other) {}
  template <typename U>
  void construct(U* p) {
    ::new (static_cast<void*>(p)) U;
  }
  template <typename U, typename... Args>
  void construct(U* p, Args&&... args) {
    ::new (static_cast<void*>(p)) U(std::forward<Args>(args)...);
  }
};

}  // namespace artex
