// Per-thread bump allocator for objects that live for one path vertex (BSDFs built at a hit), so the render loop
// never touches the heap after warm-up.
#pragma once

#include <cstddef>
#include <memory>
#include <new>
#include <type_traits>
#include <utility>
#include <vector>

namespace tessera {

// Aligned to a cache line: each render thread bumps its own arena at every path vertex, and two arenas sharing a
// line would bounce it between cores.
class alignas(64) ScratchArena {
 public:
  explicit ScratchArena(size_t block_bytes = 64 * 1024) : block_bytes_(block_bytes) {}
  ScratchArena(const ScratchArena&) = delete;
  ScratchArena& operator=(const ScratchArena&) = delete;

  // Objects made here are never destroyed: only trivially destructible types are allowed.
  template <typename T, typename... Args>
  T* make(Args&&... args) {
    static_assert(std::is_trivially_destructible_v<T>, "arena objects are never destroyed");
    void* p = allocate(sizeof(T), alignof(T));
    return new (p) T(std::forward<Args>(args)...);
  }

  void* allocate(size_t bytes, size_t align) {
    size_t offset = (used_ + align - 1) & ~(align - 1);
    if (blocks_.empty() || offset + bytes > block_bytes_) {
      if (bytes > block_bytes_) throw std::bad_alloc();
      if (!blocks_.empty()) ++current_;
      if (current_ >= blocks_.size()) blocks_.emplace_back(new std::byte[block_bytes_]);
      offset = 0;
    }
    used_ = offset + bytes;
    return blocks_[current_].get() + offset;
  }

  // Forgets every object; keeps the memory for reuse.
  void reset() {
    current_ = 0;
    used_ = 0;
  }

 private:
  size_t block_bytes_;
  std::vector<std::unique_ptr<std::byte[]>> blocks_;
  size_t current_ = 0;
  size_t used_ = 0;
};

}  // namespace tessera
