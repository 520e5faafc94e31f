// The compress push (PushMode::Compress; Push.cc, step 3): a source's clay spread over the
// contiguous clay ahead of its tool instead of put into one free voxel.
//
// When the march's target is clay (full: m * kCompressFullDen >= kCompressFullNum * Tc, in the grid
// before the push), the march goes on along the normal, collecting the contiguous full voxels (free,
// not obstacles, outside every tool) up to the tool's depth: the chain. The depth depends on whether
// the tool covers the clay it entered: no source of it has a full, free face neighbour beside or
// behind it (relative to the tool's mean normal over its sources). A tool that does not cover (a
// small tool poking a large block, a plate narrower than the clay) goes as deep as its contact is
// wide, round(sqrt(voxels it entered this push)) in 3D, their number in 2D, at least 1; the source's
// clay m is shared over its own chain, m / k each, the remainder +1 to the voxels nearest the tool: a
// local rim, the far faces untouched. A tool that covers the clay (a plate wider than it) compresses
// every column under it all the way (up to kMaxSearchLimit voxels: the plastic zone of a flat punch
// spans the whole body once the contact covers its width), and its sources' clay is pooled and shared
// evenly over the union of their chains (sharePool()), so a body whose columns differ in length still
// gets a uniform source: the global layer then moves it out evenly (straight sides, docs/ACCURACY.md
// section 6); spread per column, short columns would get more per cell and the clay would leave next
// to the plate. The full test reads the grid before this push, so the plan does not depend on the
// order of the sources. A pool is a value per voxel in dense arrays per 8^3 leaf (LeafArrays.h): the
// chains write it leaf by leaf, and sharePool() visits its leaves in parallel, in a Tree543's order. A source
// whose target is not full, or was found by the flood, is pushed as by the surface push.
#pragma once

#include "push/Pusher.h"

#include "vdbclay/Fwd.h"

#include <cstdint>
#include <vector>

namespace vdbclay {
namespace push_internal {

/// A voxel counts as clay the compress push spreads over when m * 10 >= 3 * Tc. Measured against
/// 0.9 Tc (docs/TRANSPORT.md): at 0.9 the partly filled rim under a plate is surface-pushed into
/// the layer below every frame and piles up there (squeezed cylinder: top / mid radius 1.107 against
/// 1.058 at 0.3, IoU 0.924 against 0.940); clay below 0.3 Tc is a thin film, pushed to the surface.
constexpr int kCompressFullNum = 3, kCompressFullDen = 10;

/// Whether clay of mass @a m counts as full at threshold @a threshold (Tc).
inline bool isFull(int32_t m, int32_t threshold)
{
    return int64_t(m) * kCompressFullDen >= int64_t(threshold) * kCompressFullNum;
}

/// For each tool, whether it covers the clay it entered: no source of it has a face neighbour beside
/// or behind it (direction d with d . N <= 1/2, N the mean of the tool's unit normals over its
/// sources: the way it pushes) that is full, outside every tool and not an obstacle. The mean, not
/// each source's own normal: at a plate's edge the normal tilts outward, and the clay beside the edge
/// would count as ahead. Reads the grid before the push.
std::vector<char> covering(const Pusher& pusher, const std::vector<Source>& sources, int32_t threshold);

/// The chain of @a s, whose target @a found the march found, into @a chain: the contiguous full
/// voxels along the same normal starting at the target, at most @a depth of them, inside the pusher's
/// chain region, with room for their shares given the clay planned so far as @a r sees it (empty if
/// the target is not full or was found by the flood).
void fullChain(Pusher::Reader& r, const Source& s, const Found& found, int depth, int32_t threshold,
               std::vector<Coord>& chain);

/// A covering tool's zone: each cell's value its place in the nearest chain + 1 (0: not in the zone).
using Pool = LeafArrays<int32_t>;

/// A covering tool's pooled clay @a mass shared evenly over its zone @a pool, mass / cells each, the
/// remainder +1 to the cells nearest the tool (smallest place, then a Tree543's order: the pool's
/// leaves are put in that order). On return each value is the cell's share (0 for a cell of the zone
/// that gets none). @a earlier: the pools already shared (their shares count toward a cell's value
/// too). The leaves are shared in parallel on @a threads (as the automaton's; the same shares on any
/// count).
/// @throw Error if a share does not fit a cell (int32); the pool's values are undefined then, and
/// nothing else is written.
void sharePool(Pool& pool, int64_t mass, const Pusher& pusher, const std::vector<const Pool*>& earlier,
               int threads);

} // namespace push_internal
} // namespace vdbclay
