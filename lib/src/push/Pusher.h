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
//
// The planned clay is a value per voxel in dense arrays per 8^3 leaf (LeafArrays.h). The grid, the
// obstacles and the planned clay are read through a Reader's cached accessors, one Reader per thread:
// a chain or a pass over a leaf costs a lookup per leaf, not per voxel.
#pragma once

#include "push/LeafArrays.h"

#include "vdbclay/Fwd.h"
#include "vdbclay/Shapes.h"
#include "vdbclay/Types.h"

#include <openvdb/openvdb.h>

#include <algorithm>
#include <climits>
#include <cmath>
#include <cstddef>
#include <cstdint>
#include <memory>
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

/// The clay planned into voxels so far (the targets' room test, the edit), per voxel: 0 where none.
/// A voxel's mass with its planned clay never exceeds INT32_MAX (every add passed the room test), so
/// the planned clay fits an int32.
using PlannedClay = LeafArrays<int32_t>;

/// The voxels of @a a holding a nonzero value (empty box if none).
inline Box nonZeroBounds(const LeafArrays<int32_t>& a)
{
    Box b;
    for (size_t l = 0; l < a.leafCount(); ++l) {
        const LeafArrays<int32_t>::Leaf& leaf = a.leaf(l);
        uint32_t lo[3] = {7, 7, 7}, hi[3] = {0, 0, 0};
        bool any = false;
        for (uint32_t i = 0; i < kSlotVoxels; ++i) {
            if (!leaf.v[i]) continue;
            const uint32_t p[3] = {i >> 6, (i >> 3) & 7, i & 7};
            for (int k = 0; k < 3; ++k) {
                lo[k] = std::min(lo[k], p[k]);
                hi[k] = std::max(hi[k], p[k]);
            }
            any = true;
        }
        if (!any) continue;
        const Coord& o = leaf.origin;
        b = unite(b, Box{{{o.x() + int32_t(lo[0]), o.y() + int32_t(lo[1]), o.z() + int32_t(lo[2])}},
                         {{o.x() + int32_t(hi[0]), o.y() + int32_t(hi[1]), o.z() + int32_t(hi[2])}}});
    }
    return b;
}

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

    /// Reads for one thread, through accessors that cache the leaves last visited: the grid before
    /// the push, the obstacles and the clay planned so far (which it sees as it grows). Several
    /// Readers may read in parallel while nothing is planned.
    class Reader {
    public:
        explicit Reader(const Pusher& p);
        int32_t massAt(const Coord& c) { return mMass.getValue(c); } ///< the grid's, before the push
        bool isObstacle(const Coord& c) { return mObs && mObs->isValueOn(c); }
        /// The value of @a c after the moves planned so far (pooled shares excluded).
        int64_t planned(const Coord& c) { return int64_t(massAt(c)) + mAdded.get(c); }
        /// Whether @a m more clay still fits at @a c with the clay planned so far.
        bool fits(const Coord& c, int32_t m) { return planned(c) + m <= INT32_MAX; }
        /// @a c can take @a m more clay (with the clay planned so far unless @a planned is false) and
        /// lies in @a region, in the plane (2D), outside every tool and obstacle.
        bool isFree(const Coord& c, int32_t m, const Box& region, bool planned = true);
        /// An obstacle that is not part of a tool: clay can neither stop in it nor pass through it.
        bool isWall(const Coord& c) { return isObstacle(c) && !mPusher.inAnyTool(c); }
        const Pusher& pusher() const { return mPusher; }

    private:
        const Pusher& mPusher;
        openvdb::tree::ValueAccessor<const Tree543<int32_t>, false> mMass;
        std::unique_ptr<openvdb::tree::ValueAccessor<const Tree543<openvdb::ValueMask>, false>> mObs;
        PlannedClay::ConstAccessor mAdded;
    };

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
    Found findAlone(const Source& s) const
    {
        Reader r(*this);
        return find(s, /*planned=*/false, r);
    }
    /// Where the clay of @a s goes, with the clay planned so far.
    Found target(const Source& s, Reader& r) const { return find(s, /*planned=*/true, r); }

    /// The voxel at the rounded point @a t along @a n from @a s's centre (2D: z = 0).
    Coord along(const Source& s, const Vec3& n, double t) const;
    bool inAnyTool(const Coord& c) const;
    bool is2D() const { return mIs2D; }
    size_t toolCount() const { return mTools.size(); }

    /// Plans @a m more clay into @a c (@a m > 0, and it fits: Reader::fits()).
    void add(const Coord& c, int32_t m) { mAddAcc.ref(c) += m; }
    /// The clay planned so far, per voxel (0: none).
    const PlannedClay& added() const { return mAdded; }

private:
    Found find(const Source& s, bool planned, Reader& r) const;

    const std::vector<ShapePtr>& mTools;
    std::vector<Box> mBounds;
    int mMaxSearch;
    bool mIs2D;
    const Tree543<int32_t>& mMass;
    const Tree543<openvdb::ValueMask>* mObs;
    Box mRegion, mChainRegion;
    PlannedClay mAdded;
    PlannedClay::Accessor mAddAcc{mAdded};
};

inline Coord Pusher::along(const Source& s, const Vec3& n, double t) const
{
    const Vec3 p{{double(s.c.x()), double(s.c.y()), double(s.c.z())}};
    const Vec3 q{{p[0] + t * n[0], p[1] + t * n[1], p[2] + t * n[2]}};
    int32_t v[3];
    for (int i = 0; i < 3; ++i) {
        const double r = std::floor(q[i] + 0.5);
        v[i] = int32_t(std::clamp(r, double(INT32_MIN / 2), double(INT32_MAX / 2)));
    }
    if (mIs2D) v[2] = 0;
    return Coord(v[0], v[1], v[2]);
}

inline bool Pusher::Reader::isFree(const Coord& c, int32_t m, const Box& region, bool planned)
{
    if (!inside(region, c)) return false;
    if (mPusher.mIs2D && c.z() != 0) return false;
    if (isObstacle(c)) return false;
    if (mPusher.inAnyTool(c)) return false;
    const int64_t now = planned ? this->planned(c) : int64_t(massAt(c));
    return now + m <= INT32_MAX;
}

} // namespace push_internal
} // namespace vdbclay
