// An allocator for the film's large per-pixel arrays: above a few megabytes, memory mapped in 2 MiB-aligned blocks
// that the kernel is asked to back with transparent huge pages (madvise(MADV_HUGEPAGE), Linux's
// Documentation/admin-guide/mm/transhuge.rst). Where the system's setting is "madvise" (Debian's kernels), arrays of
// ordinary 4 KiB pages cost a page fault per 4 KiB when first touched: a 1920 × 1080 film with every render pass is
// 3.7 GB, nearly a million faults, which took more CPU time than the render's own accumulation into the passes.
// Smaller arrays come from operator new. Where huge pages are off, the mapping is ordinary memory.
#pragma once

#include <sys/mman.h>

#include <cstddef>
#include <cstdint>
#include <new>

namespace tessera {

template <typename T>
class LargeAllocator {
 public:
  using value_type = T;
  static constexpr size_t kHugePage = size_t{2} << 20;
  static constexpr size_t kMapAbove = size_t{4} << 20;  // bytes: smaller arrays come from operator new

  LargeAllocator() = default;
  template <typename U>
  LargeAllocator(const LargeAllocator<U>&) {}

  T* allocate(size_t n) {
    if (n > SIZE_MAX / sizeof(T)) throw std::bad_array_new_length();
    const size_t bytes = n * sizeof(T);
    if (bytes < kMapAbove) return static_cast<T*>(::operator new (bytes, std::align_val_t{alignof(T)}));
    // One huge page more than needed, then the slack before the first 2 MiB boundary and after the array unmapped:
    // the kernel backs only aligned 2 MiB ranges with huge pages.
    const size_t length = rounded(bytes);
    void* p = mmap(nullptr, length + kHugePage, PROT_READ | PROT_WRITE, MAP_PRIVATE | MAP_ANONYMOUS, -1, 0);
    if (p == MAP_FAILED) throw std::bad_alloc();
    const auto start = reinterpret_cast<uintptr_t>(p);
    const uintptr_t aligned = (start + kHugePage - 1) & ~(kHugePage - 1);
    if (aligned > start) munmap(p, aligned - start);
    if (const size_t tail = start + length + kHugePage - (aligned + length); tail > 0)
      munmap(reinterpret_cast<void*>(aligned + length), tail);
    madvise(reinterpret_cast<void*>(aligned), length, MADV_HUGEPAGE);  // advice: a kernel without THP ignores it
    return reinterpret_cast<T*>(aligned);
  }

  void deallocate(T* p, size_t n) noexcept {
    const size_t bytes = n * sizeof(T);
    if (bytes < kMapAbove)
      ::operator delete (p, std::align_val_t{alignof(T)});
    else
      munmap(p, rounded(bytes));
  }

  template <typename U>
  bool operator==(const LargeAllocator<U>&) const {
    return true;
  }

 private:
  static size_t rounded(size_t bytes) { return (bytes + kHugePage - 1) & ~(kHugePage - 1); }
};

}  // namespace tessera
