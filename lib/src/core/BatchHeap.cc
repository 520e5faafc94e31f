// The batch allocator policy (see vdbclay/BatchHeap.h for what and why).
//
// glibc only: its mallopt() parameters, and the heap found as the "[heap]" mapping in
// /proc/self/maps, which glibc's main arena grows with brk, contiguously from its start to the
// program break (sbrk(0)). The heap is advised from its first 2 MiB boundary to the break's last
// one; a later growth is advised from there to the new break's, so each byte is advised once. A
// heap that shrank (a trim, only past 512 MiB free at its top) is advised again as it regrows. Other
// threads' arenas are mmap'd heaps of their own and are not advised: the command's allocations are
// mostly the main thread's (the trees, the push, the output).

#include "vdbclay/BatchHeap.h"

#include "vdbclay/Types.h"

#include <cstdint>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <fstream>
#include <mutex>

#if defined(__GLIBC__) && defined(__linux__)
#include <malloc.h>
#include <sys/mman.h>
#include <unistd.h>
#define VDBCLAY_GLIBC_HEAP 1
#endif

namespace vdbclay {
namespace {

std::mutex gMutex;
bool gConfigured = false;
BatchHeap gResult;
uintptr_t gAdvisedEnd = 0; // the heap is advised up to here (a huge page boundary)
uintptr_t gPageSize = 0;   // the transparent huge page size; 0 when the heap is not advised

#if VDBCLAY_GLIBC_HEAP

/// The kernel's transparent huge page mode: "always", "madvise", "never", or "" when unknown.
std::string thpMode()
{
    std::ifstream f("/sys/kernel/mm/transparent_hugepage/enabled");
    std::string line;
    if (!std::getline(f, line)) return "";
    const size_t a = line.find('['), b = line.find(']');
    if (a == std::string::npos || b == std::string::npos || b < a) return "";
    return line.substr(a + 1, b - a - 1);
}

uintptr_t thpPageSize()
{
    std::ifstream f("/sys/kernel/mm/transparent_hugepage/hpage_pmd_size");
    unsigned long long size = 0;
    if (!(f >> size) || size < 4096 || (size & (size - 1)) != 0) size = 2ull << 20;
    return uintptr_t(size);
}

/// The start of the "[heap]" mapping, or 0.
uintptr_t heapStart()
{
    std::FILE* f = std::fopen("/proc/self/maps", "r");
    if (!f) return 0;
    char line[512];
    uintptr_t start = 0;
    while (std::fgets(line, sizeof line, f)) {
        if (!std::strstr(line, "[heap]")) continue;
        unsigned long lo = 0, hi = 0;
        if (std::sscanf(line, "%lx-%lx", &lo, &hi) == 2) start = uintptr_t(lo);
        break;
    }
    std::fclose(f);
    return start;
}

uintptr_t programBreak()
{
    return reinterpret_cast<uintptr_t>(::sbrk(0));
}

/// Advises [from, the break's last page boundary); returns the bytes advised.
size_t adviseUpToBreak(uintptr_t from)
{
    const uintptr_t end = programBreak() & ~(gPageSize - 1);
    if (end < gAdvisedEnd) gAdvisedEnd = end; // trimmed: advise again as it regrows
    if (end <= from) return 0;
    if (::madvise(reinterpret_cast<void*>(from), end - from, MADV_HUGEPAGE) != 0) return 0;
    gAdvisedEnd = end;
    return size_t(end - from);
}

#endif

BatchHeap configure()
{
    BatchHeap r;
    const char* choice = std::getenv("VDBCLAY_HEAP");
    if (choice && std::strcmp(choice, "batch") != 0 && std::strcmp(choice, "system") != 0)
        throw Error(std::string("VDBCLAY_HEAP must be \"batch\" or \"system\", got \"") + choice + "\"");
    if (choice && std::strcmp(choice, "system") == 0) {
        r.note = "system (VDBCLAY_HEAP=system)";
        return r;
    }
#if VDBCLAY_GLIBC_HEAP
    const char* tunables = std::getenv("GLIBC_TUNABLES");
    if (tunables && std::strstr(tunables, "glibc.malloc.")) {
        r.note = "system (GLIBC_TUNABLES sets glibc.malloc)";
        return r;
    }
    // 32 MiB is the largest mmap threshold glibc takes on 64-bit (HEAP_MAX_SIZE / 2).
    if (::mallopt(M_MMAP_THRESHOLD, 32 << 20) != 1 || ::mallopt(M_TRIM_THRESHOLD, 512 << 20) != 1 ||
        ::mallopt(M_TOP_PAD, 64 << 20) != 1) {
        r.note = "system (mallopt refused the batch parameters)";
        return r;
    }
    r.tuned = true;
    const std::string mode = thpMode();
    if (mode != "always" && mode != "madvise") {
        r.note = "batch (no transparent huge pages: " + (mode.empty() ? std::string("unknown") : mode) + ")";
        return r;
    }
    // One block from the heap grows it by the top pad, so there is a heap to advise.
    void* volatile block = std::malloc(1 << 20);
    std::free(block);
    gPageSize = thpPageSize();
    const uintptr_t start = heapStart();
    if (start == 0) {
        gPageSize = 0;
        r.note = "batch (no [heap] mapping to advise)";
        return r;
    }
    gAdvisedEnd = (start + gPageSize - 1) & ~(gPageSize - 1);
    adviseUpToBreak(gAdvisedEnd);
    r.hugePages = true;
    r.note = "batch (transparent huge pages)";
#else
    r.note = "system (not glibc on Linux)";
#endif
    return r;
}

} // namespace

BatchHeap configureBatchHeap()
{
    std::lock_guard<std::mutex> lock(gMutex);
    if (!gConfigured) {
        gResult = configure(); // a throw leaves it unconfigured: the next call reports the same error
        gConfigured = true;
    }
    return gResult;
}

size_t adviseBatchHeapGrowth()
{
#if VDBCLAY_GLIBC_HEAP
    std::lock_guard<std::mutex> lock(gMutex);
    if (gPageSize == 0) return 0;
    return adviseUpToBreak(gAdvisedEnd);
#else
    return 0;
#endif
}

} // namespace vdbclay
