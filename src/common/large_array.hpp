// Arrays of hundreds of megabytes that are streamed from memory (the factor of
// a supernodal Cholesky solve, the triad's arrays): 2 MB aligned and, where the
// kernel allows it (transparent huge pages in "madvise" mode), backed by 2 MB
// pages, so that the streaming loads do not stop at every 4 KB page for a TLB
// miss.
// Not collective.
#pragma once

#include <sys/mman.h>

#include <cstddef>
#include <cstdlib>
#include <new>

namespace softbody {

template <typename T>
class LargeArray {
 public:
  LargeArray() = default;
  explicit LargeArray(size_t size) { resize(size); }
  LargeArray(const LargeArray &) = delete;
  LargeArray &operator=(const LargeArray &) = delete;
  ~LargeArray() { std::free(data_); }

  // Discards the contents; the new elements are uninitialised.
  void resize(size_t size) {
    std::free(data_);
    data_ = nullptr;
    size_ = size;
    if (!size) return;
    constexpr size_t kHuge = size_t(2) << 20;
    const size_t bytes = (size * sizeof(T) + kHuge - 1) / kHuge * kHuge;
    data_ = static_cast<T *>(std::aligned_alloc(kHuge, bytes));
    if (!data_) throw std::bad_alloc();
    madvise(data_, bytes, MADV_HUGEPAGE);  // a hint: without huge pages it is an ordinary array
  }
  size_t size() const { return size_; }
  T *data() { return data_; }
  const T *data() const { return data_; }
  T &operator[](size_t i) { return data_[i]; }
  const T &operator[](size_t i) const { return data_[i]; }

 private:
  T *data_ = nullptr;
  size_t size_ = 0;
};

}  // namespace softbody
