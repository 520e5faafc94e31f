// The batch allocator policy (vdbclay/BatchHeap.h). It is process-wide and set once, so every case
// runs in a process of its own (a death test's child, re-executed: "threadsafe" style) and checks
// what the kernel reports in /proc/self/smaps: which mapping a block lies in, and whether that
// mapping is advised for huge pages ("hg" in VmFlags).

#include "vdbclay/BatchHeap.h"
#include "vdbclay/Types.h"

#include <gtest/gtest.h>

#include <cstdint>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <fstream>
#include <sstream>
#include <string>
#include <vector>

#if defined(__SANITIZE_ADDRESS__) || defined(__SANITIZE_THREAD__)
#define VDBCLAY_SANITIZED_HEAP 1 // the sanitizers' allocators keep no brk heap
#elif defined(__has_feature)
#if __has_feature(address_sanitizer) || __has_feature(thread_sanitizer)
#define VDBCLAY_SANITIZED_HEAP 1
#endif
#endif

namespace {

#if defined(__GLIBC__) && defined(__linux__)
constexpr bool kGlibc = true;
#else
constexpr bool kGlibc = false;
#endif

#if defined(__GLIBC__) && defined(__linux__) && !defined(VDBCLAY_SANITIZED_HEAP)
/// One mapping of /proc/self/smaps.
struct Mapping {
    uintptr_t lo = 0, hi = 0;
    std::string name, flags;
};

std::vector<Mapping> mappings()
{
    std::ifstream f("/proc/self/smaps");
    std::vector<Mapping> out;
    std::string line;
    while (std::getline(f, line)) {
        unsigned long lo = 0, hi = 0;
        char dash = 0;
        std::istringstream in(line);
        if (line.compare(0, 8, "VmFlags:") == 0) {
            if (!out.empty()) out.back().flags = line.substr(8) + " ";
            continue;
        }
        if ((in >> std::hex >> lo >> dash >> hi) && dash == '-' && line.find(':') > line.find(' ')) {
            Mapping m;
            m.lo = uintptr_t(lo);
            m.hi = uintptr_t(hi);
            const size_t at = line.find_last_of(' ');
            m.name = at == std::string::npos ? "" : line.substr(at + 1);
            out.push_back(m);
        }
    }
    return out;
}

bool inHeap(const void* p)
{
    const uintptr_t a = reinterpret_cast<uintptr_t>(p);
    for (const Mapping& m : mappings())
        if (m.name == "[heap]" && a >= m.lo && a < m.hi) return true;
    return false;
}

/// Whether every huge page wholly inside [p, p + size) lies in a mapping advised for huge pages.
bool advised(const void* p, size_t size)
{
    const uintptr_t page = 2u << 20;
    const uintptr_t lo = (reinterpret_cast<uintptr_t>(p) + page - 1) & ~(page - 1);
    const uintptr_t hi = (reinterpret_cast<uintptr_t>(p) + size) & ~(page - 1);
    if (hi <= lo) return false; // nothing to check: the caller asks for a block spanning pages
    const std::vector<Mapping> maps = mappings();
    for (uintptr_t a = lo; a < hi; a += page) {
        bool found = false;
        for (const Mapping& m : maps)
            if (a >= m.lo && a < m.hi) found = m.flags.find(" hg ") != std::string::npos;
        if (!found) return false;
    }
    return true;
}

std::string thpMode()
{
    std::ifstream f("/sys/kernel/mm/transparent_hugepage/enabled");
    std::string line;
    std::getline(f, line);
    const size_t a = line.find('['), b = line.find(']');
    return a == std::string::npos || b == std::string::npos ? "" : line.substr(a + 1, b - a - 1);
}

#endif

void clearEnvironment()
{
    ::unsetenv("VDBCLAY_HEAP");
    ::unsetenv("GLIBC_TUNABLES"); // read by glibc at start only; configureBatchHeap reads it too
}

class BatchHeapTest : public ::testing::Test {
protected:
    void SetUp() override { GTEST_FLAG_SET(death_test_style, "threadsafe"); }
};

/// Ends the child: 0 when @a ok, else 1 after printing @a why (the parent shows it).
[[noreturn]] void finish(bool ok, const std::string& why)
{
    if (!ok) std::fprintf(stderr, "%s\n", why.c_str());
    std::fflush(stderr);
    std::_Exit(ok ? 0 : 1);
}

} // namespace

#if defined(__GLIBC__) && defined(__linux__) && !defined(VDBCLAY_SANITIZED_HEAP)

