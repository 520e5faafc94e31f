// Values per voxel held as dense arrays, one per 8^3 leaf slot: the push's planned clay and pools.
//
// A table from leaf origin to a leaf's array of 512 values (zero where nothing was set): one hash
// lookup per leaf, and none while an Accessor stays in the leaf it last visited (a chain walks 8
// voxels of a column in a leaf, a pass over the leaves walks 512), instead of a hash lookup and a
// node per voxel. Leaves are numbered in the order of their creation; sortTreeOrder() renumbers them
// in an OpenVDB Tree543's order, so a walk over the leaves and their voxels by offset visits the
// voxels in the order a tree's value iterator would. Reads through separate Accessors may run in
// parallel while nothing creates a leaf; a leaf's values may be written in parallel by the one task
// that owns the leaf.
#pragma once

#include "core/CoordHash.h"

#include <openvdb/Types.h>

#include <algorithm>
#include <array>
#include <cstddef>
#include <cstdint>
#include <memory>
#include <type_traits>
#include <unordered_map>
#include <vector>

namespace vdbclay {
namespace push_internal {

/// The voxels of a leaf slot.
constexpr uint32_t kSlotVoxels = 512;

/// The origin of the 8^3 leaf slot holding @a c.
inline openvdb::Coord slotOrigin(const openvdb::Coord& c)
{
    return openvdb::Coord(c.x() & ~7, c.y() & ~7, c.z() & ~7);
}

/// @a c's place in its slot, as OpenVDB's LeafNode numbers its voxels (x, then y, then z).
inline uint32_t slotOffset(const openvdb::Coord& c)
{
    return (uint32_t(c.x() & 7) << 6) | (uint32_t(c.y() & 7) << 3) | uint32_t(c.z() & 7);
}

/// The voxel at @a offset of the slot at @a origin.
inline openvdb::Coord slotVoxel(const openvdb::Coord& origin, uint32_t offset)
{
    return origin.offsetBy(int32_t(offset >> 6), int32_t((offset >> 3) & 7), int32_t(offset & 7));
}

/// Whether the leaf slot at @a a comes before the one at @a b in a Tree543's order: the root's
/// 4096^3 nodes by origin (x, then y, then z), the 128^3 nodes within one, then the leaves within that.
inline bool treeOrderLess(const openvdb::Coord& a, const openvdb::Coord& b)
{
    const openvdb::Coord ra(a.x() & ~4095, a.y() & ~4095, a.z() & ~4095);
    const openvdb::Coord rb(b.x() & ~4095, b.y() & ~4095, b.z() & ~4095);
    if (ra != rb) return ra < rb;
    const openvdb::Coord ia((a.x() >> 7) & 31, (a.y() >> 7) & 31, (a.z() >> 7) & 31);
    const openvdb::Coord ib((b.x() >> 7) & 31, (b.y() >> 7) & 31, (b.z() >> 7) & 31);
    if (ia != ib) return ia < ib;
    return openvdb::Coord((a.x() >> 3) & 15, (a.y() >> 3) & 15, (a.z() >> 3) & 15) <
           openvdb::Coord((b.x() >> 3) & 15, (b.y() >> 3) & 15, (b.z() >> 3) & 15);
}

template <typename T> class LeafArrays {
public:
    struct Leaf {
        openvdb::Coord origin;
        std::array<T, kSlotVoxels> v{}; // zero-initialized
    };

    /// Cached reads (and, unless @a Const, writes) for one thread: the leaf it last visited, or that
    /// this leaf was missing when the table last grew.
    template <bool Const> class AccessorT {
    public:
        using Arrays = std::conditional_t<Const, const LeafArrays, LeafArrays>;
        using LeafPtr = std::conditional_t<Const, const Leaf*, Leaf*>;
        explicit AccessorT(Arrays& a) : mArrays(&a) {}
        /// The value at @a c (0 where no leaf is).
        T get(const openvdb::Coord& c)
        {
            const LeafPtr l = find(slotOrigin(c));
            return l ? l->v[slotOffset(c)] : T(0);
        }
        /// The value at @a c, its leaf created if missing.
        T& ref(const openvdb::Coord& c)
        {
            const openvdb::Coord o = slotOrigin(c);
            if (!mLeaf || o != mOrigin) {
                mLeaf = &mArrays->obtain(o);
                mOrigin = o;
                mVersion = mArrays->mVersion;
            }
            return mLeaf->v[slotOffset(c)];
        }

    private:
        LeafPtr find(const openvdb::Coord& o)
        {
            if (mArrays->mLeaves.empty()) return nullptr;
            if (o == mOrigin && (mLeaf || mVersion == mArrays->mVersion)) return mLeaf;
            mOrigin = o;
            mLeaf = mArrays->find(o);
            mVersion = mArrays->mVersion; // a missing leaf stays missing until a leaf is created
            return mLeaf;
        }
        Arrays* mArrays;
        openvdb::Coord mOrigin;
        LeafPtr mLeaf = nullptr;
        uint64_t mVersion = UINT64_MAX; // nothing cached yet
    };
    using Accessor = AccessorT<false>;
    using ConstAccessor = AccessorT<true>;

    Leaf* find(const openvdb::Coord& origin) const
    {
        const auto it = mIndex.find(origin);
        return it != mIndex.end() ? mLeaves[it->second].get() : nullptr;
    }
    Leaf& obtain(const openvdb::Coord& origin)
    {
        const auto r = mIndex.emplace(origin, uint32_t(mLeaves.size()));
        if (r.second) {
            mLeaves.push_back(std::make_unique<Leaf>());
            mLeaves.back()->origin = origin;
            ++mVersion;
        }
        return *mLeaves[r.first->second];
    }
    size_t leafCount() const { return mLeaves.size(); }
    Leaf& leaf(size_t i) { return *mLeaves[i]; }
    const Leaf& leaf(size_t i) const { return *mLeaves[i]; }
    bool empty() const { return mLeaves.empty(); }

    /// Renumbers the leaves in a Tree543's order (treeOrderLess).
    void sortTreeOrder()
    {
        std::sort(mLeaves.begin(), mLeaves.end(),
                  [](const std::unique_ptr<Leaf>& a, const std::unique_ptr<Leaf>& b) {
                      return treeOrderLess(a->origin, b->origin);
                  });
        for (size_t i = 0; i < mLeaves.size(); ++i)
            mIndex[mLeaves[i]->origin] = uint32_t(i);
    }

private:
    std::unordered_map<openvdb::Coord, uint32_t, CoordHash> mIndex;
    std::vector<std::unique_ptr<Leaf>> mLeaves;
    uint64_t mVersion = 0; // leaves created so far
};

} // namespace push_internal
} // namespace vdbclay
