/// @file BatchHeap.h
/// @brief The allocator policy of a batch process (the vdbclay command): freed memory kept for
///        reuse, the heap backed by transparent huge pages.
///
/// A run builds and frees OpenVDB trees frame after frame: every upper internal node is a 256 KiB
/// table that its constructor zeroes, the push's and the output's buffers are megabytes, and each
/// frame frees them again. glibc's defaults hand blocks above a moving threshold (128 KiB to
/// 32 MiB) to mmap and return them to the kernel on free, and trim the heap's top, so the next
/// frame faults the same memory in again, 4 KiB at a time. configureBatchHeap() sets glibc's
/// documented mallopt() parameters instead (blocks below 32 MiB from the heap, no trimming below
/// 512 MiB, the heap grown 64 MiB at a time) and advises the heap for transparent huge pages
/// (madvise MADV_HUGEPAGE, where the kernel's THP mode is "madvise" or "always"): a 2 MiB page is
/// one fault instead of 512. The heap's later growth is advised by adviseBatchHeapGrowth(), which
/// the command calls after each frame. What glibc's GLIBC_TUNABLES=glibc.malloc.hugetlb=1 does
/// per extension, done from inside the process, where a user cannot be asked to set it.
///
/// Process-wide and permanent: for a program that owns its process. A host application (Blender,
/// Houdini, a Python session) keeps its own allocator: the library never calls these itself.
///
/// VDBCLAY_HEAP in the environment chooses: "batch" (the default) or "system" (glibc's defaults,
/// nothing changed). A GLIBC_TUNABLES that sets any glibc.malloc tunable is the user's own choice
/// and is left in force (nothing changed either). Elsewhere than glibc on Linux, nothing changes.
#pragma once

#include <cstddef>
#include <string>

namespace vdbclay {

/// What configureBatchHeap() did.
struct BatchHeap {
    bool tuned = false;     ///< glibc's malloc parameters set (blocks kept, heap grown in large steps)
    bool hugePages = false; ///< the heap advised for transparent huge pages
    std::string note;       ///< one line: what was done, or why not
};

/// Sets the process's allocator policy (see the file comment); call once, first thing in main().
/// Calling it again changes nothing and returns the first call's result.
/// @throw Error if VDBCLAY_HEAP is set to anything but "batch" or "system".
BatchHeap configureBatchHeap();

/// Advises the part of the heap grown since the last advice for transparent huge pages (one read of
/// the program break, and one madvise when it grew). Returns the bytes newly advised; 0 when
/// configureBatchHeap() did not advise the heap.
size_t adviseBatchHeapGrowth();

} // namespace vdbclay