TEST_F(BatchHeapTest, BatchKeepsLargeBlocksInTheHeapAndAdvisesItsGrowth)
{
    EXPECT_EXIT(
        {
            clearEnvironment();
            const vdbclay::BatchHeap h = vdbclay::configureBatchHeap();
            if (!h.tuned) finish(false, "not tuned: " + h.note);
            // glibc's default threshold (128 KiB, moving up only after a free) would mmap this block.
            const size_t four = size_t(4) << 20;
            char* block = static_cast<char*>(std::malloc(four));
            std::memset(block, 1, four);
            if (!inHeap(block)) finish(false, "a 4 MiB block outside the heap: " + h.note);
            const std::string mode = thpMode();
            if (mode != "always" && mode != "madvise") {
                std::free(block);
                finish(!h.hugePages && h.note.find("no transparent huge pages") != std::string::npos,
                       "THP " + mode + " but " + h.note);
            }
            if (!h.hugePages) finish(false, "THP " + mode + " but not advised: " + h.note);
            if (!advised(block, four)) finish(false, "the first block's pages are not advised");
            if (vdbclay::adviseBatchHeapGrowth() != 0) finish(false, "advice with no growth");
            // Grow the heap past its 64 MiB pad: 12 blocks of 8 MiB, headers touched only.
            std::vector<char*> more;
            for (int i = 0; i < 12; ++i)
                more.push_back(static_cast<char*>(std::malloc(size_t(8) << 20)));
            for (char* p : more)
                if (!inHeap(p)) finish(false, "an 8 MiB block outside the heap");
            const bool lastBefore = advised(more.back(), size_t(8) << 20);
            const size_t grown = vdbclay::adviseBatchHeapGrowth();
            if (lastBefore || grown == 0)
                finish(false, "the growth was advised before the call, or not at all");
            for (char* p : more)
                if (!advised(p, size_t(8) << 20)) finish(false, "a grown block's pages are not advised");
            if (vdbclay::adviseBatchHeapGrowth() != 0) finish(false, "advised twice");
            for (char* p : more)
                std::free(p);
            std::free(block);
            finish(true, "");
        },
        ::testing::ExitedWithCode(0), "");
}

TEST_F(BatchHeapTest, SystemLeavesGlibcsDefaults)
{
    EXPECT_EXIT(
        {
            clearEnvironment();
            ::setenv("VDBCLAY_HEAP", "system", 1);
            const vdbclay::BatchHeap h = vdbclay::configureBatchHeap();
            if (h.tuned || h.hugePages || h.note != "system (VDBCLAY_HEAP=system)") finish(false, h.note);
            // Above any threshold glibc's own moves to in this process (it follows freed mmap'd blocks).
            char* block = static_cast<char*>(std::malloc(size_t(24) << 20));
            const bool heap = inHeap(block);
            std::free(block);
            if (vdbclay::adviseBatchHeapGrowth() != 0) finish(false, "advised under system");
            finish(!heap, "a 24 MiB block in the heap under glibc's defaults");
        },
        ::testing::ExitedWithCode(0), "");
}

#endif

TEST_F(BatchHeapTest, TheUsersGlibcTunablesAreLeftInForce)
{
    EXPECT_EXIT(
        {
            clearEnvironment();
            ::setenv("GLIBC_TUNABLES", "glibc.malloc.hugetlb=1", 1);
            const vdbclay::BatchHeap h = vdbclay::configureBatchHeap();
            finish(!h.tuned && !h.hugePages &&
                       (!kGlibc || h.note == "system (GLIBC_TUNABLES sets glibc.malloc)"),
                   h.note);
        },
        ::testing::ExitedWithCode(0), "");
}

TEST_F(BatchHeapTest, AnUnknownChoiceIsOneClearErrorAndChangesNothing)
{
    EXPECT_EXIT(
        {
            clearEnvironment();
            ::setenv("VDBCLAY_HEAP", "huge", 1);
            for (int call = 0; call < 2; ++call) { // still unconfigured after the first
                try {
                    vdbclay::configureBatchHeap();
                    finish(false, "no error");
                } catch (const vdbclay::Error& e) {
                    if (std::string(e.what()) != "VDBCLAY_HEAP must be \"batch\" or \"system\", got \"huge\"")
                        finish(false, e.what());
                }
            }
            if (vdbclay::adviseBatchHeapGrowth() != 0) finish(false, "advised");
            ::setenv("VDBCLAY_HEAP", "system", 1);
            finish(vdbclay::configureBatchHeap().note == "system (VDBCLAY_HEAP=system)",
                   "not configurable after");
        },
        ::testing::ExitedWithCode(0), "");
}

TEST_F(BatchHeapTest, ASecondCallReturnsTheFirstCallsResult)
{
    EXPECT_EXIT(
        {
            clearEnvironment();
            const vdbclay::BatchHeap first = vdbclay::configureBatchHeap();
            ::setenv("VDBCLAY_HEAP", "system", 1);
            const vdbclay::BatchHeap second = vdbclay::configureBatchHeap();
            finish(first.note == second.note && first.tuned == second.tuned &&
                       first.hugePages == second.hugePages,
                   first.note + " then " + second.note);
        },
        ::testing::ExitedWithCode(0), "");
}
