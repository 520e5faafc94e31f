// Which sanitizer a test binary was built with, for the tests a sanitizer cannot run as written.
#pragma once

// ThreadSanitizer (GCC defines __SANITIZE_THREAD__, Clang answers __has_feature). It kills a child
// of a multi-threaded fork() that starts threads (die_after_fork), so the fork tests skip under it.
#if defined(__SANITIZE_THREAD__)
#define VDBCLAY_TSAN 1
#elif defined(__has_feature)
#if __has_feature(thread_sanitizer)
#define VDBCLAY_TSAN 1
#endif
#endif

// AddressSanitizer: its allocator's locks may be copied held into a multi-threaded fork's child,
// which then hangs at its first allocation (seen once in CI: the crew's fork test, 120 s).
#if defined(__SANITIZE_ADDRESS__)
#define VDBCLAY_ASAN 1
#elif defined(__has_feature)
#if __has_feature(address_sanitizer)
#define VDBCLAY_ASAN 1
#endif
#endif
