// The global transport's domain (Transport.cc, steps 1 and 2): the over cells that seed it, the
// flood through the full clay that finds its unknown cells and their Dirichlet neighbours, the cell
// index, and the connected parts with no room.
//
// Cells. Numbered in the order the flood reaches them (the unknowns), then the Dirichlet cells in the
// order link() makes them; the active set's rounds append more. Each cell's 6 faces (kDir order) hold
// its neighbour cell or -1: a wall (an obstacle, full clay beyond the reach, a face the dimensions
// leave out). kDir pairs opposite directions (d ^ 1), so a link is made from both sides at once.
//
// The flood. Seeds on the clay's boundary (a face on an obstacle, a tool or room) start it; a seed
// inside the full clay (down a compress push's chain) is reached through it at its depth, and one the
// reach does not get to starts a flood of its own afterwards, with a margin around it. The flood's
// parts (each seed starts one; two meet when a cell finds a face neighbour already in the domain)
// are merged by union-find as it goes, so the common case (every part touches room) needs no second
// pass over the domain.
//
// The cell index maps a coordinate to its cell: a CellIndex (CellIndex.h: a slot per 8^3 brick, a
// table per brick with cells) over the box the flood can reach (the seeds' bounds grown by the
// reach + 2, when the reach is bounded and the box has at most kCellIndexSlotsMax bricks), an Int32 tree
// beyond it (the whole body's reach; the active set's rounds may add cells with room past the box).
// Only a map: results do not depend on it. The flood's lookups (the index, the masses, the
// obstacles) are inline: no calls through the shared library's symbol table.
//
// Ordered: the same cells, numbers and links on any thread count. When its queue holds one whole
// layer of the flood (one distance) of at least SolverTuning::floodBatchMin cells, the flood takes
// that layer together, else one cell at a time: the layer's faces are probed in parallel over fixed
// chunks (Chunks.h),
// reading the index, the masses and the obstacles only, and what they found is then added serially
// in the order the one-by-one flood finds it (cell, then face), so the cells' numbers are the serial
// flood's. OpenVDB stays in Domain.cc.
#pragma once

#include "transport/CellCoord.h"
#include "transport/CellIndex.h"

#include "vdbclay/Transport.h"

#include <cstddef>
#include <cstdint>
#include <memory>
#include <vector>

namespace vdbclay {

class Automaton;

namespace transport_internal {

constexpr int kDir[6][3] = {{-1, 0, 0}, {1, 0, 0}, {0, -1, 0}, {0, 1, 0}, {0, 0, -1}, {0, 0, 1}};

/// A cell's part in the problem: an unknown (p solved), a Dirichlet cell with room (p = 0), or a
/// cell of a walled-in part with no room (left out of the solve).
enum Kind : uint8_t { kUnknown = 0, kDirichlet = 1, kFrozen = 2 };

/// The flood's margin around an over cell the contact's reach missed (doubled with the reach when a
/// part has no room).
constexpr int64_t kInnerMargin = 2;

/// The domain's cells, one entry per cell in each array.
struct Cells {
    std::vector<CellCoord> at;
    std::vector<int64_t> m0;    ///< the cell's mass when the call began
    std::vector<uint8_t> kind;  ///< Kind
    std::vector<uint8_t> hasNb; ///< link() has looked at every face of it
    std::vector<int32_t> nb;    ///< 6 per cell: the neighbour cell, or -1 (a wall)
    size_t size() const { return at.size(); }
};

/// The domain's arrays, kept in a workspace from one call to the next (cleared, never read before
/// written: a call's result does not depend on them).
struct DomainArrays {
    Cells cells;
    std::vector<int64_t> dist; ///< the flood's steps to each unknown cell
    std::vector<uint8_t> face; ///< the flood's finding at each face of its cells (FaceFound), 6 per cell
    std::vector<int32_t> comp, compParent; ///< the flood's parts: each unknown cell's, union-find
    std::vector<uint8_t> compRoom;         ///< a part touches a Dirichlet cell
    std::vector<int32_t> innerSeeds;       ///< seeds inside the full clay (indices into the seeds)
    std::vector<uint8_t> seedOnBoundary;   ///< per seed: a face on an obstacle or room
    std::vector<int32_t> openCells;        ///< the unknown cells the flood left a face to link
    std::vector<size_t> counts;            ///< scratch of selectIndices
    std::vector<uint8_t> seen;             ///< freezeSingular()'s search
    /// The layered flood's finds per chunk of a batch (Domain::build): new full cells as (cell, face,
    /// mass) in cell-then-face order, and pairs of linked cells whose parts may differ.
    std::vector<std::vector<int32_t>> finds, meets;
    std::vector<int32_t> part;
    CellIndexArrays index; ///< the cell index over the flood's box
};

class Domain {
public:
    /// The domain of @a automaton's clay, its arrays in @a arrays (cleared by build()).
    /// @a reachFromContact, @a floodBatchMin: SolverTuning's. @a serial: the flood's batches on the
    /// calling thread alone.
    Domain(const Automaton& automaton, DomainArrays& arrays, bool reachFromContact, uint64_t floodBatchMin,
           bool serial);
    ~Domain();
    Domain(const Domain&) = delete;
    Domain& operator=(const Domain&) = delete;

