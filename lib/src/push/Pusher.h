// The push's sources and their targets (Push.cc, steps 1 to 3): the clay voxels inside the tools, and
// for each the free voxel its clay goes to, with the clay planned so far.
//
// Sources. Only the mass leaves that meet the tools' bounds are visited (ClayLeaves.h), each in
// parallel, its sources collected apart and merged in leaf order, then sorted in coordinate order:
// the cost follows the clay inside the tools' bounds, and the list does not depend on the thread
// count. Each source is given the tool that holds it most deeply (smallest distance; ties: the
// first tool).
//
// Targets. A march from the source's centre along its tool's unit normal to (-distance + 0.5) past
// the surface, then on in half-voxel steps for up to maxSearch voxels, until the voxel at the rounded
// point is free (outside every tool, not an obstacle, inside the region, room for the clay below
// INT32_MAX); it stops at a wall (an obstacle that is not part of a tool). Failing that, a
// breadth-first flood from the source through passable voxels (inside a tool, or not an obstacle),
// 6-connected (4 in 2D), within Chebyshev distance maxSearch, neighbours in a fixed order: the first
// free voxel reached. So clay never crosses an obstacle, however thin. Failing that, the clay is
// trapped.
//
// findAlone() searches against the grid alone (thread-safe: sources are searched in parallel);
// target() counts the clay planned so far. The planned clay only makes voxels less free (the room
// test) and changes neither walls nor passability, so with it the march and the flood visit the same
// voxels up to the one found alone, and stop there iff it still has room (fits()); a source trapped
// alone is trapped with it. Checked in source order, a search alone that still fits is the search
// with the planned clay: the same targets as a serial search.
#pragma once

#include "core/CoordHash.h"

#include "vdbclay/Fwd.h"
#include "vdbclay/Shapes.h"
#include "vdbclay/Types.h"

#include <openvdb/Types.h>

#include <climits>
#include <cstddef>
#include <cstdint>
#include <unordered_map>
#include <utility>
#include <vector>

namespace vdbclay {

class Automaton;

namespace push_internal {

using openvdb::Coord;

/// maxSearch at most; the compress push's deepest chain.
constexpr int kMaxSearchLimit = 1024;

inline bool inside(const Box& b, const Coord& c)
{
    return c.x() >= b.min[0] && c.x() <= b.max[0] && c.y() >= b.min[1] && c.y() <= b.max[1] &&
           c.z() >= b.min[2] && c.z() <= b.max[2];
}

/// The clay planned into voxels so far (the targets' room test, the edit): a hash map from voxel to
/// its entry, the entries in the order of their first add (source order: deterministic, and near
/// coordinate order, so the edit's accessor walks the tree in order). A std::map does the same at
/// ~2.5x the cost (a tree node per voxel, log n compares per lookup).
class PlannedClay {
public:
    int64_t get(const Coord& c) const
    {
        const auto it = mIndex.find(c);
        return it != mIndex.end() ? mEntries[it->second].second : 0;
    }
    void add(const Coord& c, int64_t m)
    {
        const auto r = mIndex.emplace(c, uint32_t(mEntries.size()));
        if (r.second)
            mEntries.emplace_back(c, m);
        else
            mEntries[r.first->second].second += m;
    }
    void reserve(size_t n)
    {
        mIndex.reserve(n);
        mEntries.reserve(n);
    }
    using Entries = std::vector<std::pair<Coord, int64_t>>;
    const Entries& entries() const { return mEntries; }

private:
    std::unordered_map<Coord, uint32_t, CoordHash> mIndex;
    Entries mEntries;
};

/// A clay voxel inside a tool: its mass, the tool that holds it most deeply and its distance there.
struct Source {
    Coord c;
    int32_t mass;
    size_t tool;
    double distance;
};

/// What a search found for one source.
struct Found {
    bool ok = false; ///< false: trapped
    Coord to;
    Vec3 normal{{0, 1, 0}}; ///< the march's direction
    double t = 0;           ///< the march's parameter at the target
    bool byMarch = false;   ///< found by the march (else by the flood)
};

class Pusher {
public:
    Pusher(const Automaton& a, const std::vector<ShapePtr>& tools, int maxSearch);

    /// The union of the tools' bounds (2D: clipped to z = 0).
    Box toolBounds() const;
    /// The region targets must lie in (and the chains, until setChainRegion()).
    void setRegion(const Box& r) { mRegion = mChainRegion = r; }
    /// Compress: the region the chains may reach (at least the push's region).
    void setChainRegion(const Box& r) { mChainRegion = r; }
    const Box& chainRegion() const { return mChainRegion; }

    /// Clay voxels inside a tool whose bounds meet @a u, in coordinate order (@a threads as the
    /// automaton's: the list does not depend on it).
    std::vector<Source> sources(const Box& u, int threads) const;

    /// The unit normal of @a s's tool at its centre (2D: z dropped; up when undefined).
    Vec3 unitNormal(const Source& s) const;

    /// Where the clay of @a s goes, against the grid alone (thread-safe: reads the grid and the tools).
    Found findAlone(const Source& s) const { return find(s, /*planned=*/false); }
    /// Where the clay of @a s goes, with the clay planned so far.
    Found target(const Source& s) const { return find(s, /*planned=*/true); }
    /// Whether @a m more clay still fits at @a c with the clay planned so far.
    bool fits(const Coord& c, int32_t m) const { return planned(c) + m <= INT32_MAX; }

    /// The voxel at the rounded point @a t along @a n from @a s's centre (2D: z = 0).
    Coord along(const Source& s, const Vec3& n, double t) const;
    /// @a c can take @a m more clay (with the clay planned so far) and lies in @a region, in the
    /// plane (2D), outside every tool and obstacle.
    bool isFree(const Coord& c, int32_t m, const Box& region) const { return isFree(c, m, region, true); }
    bool inAnyTool(const Coord& c) const;
    bool isObstacle(const Coord& c) const;
    int32_t massAt(const Coord& c) const; ///< the grid's, before the push
    bool is2D() const { return mIs2D; }
    size_t toolCount() const { return mTools.size(); }

    /// The value of @a c after the moves planned so far (pooled shares excluded).
    int64_t planned(const Coord& c) const { return int64_t(massAt(c)) + mAdded.get(c); }
    void add(const Coord& c, int32_t m) { mAdded.add(c, m); }
    void reserve(size_t voxels) { mAdded.reserve(voxels); }
    const PlannedClay::Entries& added() const { return mAdded.entries(); }

private:
    Found find(const Source& s, bool planned) const;
    /// An obstacle that is not part of a tool: clay can neither stop in it nor pass through it.
    bool isWall(const Coord& c) const { return isObstacle(c) && !inAnyTool(c); }
    bool isFree(const Coord& c, int32_t m, const Box& region, bool planned) const;

    const std::vector<ShapePtr>& mTools;
    std::vector<Box> mBounds;
    int mMaxSearch;
    bool mIs2D;
    const Tree543<int32_t>& mMass;
    const Tree543<openvdb::ValueMask>* mObs;
    Box mRegion, mChainRegion;
    PlannedClay mAdded;
};

} // namespace push_internal
} // namespace vdbclay
