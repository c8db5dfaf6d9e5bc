// Giving back the memory of an array's front while the array stays allocated,
// for copies that stream one large array into another (a Cholesky factor into
// the layout its solves read): releasing the source behind the copy keeps the
// peak at about one array instead of two. The C library offers no partial
// free of one allocation; the kernel's madvise does this for whole pages.
// Not collective.
#pragma once

#include <sys/mman.h>
#include <unistd.h>

#include <cstddef>
#include <cstdint>

namespace softbody {

// Source bytes a streaming copy consumes between two releases: a system call
// per MB (256 pages freed) costs little beside copying the MB, and the copy's
// peak stays within 1 MB of one array.
constexpr size_t kReleaseBatchBytes = size_t{1} << 20;

// Returns to the system the whole pages inside [begin, end), whose contents
// the caller will never read again (MADV_DONTNEED on private memory: the pages
// are freed at once; a later read would find zeros). The partial pages at both
// ends are kept, so the allocator's own bookkeeping next to the array is not
// touched, and the allocation is freed later as usual.
inline void ReleasePages(const void *begin, const void *end) {
  const uintptr_t page = static_cast<uintptr_t>(sysconf(_SC_PAGESIZE));
  const uintptr_t first = (reinterpret_cast<uintptr_t>(begin) + page - 1) / page * page;
  const uintptr_t last = reinterpret_cast<uintptr_t>(end) / page * page;
  if (last > first) madvise(reinterpret_cast<void *>(first), last - first, MADV_DONTNEED);
}

// Releases a source array front to back as a copy consumes it: Consumed(p)
// says the copy will not read below p again; pages are released in batches of
// kReleaseBatchBytes. Does nothing when constructed with `enabled` false.
class ReleaseBehind {
 public:
  ReleaseBehind(const void *begin, bool enabled)
      : released_(static_cast<const char *>(begin)), enabled_(enabled) {}
  void Consumed(const void *upto) {
    const char *end = static_cast<const char *>(upto);
    if (!enabled_ || end < released_ + kReleaseBatchBytes) return;
    ReleasePages(released_, end);
    released_ = end;
  }

 private:
  const char *released_;
  bool enabled_;
};

}  // namespace softbody