    int32_t threshold() const { return mTc; }
    int dirs() const { return mDirs; } ///< faces per cell: 6, or 4 in 2D
    Cells& cells() { return mC; }
    const Cells& cells() const { return mC; }

    /// Appends the over cells (m > Tc, not obstacles) to @a seeds, in tree order: every cell of the
    /// grid when @a region is empty, else those in @a region (the leaves that meet it, in x, y, z order
    /// of their origins). Returns their overload (the sum of m - Tc).
    int64_t seeds(const Box& region, std::vector<CellCoord>& seeds) const;

    /// The overload @a excess of @a seeds fits where it is: every seed has room within two face
    /// steps, and the distinct cells with room within two steps of the seeds hold all of it
    /// (compressible clay, a push beside free space). The automaton then settles it in a few local
    /// steps, and a solve would cost more than it saves (docs/TRANSPORT.md: the compressible press,
    /// the stroke at 0.95 Tc). Stops at the first seed with no room near it (saturated clay).
    bool fitsNearby(const std::vector<CellCoord>& seeds, int64_t excess) const;

    /// Builds the domain of @a seeds: the flood through full clay at most @a reach steps (0:
    /// unbounded) from the contact, @a margin around the inner seeds it misses. @a cut: a full
    /// non-obstacle neighbour was left out (by the reach). Returns false if some connected part may
    /// have no room (then freezeSingular() must look); true if every part has a Dirichlet face.
    bool build(const std::vector<CellCoord>& seeds, int64_t reach, int64_t margin, bool& cut);

    /// Finds the connected parts of the unknowns with no Dirichlet face. @a grow: one was cut by the
    /// reach and @a cut is set (rebuild with a larger one); otherwise they are walled in: frozen, and
    /// reported in @a rep (noRoom, massNoRoom).
    void freezeSingular(bool cut, bool& grow, GlobalTransportReport& rep);

    /// Links cell @a i to its face neighbours, creating Dirichlet cells for neighbours with room.
    /// Returns true if a full non-obstacle neighbour is not a cell (cut by the reach). @a face: what
    /// the flood found at the cell's faces, or null to look them up: a face the flood linked, or
    /// found an obstacle at, is done; one to room gets its Dirichlet cell (made by an earlier cell's
    /// link, or now); one to full clay beyond the reach is linked if a later flood reached that cell,
    /// else cut. The same links, Dirichlet cells (in the same order) and cut either way.
    bool link(int32_t i, const uint8_t* face = nullptr);

private:
    struct Grids; ///< the automaton's grids' accessors and the index's tree (Domain.cc)

    inline bool isObstacle(const CellCoord& c) const;
    inline int32_t massAt(const CellCoord& c) const;
    int32_t indexOf(const CellCoord& c) const
    {
        return indexOf(c, [this](const CellCoord& b) { return indexBeyond(b); });
    }
    /// indexOf() with @a beyond (a parallel chunk's own lookup) for the cells beyond the box.
    template <typename Beyond> int32_t indexOf(const CellCoord& c, const Beyond& beyond) const
    {
        bool inside;
        const int32_t i = mIndex.get(c, inside);
        return inside ? i : beyond(c);
    }
    void setIndex(const CellCoord& c, int32_t i)
    {
        if (!mIndex.set(c, i)) setIndexBeyond(c, i);
    }
    /// The cell index beyond the box (the tree).
    int32_t indexBeyond(const CellCoord& c) const;
    void setIndexBeyond(const CellCoord& c, int32_t i);
    /// Sets up the index for a flood of @a reach steps (0: unbounded) from @a seeds.
    void resetIndex(const std::vector<CellCoord>& seeds, int64_t reach);
    inline int32_t addCell(const CellCoord& c, uint8_t kind);
    /// addCell() of a cell whose mass @a m is known.
    inline int32_t addCell(const CellCoord& c, uint8_t kind, int32_t m);
    /// What lies beyond a face at @a q that is not a cell of the domain (FaceFound): an obstacle (a
    /// wall), room (m < Tc), or full clay (its mass in @a m).
    inline uint8_t faceAt(const CellCoord& q, int32_t& m) const;
    /// The flood's cells [@a head, @a end) (all of them in the domain) looked at together, as the
    /// serial flood would one by one: their faces probed in parallel over fixed chunks, then what
    /// they found added in cell-then-face order (build()). @a find: the union-find's root.
    template <typename Find> void floodBatch(size_t head, size_t end, int64_t reach, const Find& find);
    /// Links cell @a i's face @a d to cell @a j, and back: a Dirichlet cell then knows its unknown
    /// neighbours, and its inflow is gathered in parallel.
    void linkPair(int32_t i, int d, int32_t j)
    {
        mC.nb[size_t(i) * 6 + size_t(d)] = j;
        mC.nb[size_t(j) * 6 + size_t(d ^ 1)] = i;
    }

    int32_t mTc;
    int mDirs;
    bool mFromContact;
    uint64_t mFloodBatchMin;
    bool mSerial;
    DomainArrays& mB;
    Cells& mC;
    std::unique_ptr<Grids> mGrids;
    CellIndex mIndex; ///< over the flood's box, in mB.index
};

} // namespace transport_internal
} // namespace vdbclay
