/// @file AllocationCounter.h
/// @brief Counts heap allocations in a test executable, for tests that must show memory stays flat.
///
/// Replaces the global operator new and delete (plain, array, nothrow and sized forms) with versions
/// that count calls and live blocks, then use malloc/free. A count is exact and the same on every
/// machine and allocator, unlike resident memory, which depends on the allocator's caching and the
/// build. The live heap bytes (malloc_usable_size: what malloc handed out) and their peak are kept
/// too, for tests of an upper bound on memory (tests/TestMemory.cc): they depend on the allocator
/// only through the usable sizes, which only make a measured peak larger.
/// Aligned new (align_val_t) keeps the library's own implementation and is not counted, consistently.
/// Include this header in exactly ONE translation unit of an executable (replacement functions must be
/// defined once).
#pragma once

#include <malloc.h>

#include <atomic>
#include <cstdint>
#include <cstdlib>
#include <new>

// gcc sees free() on a pointer that "came from new"; here new is malloc, so the pair matches.
#if defined(__GNUC__) && !defined(__clang__) && __GNUC__ >= 11
#pragma GCC diagnostic ignored "-Wmismatched-new-delete"
#endif

namespace alloc_counter {
/// Calls of operator new (any counted form) since the program started.
inline std::atomic<int64_t> newCalls{0};
/// Blocks allocated through counted operator new and not yet deleted.
inline std::atomic<int64_t> liveBlocks{0};
/// Bytes of those blocks (malloc_usable_size), and the most there were since resetPeak().
inline std::atomic<int64_t> liveBytes{0}, peakBytes{0};

inline void added(void* p)
{
    newCalls.fetch_add(1, std::memory_order_relaxed);
    liveBlocks.fetch_add(1, std::memory_order_relaxed);
    const int64_t n = int64_t(malloc_usable_size(p));
    const int64_t now = liveBytes.fetch_add(n, std::memory_order_relaxed) + n;
    int64_t seen = peakBytes.load(std::memory_order_relaxed);
    while (now > seen && !peakBytes.compare_exchange_weak(seen, now, std::memory_order_relaxed)) {
    }
}
/// Starts a new peak from the bytes in use now.
inline void resetPeak()
{
    peakBytes.store(liveBytes.load());
}
} // namespace alloc_counter

void* operator new(std::size_t n)
{
    void* p = std::malloc(n ? n : 1);
    if (!p) throw std::bad_alloc();
    alloc_counter::added(p);
    return p;
}
void* operator new[](std::size_t n)
{
    return ::operator new(n);
}
void* operator new(std::size_t n, const std::nothrow_t&) noexcept
{
    try {
        return ::operator new(n);
    } catch (...) {
        return nullptr;
    }
}
void* operator new[](std::size_t n, const std::nothrow_t& t) noexcept
{
    return ::operator new(n, t);
}
void operator delete(void* p) noexcept
{
    if (!p) return;
    alloc_counter::liveBlocks.fetch_sub(1, std::memory_order_relaxed);
    alloc_counter::liveBytes.fetch_sub(int64_t(malloc_usable_size(p)), std::memory_order_relaxed);
    std::free(p); // every counted block came from malloc in operator new above
}
void operator delete[](void* p) noexcept
{
    ::operator delete(p);
}
void operator delete(void* p, std::size_t) noexcept
{
    ::operator delete(p);
}
void operator delete[](void* p, std::size_t) noexcept
{
    ::operator delete(p);
}
void operator delete(void* p, const std::nothrow_t&) noexcept
{
    ::operator delete(p);
}
void operator delete[](void* p, const std::nothrow_t&) noexcept
{
    ::operator delete(p);
}
