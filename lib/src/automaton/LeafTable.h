// The flat leaf table: an anchor's leaves by one hash lookup (no OpenVDB in this header).
//
// For every anchor that can reach a mass leaf (a leaf's origin, or one of its upper neighbours'
// origins), the table holds the 8 leaves leafOrigin(anchor, w) its blocks read (null when missing)
// and their obstacle leaves or tiles: one lookup instead of up to 16 accessor probes per anchor, and
// none when the work item carries the anchor's index. Entries are numbered in column order
// (indexLess; Candidates' dense mode scans them in that order). The table describes the topology of
// both trees when build() ran: the Automaton clears it whenever a leaf may have been created or
// removed, or the obstacles changed (edits, resync, grown leaves), and rebuilds it before a later
// pass. An anchor the table does not hold (all its mass leaves missing) is fetched through
// accessors, as without a table.
#pragma once

#include "automaton/Candidates.h"

#include "vdbclay/Fwd.h"

#include <cstddef>
#include <cstdint>
#include <vector>

namespace vdbclay {
namespace automaton_internal {

using MassTree = Tree543<int32_t>;
using ObsTree = Tree543<openvdb::ValueMask>;
using MassLeaf = openvdb::tree::LeafNode<int32_t, 3>;
using ObsLeaf = openvdb::tree::LeafNode<openvdb::ValueMask, 3>;

/// The cells of a leaf (8^3; checked against OpenVDB's in LeafTable.cc).
constexpr size_t kLeafCells = 512;

/// What a missing leaf reads as: the background value, 0.
alignas(64) extern const int32_t kZeroLeaf[kLeafCells];

/// The leaves an anchor's blocks touch (slot w: leafOrigin(anchor, w)), as the pass reads them: a
/// leaf table's entry, or what the pass fetched through accessors. The pass reads it through a
/// pointer, never a copy, so an item touches only the lines of the slots its blocks use: read[]
/// (the filter and the loads) first, then data[] (the stores), leaf[] (a voxel turned active) and
/// obs[] (only where obstacles are).
struct LeafSet {
    const int32_t* read[8]; // data, or kZeroLeaf for a missing leaf: reads need no null test
    int32_t* data[8];       // null for a missing leaf
    MassLeaf* leaf[8];
    const ObsLeaf* obs[8];
    uint8_t missing; // slots whose mass leaf is missing
    uint8_t tile;    // missing slots inside a tile holding clay: read as 0 they would be wrong, so a
                     // pass defers every block touching one to the serial grow stage
    uint8_t obsAny;  // slots holding obstacles: an obstacle leaf, or an active obstacle tile
    uint8_t obsTile; // slots inside an active obstacle tile (no obstacle leaf)
};

class LeafTable {
public:
    /// Indexes every leaf of @a tree (and the obstacles of @a obstacles, which may be null).
    void build(MassTree& tree, const ObsTree* obstacles, bool is3D);
    /// Forgets the table: no pass uses it until the next build().
    void clear() { mValid = false; }
    bool valid() const { return mValid; }
    /// Anchors indexed (0 when not valid).
    size_t size() const { return mValid ? mKeys.size() : 0; }
    /// The anchors in column order with their neighbours; WorkItem::entry indexes them (valid tables).
    AnchorIndex anchorIndex() const;

    /// The leaves of entry @a e (< size()).
    const LeafSet& entry(uint32_t e) const { return mEntries[e]; }
    /// The leaves of anchor @a o, or null when the table lacks it (valid tables).
    const LeafSet* find(const Origin& o) const
    {
        const size_t mask = mSlots.size() - 1;
        for (size_t i = slotOf(o.x(), o.y(), o.z());; i = (i + 1) & mask) {
            const Slot& s = mSlots[i];
            if (s.index == kEmpty) return nullptr;
            if (s.x == o.x() && s.y == o.y() && s.z == o.z()) return &mEntries[s.index];
        }
    }

private:
    struct Slot {
        int32_t x, y, z;
        uint32_t index; // into mEntries; kEmpty: a free slot
    };
    static constexpr uint32_t kEmpty = UINT32_MAX;

    size_t slotOf(int32_t x, int32_t y, int32_t z) const
    {
        uint64_t k = uint64_t(uint32_t(x) >> 3) * 0x9E3779B97F4A7C15ull;
        k += uint64_t(uint32_t(y) >> 3) * 0xC2B2AE3D27D4EB4Full +
             uint64_t(uint32_t(z) >> 3) * 0x165667B19E3779F9ull;
        k ^= k >> 29;
        k *= 0xBF58476D1CE4E5B9ull;
        return size_t(k >> mShift);
    }
    /// Re-fills the hash with @a count slots (a power of two, at least twice the keys).
    void resize(size_t count);
    /// Adds anchor @a o to the keys unless it is there.
    void insert(const Origin& o);

    std::vector<LeafSet> mEntries;
    std::vector<Origin> mKeys;        // mEntries[i]'s anchor, in column order (indexLess)
    std::vector<uint32_t> mUp, mDown; // AnchorIndex's neighbours, 8 per entry
    std::vector<Slot> mSlots;         // open addressing, linear probing, at most half full
    int mShift = 64;
    bool mValid = false;
};

} // namespace automaton_internal
} // namespace vdbclay
