#pragma once
// An allocator for a volume's samples: blocks of 2 MiB or more are aligned to 2 MiB and
// advised to the kernel as transparent huge pages (Linux, THP "madvise" or "always").
// Why: a ray crossing a volume slice by slice touches a new 4 KiB page at nearly every
// sample (a slice of a 512² 16-bit scan is 512 KiB), so with small pages most samples of a
// large volume miss the TLB; with 2 MiB pages the TLB covers the whole volume.

#include <cstddef>
#include <cstdlib>
#include <new>

#if defined(__linux__)
#include <sys/mman.h>
#endif

namespace volcast {

constexpr size_t kHugePageBytes = size_t(2) << 20;

template <typename T>
struct HugePageAllocator {
    using value_type = T;
    HugePageAllocator() = default;
    template <typename U>
    HugePageAllocator(const HugePageAllocator<U> &) {}

    T *allocate(size_t n) {
        if (n > size_t(-1) / sizeof(T)) throw std::bad_array_new_length();
        const size_t bytes = n * sizeof(T);
        if (bytes < kHugePageBytes) {
            if (void *p = std::malloc(bytes == 0 ? 1 : bytes)) return static_cast<T *>(p);
            throw std::bad_alloc();
        }
        const size_t rounded = (bytes + kHugePageBytes - 1) / kHugePageBytes * kHugePageBytes;
        void *p = std::aligned_alloc(kHugePageBytes, rounded);
        if (!p) throw std::bad_alloc();
#if defined(__linux__) && defined(MADV_HUGEPAGE)
        // Advice only: where THP is off it fails and the pages stay small.
        (void)madvise(p, rounded, MADV_HUGEPAGE);
#endif
        return static_cast<T *>(p);
    }
    void deallocate(T *p, size_t) noexcept { std::free(p); }

    template <typename U>
    bool operator==(const HugePageAllocator<U> &) const noexcept { return true; }
};

} // namespace volcast
