#pragma once

// An array of trivially copyable values for the large arrays of a vocabulary (a 1M-word
// tree holds 35 MiB of centres and 9 MiB of nodes). Filling freshly allocated memory
// costs a page fault per 4 KiB page, which is most of the time of reading a large
// vocabulary; on Linux an array of 2 MiB or more is placed on 2 MiB boundaries and
// advised for transparent huge pages (madvise, the kernel's default mode), one fault per
// 2 MiB. Elsewhere, or when the kernel declines, it is ordinary memory. Copies share
// the values (the tree never changes them after it is built).

#include <cstddef>
#include <cstdlib>
#include <memory>
#include <new>
#include <type_traits>

#if defined(__linux__)
#include <sys/mman.h>
#endif

namespace vmap::detail {

template <class T>
class LargeArray {
  static_assert(std::is_trivially_copyable_v<T>);

 public:
  /// n values, not initialised (the caller writes every one).
  void resize_for_overwrite(std::size_t n) {
    if (n == 0) {
      p_.reset();
      n_ = 0;
      return;
    }
    constexpr std::size_t huge = std::size_t{2} << 20;
    const std::size_t bytes = n * sizeof(T);
    const std::size_t align = bytes >= huge ? huge : 64;
    const std::size_t rounded = (bytes + align - 1) / align * align;
    void* p = std::aligned_alloc(align, rounded);
    if (p == nullptr) throw std::bad_alloc();
#if defined(__linux__) && defined(MADV_HUGEPAGE)
    if (align == huge) (void)madvise(p, rounded, MADV_HUGEPAGE);  // advice only: failure is harmless
#endif
    p_ = std::shared_ptr<T[]>(static_cast<T*>(p), [](T* q) { std::free(q); });
    n_ = n;
  }
  /// n copies of v.
  void assign(std::size_t n, const T& v) {
    resize_for_overwrite(n);
    for (std::size_t i = 0; i < n; ++i) p_[i] = v;
  }

  [[nodiscard]] T* data() noexcept { return p_.get(); }
  [[nodiscard]] const T* data() const noexcept { return p_.get(); }
  [[nodiscard]] std::size_t size() const noexcept { return n_; }
  [[nodiscard]] bool empty() const noexcept { return n_ == 0; }
  T& operator[](std::size_t i) noexcept { return p_[i]; }
  const T& operator[](std::size_t i) const noexcept { return p_[i]; }
  T* begin() noexcept { return p_.get(); }
  T* end() noexcept { return p_.get() + n_; }
  const T* begin() const noexcept { return p_.get(); }
  const T* end() const noexcept { return p_.get() + n_; }

 private:
  std::shared_ptr<T[]> p_;
  std::size_t n_ = 0;
};

}  // namespace vmap::detail
