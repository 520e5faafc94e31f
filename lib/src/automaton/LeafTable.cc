// The flat leaf table (see LeafTable.h).
#include "automaton/LeafTable.h"

#include "automaton/BlockMasks.h"

#include <openvdb/openvdb.h>
#include <openvdb/tree/ValueAccessor.h>

#include <algorithm>
#include <optional>
#include <type_traits>

namespace vdbclay {
namespace automaton_internal {

static_assert(std::is_same<MassTree, openvdb::Int32Tree>::value, "MassTree must be openvdb::Int32Tree");
static_assert(std::is_same<ObsTree, openvdb::MaskTree>::value, "ObsTree must be openvdb::MaskTree");
static_assert(std::is_same<MassLeaf, openvdb::Int32Tree::LeafNodeType>::value, "MassLeaf: the tree's leaf");
static_assert(std::is_same<ObsLeaf, openvdb::MaskTree::LeafNodeType>::value, "ObsLeaf: the tree's leaf");
static_assert(MassLeaf::DIM == 8 && MassLeaf::SIZE == kLeafCells, "vdbclay's block masks assume 8^3 leaves");

alignas(64) const int32_t kZeroLeaf[kLeafCells] = {};

AnchorIndex LeafTable::anchorIndex() const
{
    AnchorIndex ix;
    if (!mValid) return ix;
    ix.keys = mKeys.data();
    ix.up = mUp.data();
    ix.down = mDown.data();
    ix.size = mKeys.size();
    return ix;
}

void LeafTable::resize(size_t count)
{
    mShift = 64;
    for (size_t c = count; c > 1; c >>= 1)
        --mShift;
    mSlots.assign(count, Slot{0, 0, 0, kEmpty});
    const size_t mask = count - 1;
    for (uint32_t k = 0; k < mKeys.size(); ++k) {
        const Origin& o = mKeys[k];
        size_t i = slotOf(o.x(), o.y(), o.z());
        while (mSlots[i].index != kEmpty)
            i = (i + 1) & mask;
        mSlots[i] = Slot{o.x(), o.y(), o.z(), k};
    }
}

void LeafTable::insert(const Origin& o)
{
    if (2 * (mKeys.size() + 1) > mSlots.size()) resize(std::max<size_t>(64, 2 * mSlots.size()));
    const size_t mask = mSlots.size() - 1;
    size_t i = slotOf(o.x(), o.y(), o.z());
    for (;; i = (i + 1) & mask) {
        const Slot& s = mSlots[i];
        if (s.index == kEmpty) break;
        if (s.x == o.x() && s.y == o.y() && s.z == o.z()) return;
    }
    mSlots[i] = Slot{o.x(), o.y(), o.z(), uint32_t(mKeys.size())};
    mKeys.push_back(o);
}

void LeafTable::build(MassTree& tree, const ObsTree* obstacles, bool is3D)
{
    using openvdb::Coord;
    mKeys.clear();
    mSlots.clear();
    mShift = 64;
    // The anchors whose blocks can read a leaf: its origin and, on odd steps, the origins of the
    // upper neighbours whose straddling blocks reach down into it.
    const int nd = is3D ? 8 : 4;
    for (auto it = tree.cbeginLeaf(); it; ++it) {
        const Coord o = it->origin();
        for (int d = 0; d < nd; ++d)
            insert(Origin(o.x() + ((d & 1) ? 8 : 0), o.y() + ((d & 2) ? 8 : 0), o.z() + ((d & 4) ? 8 : 0)));
    }
    // Entries in column order (Candidates' dense mode relies on it), then the hash re-filled.
    std::sort(mKeys.begin(), mKeys.end(), [](const Origin& a, const Origin& b) { return indexLess(a, b); });
    resize(std::max<size_t>(64, mSlots.size())); // find() needs a free slot
    mEntries.resize(mKeys.size());
    mUp.assign(8 * mKeys.size(), kNoEntry);
    mDown.assign(8 * mKeys.size(), kNoEntry);
    for (size_t k = 0; k < mKeys.size(); ++k) {
        const Origin& a = mKeys[k];
        for (int s = 0; s < nd; ++s) {
            const int dx = (s & 1) ? 8 : 0, dy = (s & 2) ? 8 : 0, dz = (s & 4) ? 8 : 0;
            const LeafSet* u = find(Origin(a.x() + dx, a.y() + dy, a.z() + dz));
            const LeafSet* d = find(Origin(a.x() - dx, a.y() - dy, a.z() - dz));
            if (u) mUp[8 * k + s] = uint32_t(u - mEntries.data());
            if (d) mDown[8 * k + s] = uint32_t(d - mEntries.data());
        }
    }
    openvdb::tree::ValueAccessor<MassTree, false> acc(tree);
    std::optional<openvdb::tree::ValueAccessor<const ObsTree, false>> oacc;
    if (obstacles) oacc.emplace(*obstacles);
    for (size_t k = 0; k < mKeys.size(); ++k) {
        LeafSet& e = mEntries[k];
        e.missing = e.tile = e.obsAny = e.obsTile = 0;
        for (int w = 0; w < 8; ++w) {
            const Origin lo = leafOrigin(mKeys[k], w);
            const Coord c(lo.x(), lo.y(), lo.z());
            e.leaf[w] = acc.probeLeaf(c);
            e.data[w] = e.leaf[w] ? e.leaf[w]->buffer().data() : nullptr;
            e.read[w] = e.leaf[w] ? e.data[w] : kZeroLeaf;
            if (!e.leaf[w]) {
                e.missing |= uint8_t(1u << w);
                if (acc.getValue(c) != 0) e.tile |= uint8_t(1u << w);
            }
            e.obs[w] = oacc ? oacc->probeConstLeaf(c) : nullptr;
            const bool tile = oacc && !e.obs[w] && oacc->isValueOn(c);
            if (tile) e.obsTile |= uint8_t(1u << w);
            if (e.obs[w] || tile) e.obsAny |= uint8_t(1u << w);
        }
    }
    mValid = true;
}

} // namespace automaton_internal
} // namespace vdbclay
