// Where the clay changed, leaf slot by leaf slot (no OpenVDB here).
//
// A ChangedClay holds, for each leaf slot (8^3 voxels; slot = voxel >> 3) where some voxel's mass
// changed, the bounds of those voxels. An Automaton records into the one attached to it
// (automaton_internal::setChangedClay): every block a step changed, each cell setMasses() set, and
// the part of an edit()'s region in each of its leaves (the edit does not say which voxels it
// changed). The Sculptor's surface tension reads it to smooth only the surface a frame changed
// (sculpt/SurfaceTension.h). Recording appends (a step's changed blocks cost a few stores each);
// compact() merges the entries of a slot into one, in slot order, and runs whenever the entries
// have doubled since the last, so the memory follows the slots changed, not the steps run. The
// compacted entries are a set: they do not depend on the order of recording, so not on the thread
// count either.
#pragma once

#include "vdbclay/Types.h"

#include <array>
#include <cstddef>
#include <cstdint>
#include <vector>

namespace vdbclay {
namespace automaton_internal {

class ChangedClay {
public:
    /// A slot (voxel >> 3 along each axis) and the bounds of its changed voxels.
    struct Entry {
        std::array<int32_t, 3> slot{{0, 0, 0}};
        Box voxels;
    };
    /// Records that voxels of @a box (inclusive, not empty) changed.
    void add(const Box& box);
    /// Records one changed voxel.
    void addVoxel(int32_t x, int32_t y, int32_t z)
    {
        Entry e;
        e.slot = {{x >> 3, y >> 3, z >> 3}};
        e.voxels.min = e.voxels.max = {{x, y, z}};
        push(e);
    }
    /// Records @a entry as it is (a checkpoint's entries read back).
    void push(const Entry& entry)
    {
        mEntries.push_back(entry);
        if (mEntries.size() >= 2 * mCompacted + 4096) compact();
    }
    /// One entry per slot, in slot order (x, then y, then z), each the union of that slot's boxes.
    void compact();
    /// The entries, compacted.
    const std::vector<Entry>& entries()
    {
        compact();
        return mEntries;
    }
    /// The entries compacted, leaving this one as it is.
    std::vector<Entry> compacted() const
    {
        ChangedClay c = *this;
        c.compact();
        return c.mEntries;
    }
    bool empty() const { return mEntries.empty(); }
    void clear()
    {
        mEntries.clear();
        mCompacted = 0;
    }
    /// Bytes held (the memory estimate's kChangedClayBytesPerSlot per slot, twice over while appending).
    size_t bytes() const { return mEntries.capacity() * sizeof(Entry); }

private:
    std::vector<Entry> mEntries;
    size_t mCompacted = 0; ///< entries after the last compact()
};

} // namespace automaton_internal
} // namespace vdbclay
