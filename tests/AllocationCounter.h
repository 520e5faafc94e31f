/// @file AllocationCounter.h
/// @brief Counts heap allocations in a test executable, for tests that must show memory stays flat.
///
/// Replaces the global operator new and delete (plain, array and nothrow forms) with versions that
/// count calls and live blocks, then use malloc/free. A count is exact and the same on every machine
/// and allocator, unlike resident memory, which depends on the allocator's caching and the build.
/// Aligned new (align_val_t) keeps the library's own implementation and is not counted, consistently.
/// Include this header in exactly ONE translation unit of an executable (replacement functions must be
/// defined once).
#pragma once

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
} // namespace alloc_counter

void* operator new(std::size_t n)
{
    void* p = std::malloc(n ? n : 1);
    if (!p) throw std::bad_alloc();
    alloc_counter::newCalls.fetch_add(1, std::memory_order_relaxed);
    alloc_counter::liveBlocks.fetch_add(1, std::memory_order_relaxed);
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
