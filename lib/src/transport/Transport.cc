// Global transport: the overload moved through the full clay to where there is room, in integers.
//
// Why. In clay at m0 = Tc the paper's automaton moves displaced clay by a random walk through
// saturated cells: steps grow as N^2 and work as N^5-N^6, and the clay exits where the walk
// happens to reach open space. A pressure projection solved as an obstacle problem moves it in one
// pass (docs/TRANSPORT.md, and the prototype study it follows).
//
// 1. Domain. Seeds: every non-obstacle cell over Tc, in tree order. A breadth-first flood through
//    face neighbours that are full (m >= Tc) and not obstacles, at most `reach` steps from the
//    contact (the seeds with a face on an obstacle, a tool or room; the plastic zone: a small tool
//    moves clay near itself, a plate covering the body moves the whole body), gives the unknown
//    cells D. Seeds inside the full clay (a compress push's chains) join at their depth; one beyond
//    the reach starts its own flood with a margin of 2 (reachFromContact; round 4 flooded `reach`
//    around every seed: the 128-wide compress stroke's domain 2.5x larger). D's face neighbours
//    with room (m < Tc, not an obstacle) are Dirichlet cells B (p = 0). Obstacles, and full cells
//    beyond the reach, are walls: their faces are left out of the Laplacian (no flux).
// 2. Singular parts. A connected part of D with no face on B has no room: its Poisson problem is
//    singular (the flood finds the parts and which touch B; only then are they searched). If it
//    was cut by the reach, the reach doubles and the domain is rebuilt (up to the whole body);
//    otherwise it is walled in: its clay stays (NoRoom), it leaves the solve.
// 3. Active set. Solve L p = m - Tc on D (L: for each non-wall face, p_i - p_j; p_j = 0 on B) by
//    preconditioned conjugate gradients, warm-started from the previous round, to roundTolerance
//    while the set changes, then to tolerance (the early rounds only locate the rim): MIC(0) for small
//    solves, an aggregation multigrid V-cycle (Multigrid.h) from multigridMin unknowns (whose
//    iterations stay nearly flat as N grows; its hierarchy is built in the first round and rebound
//    to the later rounds' matrices, which change only at the rim). A B cell whose inflow (the sum of p over
//    its D faces) exceeds its room joins D (its right-hand side is then negative: it absorbs its room), and
//    what it cannot hold cascades to its neighbours with room, which join too if it overflows them; a joined
//    cell with p < 0 leaves again. Repeat until nothing changes (or maxRounds): the cells of D end exactly
//    full.
// 4. Routing, exact. Cells of D in order of decreasing p (ties: coordinate order) send their
//    current integer excess (their own plus what higher cells sent them) to their lower-p non-wall
//    face neighbours, pro rata of the drop p_i - p_j, largest remainder first. So every D cell with
//    excess ends at exactly Tc, B cells receive, mass is exact by construction, walls are never
//    crossed. Cells with no lower neighbour (only from solver error) keep their excess for the
//    automaton's cleanup.
// 5. The changed cells' new masses are written through Automaton::setMasses() (their bounding box is
//    woken as by an edit of it; only the cells are read).
//
// Determinism. The flood, the cell numbering and the routing's integer split are serial and ordered
// (the routing's sort, a radix sort or a parallel sort for many cells, is on a strict total order:
// one result; its gathering of each cell's lower neighbours is parallel and exact). Every array lives
// in a GlobalTransportWorkspace when the caller keeps one (the Sculptor does: no fresh pages each
// frame); none is read before written. The solver's set-up and vector operations run over fixed
// chunks of rows; dot products add per-chunk partial sums in chunk order. Every floating-point
// operation is therefore the same on any thread count, and so is the potential, the routing and the
// result.
//
// Cost. The flood and the solve touch the full cells within the reach and their faces, never the
// bounding box: work follows the clay body (or the plastic zone), times the CG iterations.

#include "vdbclay/Transport.h"
#include "vdbclay/Automaton.h"

#include "transport/Chunks.h"
#include "transport/Multigrid.h"
#include "transport/CellIndex.h"

#include <openvdb/openvdb.h>
#include <openvdb/tree/ValueAccessor.h>

#include <tbb/blocked_range.h>
#include <tbb/parallel_for.h>
#include <tbb/parallel_sort.h>
#include <tbb/task_arena.h>

#include <algorithm>
#include <chrono>
#include <climits>
#include <cstring>
#include <cmath>
#include <memory>
#include <numeric>

namespace vdbclay {

const char* transportName(Transport transport)
{
    return transport == Transport::Global ? "global" : "local";
}

Transport parseTransport(const std::string& name)
{
    if (name == "local") return Transport::Local;
    if (name == "global") return Transport::Global;
    throw Error("unknown transport \"" + name + "\" (expected one of: local, global)");
}

namespace {

using openvdb::Coord;
using namespace transport_internal;

constexpr int kDir[6][3] = {{-1, 0, 0}, {1, 0, 0}, {0, -1, 0}, {0, 1, 0}, {0, 0, -1}, {0, 0, 1}};

enum Kind : uint8_t { kUnknown = 0, kDirichlet = 1, kFrozen = 2 };

/// The active set's rounds solve to the tolerance once a round changes at most 1/kTightChange of the rows.
constexpr size_t kTightChange = 1000;

/// What the flood found at an unknown cell's face (Solver::link): linked or a wall (an obstacle,
/// or a face the dimensions leave out), a cell with room, full clay beyond the reach.
enum FaceFound : uint8_t { kFaceDone = 0, kFaceRoom = 1, kFaceFull = 2 };

/// reachFromContact: the flood's margin around an over cell the contact's reach missed (doubled with
/// the reach when a part has no room).
constexpr int64_t kInnerMargin = 2;

/// The routing sorts up to this many cells by a serial radix sort, more by a parallel comparison sort
/// when threaded (the same sequence either way).
constexpr size_t kRadixMax = size_t(1) << 20;

/// The layer's arrays, kept from one call to the next by a GlobalTransportWorkspace (cleared, never
/// read before written: a call's result does not depend on them).
struct Buffers {
    std::vector<Coord> cells;
    std::vector<RowCoord> coord;
    std::vector<int64_t> m0, dist, cur;
    std::vector<uint8_t> kind, hasNb, seen, compRoom;
    std::vector<uint8_t> face; ///< the flood's finding at each face of its cells (FaceFound), 6 per cell
    std::vector<int32_t> nb, row, rowCell, oldRow, joined, left, solveNb, mgRow, order, part;
    std::vector<int32_t> comp, compParent; ///< the flood's parts: each unknown cell's, union-find
    std::vector<int32_t> innerSeeds;       ///< seeds inside the full clay (indices into the seeds)
    std::vector<double> p, inflow, solveDiag, solveB, inv;
    std::vector<double> work[6];
    std::vector<size_t> counts;
    std::vector<int32_t> byCoord;       ///< every cell in coordinate order (MIC(0)'s rows)
    std::vector<int32_t> changed, outJ; ///< the routing's changed cells; its gathered lower neighbours
    std::vector<double> outW, outSum;
    std::vector<uint8_t> outN;
    std::vector<int32_t> denseIndex; ///< the cell index over the flood's box (Solver::indexOf)
    /// The routing's radix sort (Solver::sortByPotential): keys, and the pass's copies and counts.
    std::vector<uint64_t> sortKey, sortKeyTmp;
    std::vector<int32_t> sortTmp, sortPart;
    std::vector<size_t> sortCount;
    std::vector<Automaton::CellMass> write; ///< the routing's changed cells and their masses
    std::vector<int32_t> micNb6;            ///< MIC(0)'s rows at a fixed width (row n: none)
    std::unique_ptr<Multigrid> mg;
};

class Solver {
public:
    Solver(Automaton& a, const GlobalTransportOptions& o, Buffers& b, bool keep)
        : mA(a), mOpt(o), mTc(a.options().rule.threshold), mDirs(a.options().dimensions == 2 ? 4 : 6),
          mMass(a.mass()->constTree()), mObs(a.obstacles() ? &a.obstacles()->constTree() : nullptr),
          mSerial(o.threads == 1), mMassAcc(mMass), mB(b), mKeep(keep), mCells(b.cells), mM0(b.m0),
          mKind(b.kind), mHasNb(b.hasNb), mNb(b.nb), mDist(b.dist), mP(b.p), mRow(b.row), mRowCell(b.rowCell),
          mOldRow(b.oldRow), mJoined(b.joined), mLeft(b.left), mCoord(b.coord), mInflow(b.inflow),
          mCounts(b.counts), mSolveNb(b.solveNb), mSolveDiag(b.solveDiag), mSolveB(b.solveB), mInv(b.inv),
          mWork(b.work), mMgRow(b.mgRow)
    {
        if (mObs) mObsAcc = std::make_unique<openvdb::tree::ValueAccessor<const openvdb::MaskTree>>(*mObs);
    }

    GlobalTransportReport run()
    {
        GlobalTransportReport rep;
        // Nothing over Tc (the automaton keeps the sum): nothing to do, at no cost (a push that
        // found room where it was, a compressible clay).
        if (mA.residualOverload() == 0) return rep;
        std::vector<Coord> seeds;
        auto seed = [&](const Coord& c, int32_t m) {
            if (m > mTc && !isObstacle(c)) {
                seeds.push_back(c);
                rep.overloadBefore += int64_t(m) - mTc;
            }
        };
        if (mOpt.seedRegion.empty()) {
            for (auto it = mMass.cbeginValueOn(); it; ++it)
                seed(it.getCoord(), *it);
        } else { // the leaves that meet the region, in x, y, z order of their origins
            const Box& r = mOpt.seedRegion;
            openvdb::tree::ValueAccessor<const openvdb::Int32Tree> acc(mMass);
            const int32_t lo[3] = {r.min[0] & ~7, r.min[1] & ~7, r.min[2] & ~7};
            for (int32_t x = lo[0]; x <= r.max[0]; x += 8)
                for (int32_t y = lo[1]; y <= r.max[1]; y += 8)
                    for (int32_t z = lo[2]; z <= r.max[2]; z += 8) {
                        const auto* leaf = acc.probeConstLeaf(Coord(x, y, z));
                        if (!leaf) continue;
                        for (auto it = leaf->cbeginValueOn(); it; ++it) {
                            const Coord c = it.getCoord();
                            if (c.x() < r.min[0] || c.x() > r.max[0] || c.y() < r.min[1] ||
                                c.y() > r.max[1] || c.z() < r.min[2] || c.z() > r.max[2])
                                continue;
                            seed(c, *it);
                        }
                    }
        }
        rep.overloadAfter = mA.residualOverload();
        if (seeds.empty()) return rep;
        if (fitsNearby(seeds, rep.overloadBefore)) {
            rep.skipped = true;
            return rep;
        }

        int64_t reach = mOpt.reach > 0 ? mOpt.reach : 0;
        int64_t margin = kInnerMargin; // doubles with the reach: a walled-in inner seed grows as fast
        for (;;) {
            bool cut = false;
            const bool allRoom = build(seeds, reach, margin, cut);
            rep.reach = reach;
            bool grow = false;
            if (!allRoom) freezeSingular(cut, grow, rep);
            if (grow) {
                reach = reach * 2 >= int64_t(1) << 40 ? 0 : reach * 2;
                margin = std::min<int64_t>(margin * 2, int64_t(1) << 40);
                continue;
            }
            break;
        }
        activeSet(rep);
        releaseSolver(); // before the routing's own arrays: a lower peak
        route(rep);
        return rep;
    }

private:
    bool isObstacle(const Coord& c) const { return mObsAcc && mObsAcc->isValueOn(c); }
    int32_t massAt(const Coord& c) const { return mMassAcc.getValue(c); }

    /// The overload fits where it is: every over cell has room within two face steps, and the
    /// distinct cells with room within two steps of the over cells hold all of it (compressible
    /// clay, a push beside free space). The automaton then settles it in a few local steps, and a
    /// solve would cost more than it saves (docs/TRANSPORT.md: the compressible press, the stroke
    /// at 0.95 Tc). Stops at the first over cell with no room near it (saturated clay).
    bool fitsNearby(const std::vector<Coord>& seeds, int64_t excess) const
    {
        std::vector<Coord> near;
        for (int dx = -2; dx <= 2; ++dx)
            for (int dy = -2; dy <= 2; ++dy)
                for (int dz = mDirs == 6 ? -2 : 0; dz <= (mDirs == 6 ? 2 : 0); ++dz) {
                    const int l1 = std::abs(dx) + std::abs(dy) + std::abs(dz);
                    if (l1 >= 1 && l1 <= 2) near.emplace_back(dx, dy, dz);
                }
        openvdb::tree::ValueAccessor<const openvdb::Int32Tree> acc(mMass);
        std::vector<Coord> room;
        for (const Coord& c : seeds) {
            bool any = false;
            for (const Coord& o : near) {
                const Coord q = c + o;
                if (acc.getValue(q) >= mTc || isObstacle(q)) continue;
                any = true;
                room.push_back(q);
            }
            if (!any) return false;
        }
        std::sort(room.begin(), room.end());
        room.erase(std::unique(room.begin(), room.end()), room.end());
        int64_t total = 0;
        for (const Coord& q : room)
            total += int64_t(mTc) - acc.getValue(q);
        return total >= excess;
    }
    bool inPlane(const Coord& c) const { return mDirs == 6 || c.z() == 0; }

    /// The cell index: a dense array over the box the flood can reach (the seeds' bounds grown by the
    /// reach + 2, when the reach is bounded: round 5, ~10 % of a stroke frame's instructions went to
    /// the tree's lookups), an Int32 tree beyond it (the whole body's reach; the active set's rounds
    /// may add cells with room past the box). Only a map: results do not depend on it.
    int32_t indexOf(const Coord& c) const
    {
        if (mDense) {
            // One unsigned comparison per axis: a negative offset wraps past every dimension.
            const uint64_t x = uint64_t(int64_t(c.x()) - mDenseLo.x()),
                           y = uint64_t(int64_t(c.y()) - mDenseLo.y()),
                           z = uint64_t(int64_t(c.z()) - mDenseLo.z());
            if (x < uint64_t(mDenseDim[0]) && y < uint64_t(mDenseDim[1]) && z < uint64_t(mDenseDim[2]))
                return mB.denseIndex[size_t((x * uint64_t(mDenseDim[1]) + y) * uint64_t(mDenseDim[2]) + z)];
        }
        return mIndexAcc ? mIndexAcc->getValue(c) : -1;
    }
    void setIndex(const Coord& c, int32_t i)
    {
        if (mDense) {
            const int64_t x = int64_t(c.x()) - mDenseLo.x(), y = int64_t(c.y()) - mDenseLo.y(),
                          z = int64_t(c.z()) - mDenseLo.z();
            if (x >= 0 && y >= 0 && z >= 0 && x < mDenseDim[0] && y < mDenseDim[1] && z < mDenseDim[2]) {
                mB.denseIndex[size_t((x * mDenseDim[1] + y) * mDenseDim[2] + z)] = i;
                return;
            }
        }
        if (!mIndexAcc) {
            mIndex = std::make_unique<openvdb::Int32Tree>(-1);
            mIndexAcc = std::make_unique<openvdb::tree::ValueAccessor<openvdb::Int32Tree>>(*mIndex);
        }
        mIndexAcc->setValue(c, i);
    }
    /// Sets up the index for a flood of @a reach steps (0: unbounded) from @a seeds.
    void resetIndex(const std::vector<Coord>& seeds, int64_t reach)
    {
        mIndexAcc.reset();
        mIndex.reset();
        mDense = false;
        if (reach <= 0 || seeds.empty() || reach > (int64_t(1) << 20)) return;
        Coord lo = seeds.front(), hi = lo;
        for (const Coord& c : seeds) {
            lo.minComponent(c);
            hi.maxComponent(c);
        }
        const int64_t g = reach + 2;
        int64_t volume = 1;
        for (int a = 0; a < 3; ++a) {
            const int64_t grow = (a == 2 && mDirs == 4) ? 0 : g;
            mDenseDim[a] = int64_t(hi[a]) - lo[a] + 1 + 2 * grow;
            volume *= mDenseDim[a];
            if (volume > kDenseIndexMax) return;
        }
        mDenseLo = Coord(int32_t(int64_t(lo.x()) - g), int32_t(int64_t(lo.y()) - g),
                         int32_t(int64_t(lo.z()) - (mDirs == 4 ? 0 : g)));
        if (int64_t(lo.x()) - g < INT32_MIN || int64_t(lo.y()) - g < INT32_MIN ||
            int64_t(lo.z()) - g < INT32_MIN)
            return;
        mB.denseIndex.assign(size_t(volume), -1);
        mDense = true;
    }
    int32_t addCell(const Coord& c, uint8_t kind) { return addCell(c, kind, massAt(c)); }
    /// addCell() of a cell whose mass @a m is known.
    int32_t addCell(const Coord& c, uint8_t kind, int32_t m)
    {
        const int32_t i = int32_t(mCells.size());
        mCells.push_back(c);
        mM0.push_back(m);
        mKind.push_back(kind);
        mNb.insert(mNb.end(), 6, -1);
        mHasNb.push_back(0);
        setIndex(c, i);
        return i;
    }

    /// What lies beyond a face at @a q that is not a cell of the domain: an obstacle (kFaceDone: a
    /// wall), room (m < Tc), or full clay (its mass in @a m).
    FaceFound faceAt(const Coord& q, int32_t& m) const
    {
        if (isObstacle(q)) return kFaceDone;
        m = massAt(q);
        return m < mTc ? kFaceRoom : kFaceFull;
    }

    /// Links cell @a i's face @a d to cell @a j, and back (kDir pairs opposite directions: d ^ 1): a
    /// Dirichlet cell then knows its unknown neighbours, and its inflow is gathered in parallel.
    void linkPair(int32_t i, int d, int32_t j)
    {
        mNb[size_t(i) * 6 + size_t(d)] = j;
        mNb[size_t(j) * 6 + size_t(d ^ 1)] = i;
    }

    /// Links cell @a i to its face neighbours, creating Dirichlet cells for neighbours with room.
    /// Returns true if a full non-obstacle neighbour is not a cell (cut by the reach). @a face: what the
    /// flood found at the cell's faces (mB.face; round 6: the flood and the links took 19 % of a
    /// compress stroke frame, half of it looking the faces up again), or null to look them up: a face
    /// the flood linked, or found an obstacle at, is done; one to room gets its Dirichlet cell (made by
    /// an earlier cell's link, or now); one to full clay beyond the reach is linked if a later flood
    /// reached that cell, else cut. The same links, Dirichlet cells (in the same order) and cut either way.
    bool link(int32_t i, const uint8_t* face = nullptr)
    {
        bool cut = false;
        const Coord c = mCells[size_t(i)];
        for (int d = 0; d < mDirs; ++d) {
            if (face && face[d] == kFaceDone) continue;
            const Coord q = c.offsetBy(kDir[d][0], kDir[d][1], kDir[d][2]);
            int32_t j = indexOf(q);
            if (j < 0) {
                int32_t m = 0;
                const FaceFound found = face ? FaceFound(face[d]) : faceAt(q, m);
                if (found == kFaceDone) continue;
                if (found == kFaceFull) {
                    cut = true; // beyond the reach: a wall for this solve
                    continue;
                }
                j = addCell(q, kDirichlet);
            }
            linkPair(i, d, j);
        }
        mHasNb[size_t(i)] = 1;
        return cut;
    }

    /// Builds the domain. Returns false if some connected part of it may have no room (then
    /// freezeSingular() must look); true if every part has a Dirichlet face. The parts are found
    /// during the flood (each seed starts one; two meet when a cell finds a face neighbour already
    /// in the domain: union-find), so the common case needs no second pass over the domain.
    bool build(const std::vector<Coord>& seeds, int64_t reach, int64_t margin, bool& cut)
    {
        std::vector<int32_t>& comp = mB.comp;
        std::vector<int32_t>& parent = mB.compParent;
        std::vector<uint8_t>& face = mB.face;
        comp.clear();
        parent.clear();
        face.clear();
        mB.byCoord.clear();
        mByCoordCells = 0;
        auto find = [&](int32_t a) {
            while (parent[size_t(a)] != a) {
                parent[size_t(a)] = parent[size_t(parent[size_t(a)])];
                a = parent[size_t(a)];
            }
            return a;
        };
        mCells.clear();
        mM0.clear();
        mKind.clear();
        mNb.clear();
        mHasNb.clear();
        mDist.clear();
        resetIndex(seeds, reach);
        // The queue is the cells themselves: the flood appends the unknown cells in the order it
        // reaches them (the Dirichlet cells come after it, in link()), so cells [head, size) are queued.
        size_t head = 0;
        auto start = [&](const Coord& s, int64_t dist) {
            addCell(s, kUnknown);
            mDist.push_back(dist);
            comp.push_back(int32_t(parent.size()));
            parent.push_back(int32_t(parent.size()));
        };
        // The reach counts from the contact: the seeds on the clay's boundary (a face on an obstacle,
        // a tool, or a cell with room) start the flood; a seed inside the full clay (down a compress
        // chain) is reached through it at its depth. One the reach did not get to (a chain deeper, in
        // face steps, than the reach: a diagonal one) starts a flood of its own afterwards, with a
        // margin of @a margin steps around it (it already lies in the plastic zone). So a compress
        // push's chains add next to no reach beyond the contact.
        const bool fromContact = mOpt.reachFromContact;
        const int64_t innerDist = reach > margin ? reach - margin : 0;
        bool innerStarted = !fromContact;
        if (fromContact) {
            std::vector<int32_t>& inner = mB.innerSeeds;
            inner.clear();
            for (size_t si = 0; si < seeds.size(); ++si) {
                const Coord& s = seeds[si];
                if (indexOf(s) >= 0) continue;
                bool boundary = false;
                for (int d = 0; d < mDirs && !boundary; ++d) {
                    const Coord q = s.offsetBy(kDir[d][0], kDir[d][1], kDir[d][2]);
                    boundary = isObstacle(q) || massAt(q) < mTc;
                }
                if (boundary)
                    start(s, 0);
                else
                    inner.push_back(int32_t(si));
            }
        } else {
            for (const Coord& s : seeds)
                if (indexOf(s) < 0) start(s, 0);
        }
        cut = false;
        for (;;) {
            if (head == mCells.size()) { // the seeds the contact's flood did not reach start their own
                if (innerStarted) break;
                innerStarted = true;
                for (const int32_t si : mB.innerSeeds)
                    if (indexOf(seeds[size_t(si)]) < 0) start(seeds[size_t(si)], innerDist);
                continue;
            }
            const int32_t i = int32_t(head++);
            const Coord c = mCells[size_t(i)];
            const int64_t di = mDist[size_t(i)];
            face.resize(size_t(i + 1) * 6, kFaceDone); // cells are taken in index order
            for (int d = 0; d < mDirs; ++d) {
                const Coord q = c.offsetBy(kDir[d][0], kDir[d][1], kDir[d][2]);
                const int32_t k = indexOf(q);
                if (k >= 0) { // every face between two domain cells is seen here, from one side
                    linkPair(i, d, k);
                    if (comp[size_t(i)] == comp[size_t(k)]) continue; // one label: one part already
                    const int32_t a = find(comp[size_t(i)]), b = find(comp[size_t(k)]);
                    if (a != b) parent[size_t(std::max(a, b))] = std::min(a, b);
                    continue;
                }
                int32_t m = 0;
                const FaceFound found = faceAt(q, m);
                if (found == kFaceDone) continue;
                // Room, or full clay beyond the reach: link() makes the Dirichlet cell or marks the cut
                // (unless a later flood gets there).
                if (found == kFaceRoom || (reach > 0 && di >= reach)) {
                    face[size_t(i) * 6 + size_t(d)] = uint8_t(found);
                    continue;
                }
                linkPair(i, d, addCell(q, kUnknown, m));
                mDist.push_back(di + 1);
                comp.push_back(comp[size_t(i)]);
            }
        }
        // Link every unknown cell (Dirichlet cells appear here, after the unknowns), and mark
        // the parts that touch a Dirichlet cell.
        std::vector<uint8_t>& room = mB.compRoom;
        room.assign(parent.size(), 0);
        const size_t unknowns = mCells.size();
        for (size_t i = 0; i < unknowns; ++i) {
            cut |= link(int32_t(i), &face[i * 6]);
            for (int d = 0; d < mDirs; ++d) {
                const int32_t j = mNb[i * 6 + size_t(d)];
                if (j >= 0 && mKind[size_t(j)] == kDirichlet) {
                    room[size_t(find(comp[i]))] = 1;
                    break;
                }
            }
        }
        for (size_t r = 0; r < parent.size(); ++r)
            if (parent[r] == int32_t(r) && !room[r]) return false;
        return true;
    }

    /// Finds connected parts of the unknowns with no Dirichlet face. @a grow: one was cut by the
    /// reach (rebuild with a larger one); otherwise they are walled in: frozen, reported.
    void freezeSingular(bool cut, bool& grow, GlobalTransportReport& rep)
    {
        grow = false;
        std::vector<uint8_t>& seen = mB.seen;
        seen.assign(mCells.size(), 0);
        std::vector<int32_t>& part = mB.part;
        for (size_t s = 0; s < mCells.size(); ++s) {
            if (mKind[s] != kUnknown || seen[s]) continue;
            part.clear();
            part.push_back(int32_t(s));
            seen[s] = 1;
            bool room = false, partCut = false;
            for (size_t k = 0; k < part.size(); ++k) {
                const size_t i = size_t(part[k]);
                const Coord c = mCells[i];
                for (int d = 0; d < mDirs; ++d) {
                    const int32_t j = mNb[i * 6 + size_t(d)];
                    if (j < 0) {
                        const Coord q = c.offsetBy(kDir[d][0], kDir[d][1], kDir[d][2]);
                        if (!isObstacle(q)) partCut = true; // a full cell beyond the reach
                        continue;
                    }
                    if (mKind[size_t(j)] == kDirichlet)
                        room = true;
                    else if (mKind[size_t(j)] == kUnknown && !seen[size_t(j)]) {
                        seen[size_t(j)] = 1;
                        part.push_back(j);
                    }
                }
            }
            if (room) continue;
            if (partCut && cut) {
                grow = true;
                return;
            }
            rep.noRoom = true;
            for (int32_t i : part) {
                mKind[size_t(i)] = kFrozen;
                rep.massNoRoom += std::max<int64_t>(0, mM0[size_t(i)] - mTc);
            }
        }
    }

    /// Conjugate gradients, MIC(0)-preconditioned, on the unknown cells, warm-started from mP.
    /// The rows (unknown cells), the matrix, the right-hand side and the preconditioner.
    void setUpSolve(GlobalTransportReport& rep)
    {
        // Rows: the unknown cells in coordinate order (x, y, z), the natural order for the
        // incomplete Cholesky factor.
        // (The multigrid needs no particular order: its rows stay in cell order, the flood's.)
        mRow.resize(mCells.size());
        forChunks(mCells.size(), mSerial,
                  [&](size_t lo, size_t hi) { std::fill(&mRow[lo], &mRow[0] + hi, -1); });
        selectIndices(mCells.size(), mSerial, mCounts, mRowCell,
                      [&](size_t i) { return mKind[i] == kUnknown; });
        const bool multigrid = mRowCell.size() >= mOpt.multigridMin;
        if (!multigrid) {
            // Every cell in coordinate order, kept across the rounds: only the cells added since
            // the last round are sorted and merged in (the rounds add a thin rim); the rows are the
            // unknown cells of that list (the same order a sort of the rows would give).
            std::vector<int32_t>& byCoord = mB.byCoord;
            const auto before = [&](int32_t a, int32_t b) { return mCells[size_t(a)] < mCells[size_t(b)]; };
            const size_t old = byCoord.size();
            for (size_t i = mByCoordCells; i < mCells.size(); ++i)
                byCoord.push_back(int32_t(i));
            sortByCoord(byCoord, old);
            std::inplace_merge(byCoord.begin(), byCoord.begin() + std::ptrdiff_t(old), byCoord.end(), before);
            mByCoordCells = mCells.size();
            mRowCell.clear();
            for (const int32_t i : byCoord)
                if (mKind[size_t(i)] == kUnknown) mRowCell.push_back(i);
        }
        forChunks(mRowCell.size(), mSerial, [&](size_t lo, size_t hi) {
            for (size_t k = lo; k < hi; ++k)
                mRow[size_t(mRowCell[k])] = int32_t(k);
        });
        const size_t n = mRowCell.size();
        mSolveMg = nullptr;
        if (n == 0) return;
        std::vector<int32_t>& nb = mSolveNb;
        std::vector<double>& diag = mSolveDiag;
        std::vector<double>& b = mSolveB;
        // Every entry written: a neighbour's row is mRow's (-1 for a Dirichlet or frozen cell, and
        // mNb holds -1 past mDirs); the diagonal counts the faces to non-frozen cells.
        nb.resize(n * 6);
        diag.resize(n);
        b.resize(n);
        forChunks(n, mSerial, [&](size_t lo, size_t hi) {
            for (size_t k = lo; k < hi; ++k) {
                const size_t i = size_t(mRowCell[k]);
                int faces = 0;
                for (int d = 0; d < 6; ++d) {
                    const int32_t j = mNb[i * 6 + size_t(d)];
                    int32_t row = -1;
                    if (j >= 0) {
                        faces += mKind[size_t(j)] != kFrozen ? 1 : 0;
                        row = mRow[size_t(j)];
                    }
                    nb[k * 6 + size_t(d)] = row;
                }
                diag[k] = double(faces);
                b[k] = double(mM0[i] - mTc);
            }
        });
        // Modified incomplete Cholesky, MIC(0) (Bridson's tuning 0.97, safety 0.25): A ~ (D + L)
        // D^-1 (D + L)^T with L the strictly lower part of A (all -1) and D = the pivots below.
        // Eliminating row j leaves fill-in 1/d_j between each pair of its later neighbours; MIC
        // adds the dropped fill-in of row k to its pivot. Serial (triangular solves): the same on
        // any thread count.
        if (multigrid) {
            // The hierarchy of the frame's first round serves the later rounds (rebind) while they
            // keep most of its rows; rows are in cell order, and cells are only ever appended.
            std::vector<int32_t>& oldRow = mOldRow;
            std::vector<RowCoord>& coord = mCoord;
            oldRow.resize(n);
            coord.resize(n);
            if (!mB.mg) mB.mg = std::make_unique<Multigrid>();
            Multigrid& mg = *mB.mg;
            const bool reusable = mMgBuilt && mg.levels() >= 2;
            std::vector<double> partial;
            const double kept = chunkedSum(n, mSerial, partial, [&](size_t k) {
                const size_t i = size_t(mRowCell[k]);
                coord[k] = RowCoord{mCells[i].x(), mCells[i].y(), mCells[i].z()};
                oldRow[k] = reusable && i < mMgRow.size() ? mMgRow[i] : -1;
                return oldRow[k] >= 0 ? 1.0 : 0.0;
            });
            if (reusable && kept >= double(n - n / 20) && kept > 0) {
                mg.rebind(n, nb, diag, coord, oldRow, mSerial);
                ++rep.multigridReused;
            } else {
                mg.build(n, nb, diag, coord, mSerial);
                mMgBuilt = true;
            }
            mMgRow.swap(mRow); // mRow is rebuilt by the next set-up
            mSolveMg = &mg;
        }
        if (!multigrid) {
            // The rows at a fixed width, a missing face pointing at row n (a sentinel), for A v and
            // the triangular solves. Rows are in coordinate order and kDir lists -x, +x, -y, +y, -z,
            // +z: a row's even faces are its lower neighbours, its odd faces its upper ones.
            std::vector<int32_t>& nb6 = mB.micNb6;
            nb6.resize(n * 6);
            for (size_t e = 0; e < n * 6; ++e)
                nb6[e] = nb[e] >= 0 ? nb[e] : int32_t(n);
            std::vector<double> piv(n);
            std::vector<double>& inv = mInv;
            inv.assign(n, 0.0);
            // In coordinate order a row's even faces (-x, -y, -z) are its lower rows and its odd
            // faces its upper ones: the factor reads only those (the same terms in the same order).
            std::vector<uint8_t> upper(n);
            for (size_t k = 0; k < n; ++k)
                upper[k] = uint8_t((nb[k * 6 + 1] >= 0) + (nb[k * 6 + 3] >= 0) + (nb[k * 6 + 5] >= 0));
            constexpr double tau = 0.97, safety = 0.25;
            for (size_t k = 0; k < n; ++k) {
                double e = diag[k];
                for (int d = 0; d < 6; d += 2) {
                    const int32_t j = nb[k * 6 + size_t(d)];
                    if (j < 0) continue;
                    e -= (1.0 + tau * double(upper[size_t(j)] - 1)) / piv[size_t(j)];
                }
                if (e < safety * diag[k]) e = diag[k];
                piv[k] = e;
                inv[k] = 1.0 / e;
            }
        }
    }

    /// Conjugate gradients to @a tolerance on the unknown cells, warm-started from mP. @a same: the
    /// set is that of the last solve (a tighter pass after a loose one): matrix and preconditioner
    /// are kept.
    void solve(GlobalTransportReport& rep, double tolerance, bool same)
    {
        ++rep.solves;
        if (!same) setUpSolve(rep);
        const size_t n = mRowCell.size();
        rep.unknowns = n;
        if (n == 0) return;
        Multigrid* mg = mSolveMg;
        if (mg) ++rep.multigridSolves;
        const bool multigrid = mg != nullptr;
        const std::vector<double>& diag = mSolveDiag;
        const std::vector<double>& b = mSolveB;
        const std::vector<double>& inv = mInv;
        // Work vectors kept across solves (every entry is written before it is read).
        std::vector<double>& x = mWork[0];
        std::vector<double>& r = mWork[1];
        std::vector<double>& z = mWork[2];
        std::vector<double>& p = mWork[3];
        std::vector<double>& q = mWork[4];
        std::vector<double>& w = mWork[5];
        for (std::vector<double>* v : {&x, &r, &z, &p, &q})
            v->resize(n);
        w.resize(multigrid ? 0 : n + 1);
        if (!multigrid) { // the triangular solves' sentinels: adding -0 leaves every sum as it was
            w[n] = -0.0;
            z.resize(n + 1);
            z[n] = -0.0;
        }
        forChunks(n, mSerial, [&](size_t lo, size_t hi) {
            for (size_t k = lo; k < hi; ++k)
                x[k] = mP[size_t(mRowCell[k])];
        });
        const int32_t* micNb6 = mg ? nullptr : mB.micNb6.data();
        auto precondition = [&](const std::vector<double>& in, std::vector<double>& out) {
            if (mg) {
                mg->apply(in, out);
                return;
            }
            // The lower faces (even) in order, then the upper ones (odd), each missing face adding
            // w[n] = out[n] = -0: the additions of a loop over the present faces, zeros' signs too.
            const int32_t* rows = micNb6;
            for (size_t k = 0; k < n; ++k) { // (D + L) w = in
                const int32_t* row = rows + k * 6;
                double s = in[k];
                s += w[size_t(row[0])];
                s += w[size_t(row[2])];
                s += w[size_t(row[4])];
                w[k] = s * inv[k];
            }
            for (size_t k = n; k-- > 0;) { // (D + L)^T out = D w
                const int32_t* row = rows + k * 6;
                double s = 0;
                s += out[size_t(row[1])];
                s += out[size_t(row[3])];
                s += out[size_t(row[5])];
                out[k] = w[k] + s * inv[k];
            }
        };
        // A v reads the fixed-width rows (the multigrid's finest level's, or MIC(0)'s; a missing face:
        // v[n] = +0, and v - (+0) is v, a zero's sign too: the same values as a loop over the faces).
        const int32_t* nb6 = mg ? mg->finestRows().data() : micNb6;
        // Row k of A v (v[n] must be +0).
        auto rowOfA = [&](const std::vector<double>& v, size_t k) {
            const int32_t* row = nb6 + k * 6;
            double s = diag[k] * v[k];
            s -= v[size_t(row[0])];
            s -= v[size_t(row[1])];
            s -= v[size_t(row[2])];
            s -= v[size_t(row[3])];
            s -= v[size_t(row[4])];
            s -= v[size_t(row[5])];
            return s;
        };
        auto apply = [&](std::vector<double>& v, std::vector<double>& out) {
            v.resize(n + 1);
            v[n] = 0.0;
            forChunks(n, mSerial, [&](size_t lo, size_t hi) {
                for (size_t k = lo; k < hi; ++k)
                    out[k] = rowOfA(v, k);
            });
        };
        std::vector<double> partial;
        apply(x, q);
        forChunks(n, mSerial, [&](size_t lo, size_t hi) {
            for (size_t k = lo; k < hi; ++k) {
                r[k] = b[k] - q[k];
            }
        });
        precondition(r, z);
        p = z;
        p.resize(n + 1); // A p below: the sentinel, as in apply()
        p[n] = 0.0;
        const double bnorm =
            std::sqrt(chunkedSum(n, mSerial, partial, [&](size_t k) { return b[k] * b[k]; }));
        const double stop = tolerance * std::max(bnorm, 1e-300);
        double rz = chunkedSum(n, mSerial, partial, [&](size_t k) { return r[k] * z[k]; });
        double rr = chunkedSum(n, mSerial, partial, [&](size_t k) { return r[k] * r[k]; });
        // Each pass below also forms its dot product, per chunk, added in chunk order.
        auto pass = [&](const auto& fn) {
            const size_t chunks = (n + kChunk - 1) / kChunk;
            partial.assign(chunks, 0.0);
            forChunks(n, mSerial, [&](size_t lo, size_t hi) { partial[lo / kChunk] = fn(lo, hi); });
            double sum = 0;
            for (double v : partial)
                sum += v;
            return sum;
        };
        const uint64_t maxIt = 20000;
        for (uint64_t it = 0; it < maxIt; ++it) {
            if (std::sqrt(rr) <= stop) break;
            const double pq = pass([&](size_t lo, size_t hi) { // q = A p, and p . q
                double sum = 0;
                for (size_t k = lo; k < hi; ++k) {
                    const double v = rowOfA(p, k);
                    q[k] = v;
                    sum += p[k] * v;
                }
                return sum;
            });
            if (!(pq > 0)) break;
            const double alpha = rz / pq;
            rr = pass([&](size_t lo, size_t hi) {
                double sum = 0;
                for (size_t k = lo; k < hi; ++k) {
                    x[k] += alpha * p[k];
                    r[k] -= alpha * q[k];
                    sum += r[k] * r[k];
                }
                return sum;
            });
            precondition(r, z);
            const double rzNew = chunkedSum(n, mSerial, partial, [&](size_t k) { return r[k] * z[k]; });
            const double beta = rzNew / rz;
            rz = rzNew;
            forChunks(n, mSerial, [&](size_t lo, size_t hi) {
                for (size_t k = lo; k < hi; ++k)
                    p[k] = z[k] + beta * p[k];
            });
            ++rep.iterations;
        }
        forChunks(n, mSerial, [&](size_t lo, size_t hi) {
            for (size_t k = lo; k < hi; ++k)
                mP[size_t(mRowCell[k])] = x[k];
        });
    }

    void activeSet(GlobalTransportReport& rep)
    {
        mP.assign(mCells.size(), 0.0);
        mMgBuilt = false;
        mMgRow.clear();
        // Rounds solve loosely until the set stops changing, then once to the tolerance (and on
        // if that still changes it): the early rounds only locate the rim.
        const double loose = mOpt.roundTolerance;
        bool tight = !(loose > mOpt.tolerance), same = false;
        for (int round = 0; round < mOpt.maxRounds; ++round) {
            if (round + 1 == mOpt.maxRounds) tight = true;
            solve(rep, tight ? mOpt.tolerance : loose, same);
            same = false;
            // Inflow of each Dirichlet cell: sum of p over its unknown faces.
            const size_t cells = mCells.size();
            // Gathered (the links back) in parallel; added in increasing cell order, as a serial
            // scatter over the unknown cells would: the same value on any thread count.
            std::vector<double>& inflow = mInflow;
            inflow.resize(cells);
            forChunks(cells, mSerial, [&](size_t lo, size_t hi) {
                for (size_t j = lo; j < hi; ++j) {
                    inflow[j] = 0.0;
                    if (mKind[j] != kDirichlet) continue;
                    int32_t from[6];
                    int n = 0;
                    for (int d = 0; d < mDirs; ++d) {
                        const int32_t i = mNb[j * 6 + size_t(d)];
                        if (i >= 0 && mKind[size_t(i)] == kUnknown) from[n++] = i;
                    }
                    for (int k = 1; k < n; ++k) // insertion sort: at most 6
                        for (int m = k; m > 0 && from[m - 1] > from[m]; --m)
                            std::swap(from[m - 1], from[m]);
                    double sum = 0.0;
                    for (int k = 0; k < n; ++k)
                        sum += mP[size_t(from[k])];
                    inflow[j] = sum;
                }
            });
            std::vector<int32_t>& joined = mJoined;
            std::vector<int32_t>& left = mLeft;
            selectIndices(cells, mSerial, mCounts, joined, [&](size_t i) {
                return mKind[i] == kDirichlet && inflow[i] > double(mTc - mM0[i]) + 0.5;
            });
            selectIndices(cells, mSerial, mCounts, left,
                          [&](size_t i) { return mKind[i] == kUnknown && mM0[i] < mTc && mP[i] < 0; });
            if (joined.empty() && left.empty()) {
                if (tight) break;
                tight = same = true;
                continue;
            }
            // A change of at most 1/kTightChange of the rows (the rim settled to a few cells): the next
            // solve, which needs a new set-up anyway, goes straight to the tolerance (round 5: the
            // 128-wide compress stroke's rounds change 41-114 cells of ~21,000, then 2-11, then none;
            // a loose solve of one iteration and its set-up confirmed that before the tight one).
            if (joined.size() + left.size() <= mRowCell.size() / kTightChange) tight = true;
            for (int32_t i : joined)
                mKind[size_t(i)] = kUnknown;
            for (int32_t i : left) {
                mKind[size_t(i)] = kDirichlet;
                mP[size_t(i)] = 0;
            }
            // Cascade: a joined cell passes what it cannot hold (inflow - room) on, split evenly
            // over its neighbours with room; those that then overflow join now rather than one
            // solve later (the set grows shell by shell otherwise). A wrong guess leaves again
            // (p < 0) in the next round. Serial, in join order.
            for (size_t q = 0; q < joined.size(); ++q) {
                const size_t i = size_t(joined[q]);
                const double over = inflow[i] - double(mTc - mM0[i]);
                if (!mHasNb[i]) link(int32_t(i));
                inflow.resize(mCells.size(), 0.0);
                int room = 0;
                for (int d = 0; d < mDirs; ++d) {
                    const int32_t j = mNb[i * 6 + size_t(d)];
                    if (j >= 0 && mKind[size_t(j)] == kDirichlet) ++room;
                }
                if (room == 0 || !(over > 0)) continue;
                for (int d = 0; d < mDirs; ++d) {
                    const int32_t j = mNb[i * 6 + size_t(d)];
                    if (j < 0 || mKind[size_t(j)] != kDirichlet) continue;
                    inflow[size_t(j)] += over / room;
                    if (inflow[size_t(j)] > double(mTc - mM0[size_t(j)]) + 0.5) {
                        mKind[size_t(j)] = kUnknown;
                        joined.push_back(j);
                    }
                }
            }
            // (Every joined cell was linked above, new Dirichlet cells included.)
            mP.resize(mCells.size(), 0.0);
            // A part can lose its last Dirichlet face only by a neighbour joining: if every joined
            // cell touches a Dirichlet cell, each part holding one has room, and so has every part
            // that met one (leaving cells only add room). Else search the whole domain again.
            bool allRoom = true;
            for (int32_t i : joined) {
                bool room = false;
                for (int d = 0; d < mDirs && !room; ++d) {
                    const int32_t j = mNb[size_t(i) * 6 + size_t(d)];
                    room = j >= 0 && mKind[size_t(j)] == kDirichlet;
                }
                if (!room) {
                    allRoom = false;
                    break;
                }
            }
            if (allRoom) continue;
            bool grow = false;
            freezeSingular(false, grow, rep);
        }
    }

    /// Frees what the solves kept across rounds (hierarchy, matrix, work vectors).
    void releaseSolver()
    {
        mMgBuilt = false;
        mSolveMg = nullptr;
        if (mKeep) return;
        mB.mg.reset();
        std::vector<int32_t>().swap(mMgRow);
        std::vector<int32_t>().swap(mSolveNb);
        std::vector<double>().swap(mSolveDiag);
        std::vector<double>().swap(mSolveB);
        std::vector<double>().swap(mInv);
        for (std::vector<double>& v : mWork)
            std::vector<double>().swap(v);
    }

    /// The radix sorts' digits: six of 11 bits (the last one of 9).
    static constexpr int kBits = 11, kDigits = 6;
    static constexpr uint64_t kMask = (uint64_t(1) << kBits) - 1;

    /// A stable LSD radix sort of @a order by mB.sortKey (one key per entry): the digits counted in
    /// one pass (mB.sortCount, kDigits tables of 2^kBits), then a pass per digit, skipped where every
    /// key has the same digit. Leaves the keys sorted in mB.sortKey.
    void radixSort(std::vector<int32_t>& order)
    {
        const size_t n = order.size();
        std::vector<uint64_t>& key = mB.sortKey;
        std::vector<uint64_t>& keyTmp = mB.sortKeyTmp;
        std::vector<int32_t>& tmp = mB.sortTmp;
        keyTmp.resize(n);
        tmp.resize(n);
        std::vector<size_t>& count = mB.sortCount;
        count.assign(size_t(kDigits) << kBits, 0);
        for (size_t u = 0; u < n; ++u)
            for (int d = 0; d < kDigits; ++d)
                ++count[(size_t(d) << kBits) + ((key[u] >> (kBits * d)) & kMask)];
        for (int d = 0; d < kDigits; ++d) {
            size_t* c = &count[size_t(d) << kBits];
            if (c[(key[0] >> (kBits * d)) & kMask] == n) continue; // one digit for all: the order stands
            size_t sum = 0;
            for (size_t b = 0; b <= kMask; ++b) {
                const size_t k = c[b];
                c[b] = sum;
                sum += k;
            }
            for (size_t u = 0; u < n; ++u) {
                const size_t at = c[(key[u] >> (kBits * d)) & kMask]++;
                keyTmp[at] = key[u];
                tmp[at] = order[u];
            }
            key.swap(keyTmp);
            order.swap(tmp);
        }
    }

    /// Sorts the cells @a order[from, end) by coordinate (x, then y, then z: Coord's <). Their
    /// coordinates relative to the smallest, packed into one 64-bit key when they fit (21 bits an
    /// axis), are radix-sorted (the keys are distinct: the same sequence as a comparison sort, in
    /// O(n)); otherwise std::sort. (Round 8: the comparison sort was 2.5 % of a surface stroke's frame.)
    void sortByCoord(std::vector<int32_t>& order, size_t from)
    {
        const size_t n = order.size() - from;
        if (n < 2) return;
        const auto before = [&](int32_t a, int32_t b) { return mCells[size_t(a)] < mCells[size_t(b)]; };
        Coord lo = mCells[size_t(order[from])], hi = lo;
        for (size_t u = from; u < order.size(); ++u) {
            lo.minComponent(mCells[size_t(order[u])]);
            hi.maxComponent(mCells[size_t(order[u])]);
        }
        constexpr int64_t kAxis = int64_t(1) << 21;
        if (n < 64 || int64_t(hi.x()) - lo.x() >= kAxis || int64_t(hi.y()) - lo.y() >= kAxis ||
            int64_t(hi.z()) - lo.z() >= kAxis) {
            std::sort(order.begin() + std::ptrdiff_t(from), order.end(), before);
            return;
        }
        std::vector<int32_t>& part = mB.sortPart;
        part.assign(order.begin() + std::ptrdiff_t(from), order.end());
        std::vector<uint64_t>& key = mB.sortKey;
        key.resize(n);
        for (size_t u = 0; u < n; ++u) {
            const Coord& c = mCells[size_t(part[u])];
            key[u] = uint64_t(int64_t(c.x()) - lo.x()) << 42 | uint64_t(int64_t(c.y()) - lo.y()) << 21 |
                     uint64_t(int64_t(c.z()) - lo.z());
        }
        radixSort(part);
        std::copy(part.begin(), part.end(), order.begin() + std::ptrdiff_t(from));
    }

    /// Sorts @a order (cells) as @a higher does: decreasing p, ties by coordinate. A stable LSD radix
    /// sort on p's bits (11 bits a pass; a pass whose digit is the same for every key is skipped), then
    /// each run of equal p by coordinate: the same sequence as a comparison sort, in O(n) (round 6: the
    /// comparison sort took 6.5 % of a 128-wide compress stroke's frame).
    template <typename Higher> void sortByPotential(std::vector<int32_t>& order, const Higher& higher)
    {
        const size_t n = order.size();
        if (n < 2) return;
        std::vector<uint64_t>& key = mB.sortKey;
        key.resize(n);
        for (size_t u = 0; u < n; ++u) {
            // +0.0 makes -0 into +0 (they compare equal); the bits then order as the doubles once a
            // negative's are all flipped and a positive's sign bit is set; complemented: decreasing p.
            const double v = mP[size_t(order[u])] + 0.0;
            uint64_t b;
            std::memcpy(&b, &v, sizeof b);
            b = (b >> 63) ? ~b : b | (uint64_t(1) << 63);
            key[u] = ~b;
        }
        radixSort(order);
        for (size_t u = 0; u < n;) {
            size_t e = u + 1;
            while (e < n && key[e] == key[u])
                ++e;
            if (e - u > 1)
                std::sort(order.begin() + std::ptrdiff_t(u), order.begin() + std::ptrdiff_t(e), higher);
            u = e;
        }
    }

    void route(GlobalTransportReport& rep)
    {
        std::vector<int32_t>& order = mB.order;
        selectIndices(mCells.size(), mSerial, mCounts, order, [&](size_t i) { return mKind[i] == kUnknown; });
        // A strict total order (ties by coordinate): every sort gives the same sequence.
        const auto higher = [&](int32_t a, int32_t b) {
            if (mP[size_t(a)] != mP[size_t(b)]) return mP[size_t(a)] > mP[size_t(b)];
            return mCells[size_t(a)] < mCells[size_t(b)];
        };
        if (mSerial || order.size() < kRadixMax)
            sortByPotential(order, higher);
        else
            tbb::parallel_sort(order.begin(), order.end(), higher);
        std::vector<int64_t>& cur = mB.cur;
        cur.assign(mM0.begin(), mM0.end());
        // Each cell's lower neighbours and drops depend on p and the kinds only, not on what the
        // cells above sent: gathered in parallel, a block of the order at a time (bounded memory,
        // read in order by the serial pass, which then only splits the integer excess).
        constexpr size_t kBlock = size_t(1) << 16;
        std::vector<int32_t>& outJ = mB.outJ;
        std::vector<double>& outW = mB.outW;
        std::vector<double>& outSum = mB.outSum;
        std::vector<uint8_t>& outN = mB.outN;
        const size_t block = std::min(kBlock, order.size());
        outJ.resize(block * 6);
        outW.resize(block * 6);
        outSum.resize(block);
        outN.resize(block);
        for (size_t t0 = 0; t0 < order.size(); t0 += kBlock) {
            const size_t t1 = std::min(order.size(), t0 + kBlock);
            forChunks(t1 - t0, mSerial, [&](size_t lo, size_t hi) {
                for (size_t u = lo; u < hi; ++u) {
                    const size_t i = size_t(order[t0 + u]);
                    const double pi = mP[i];
                    double W = 0;
                    uint8_t n = 0;
                    for (int d = 0; d < mDirs; ++d) {
                        const int32_t j = mNb[i * 6 + size_t(d)];
                        if (j < 0) continue;
                        const uint8_t k = mKind[size_t(j)];
                        if (k == kFrozen) continue;
                        const double pj = k == kUnknown ? mP[size_t(j)] : 0.0;
                        if (!(pj < pi)) continue;
                        outJ[u * 6 + n] = j;
                        outW[u * 6 + n] = pi - pj;
                        ++n;
                        W += pi - pj;
                    }
                    outN[u] = n;
                    outSum[u] = W;
                }
            });
            for (size_t u = 0; u < t1 - t0; ++u) {
                const size_t i = size_t(order[t0 + u]);
                const int64_t x = cur[i] - mTc;
                if (x <= 0) continue;
                const int n = outN[u];
                const double W = outSum[u];
                if (n == 0 || !(W > 0)) continue;
                int64_t share[6];
                double frac[6];
                int rank[6]; // the outs by decreasing remainder, ties in direction order
                int64_t given = 0;
                for (int k = 0; k < n; ++k) {
                    const double exact = double(x) * (outW[u * 6 + size_t(k)] / W);
                    share[k] = int64_t(std::floor(exact));
                    frac[k] = exact - double(share[k]);
                    given += share[k];
                    int m = k;
                    for (; m > 0 && frac[rank[m - 1]] < frac[k]; --m)
                        rank[m] = rank[m - 1];
                    rank[m] = k;
                }
                int64_t left = x - given;
                for (int k = 0; left != 0; k = (k + 1) % n) {
                    if (left > 0) {
                        ++share[rank[k]];
                        --left;
                    } else if (share[rank[k]] > 0) {
                        --share[rank[k]];
                        ++left;
                    }
                }
                for (int k = 0; k < n; ++k) {
                    cur[size_t(outJ[u * 6 + size_t(k)])] += share[k];
                    rep.massMoved += share[k];
                }
                cur[i] -= x;
            }
        }
        // Write the changed cells.
        std::vector<int32_t>& changed = mB.changed;
        selectIndices(mCells.size(), mSerial, mCounts, changed, [&](size_t i) { return cur[i] != mM0[i]; });
        if (changed.empty()) return;
        // Their bounds, per fixed chunk, united in chunk order.
        const size_t chunks = (changed.size() + kChunk - 1) / kChunk;
        std::vector<Box> boxes(chunks);
        std::vector<uint8_t> tooBig(chunks, 0);
        forChunks(changed.size(), mSerial, [&](size_t lo, size_t hi) {
            Coord mn = mCells[size_t(changed[lo])], mx = mn;
            for (size_t k = lo; k < hi; ++k) {
                const size_t i = size_t(changed[k]);
                if (cur[i] > INT32_MAX) tooBig[lo / kChunk] = 1;
                mn.minComponent(mCells[i]);
                mx.maxComponent(mCells[i]);
            }
            boxes[lo / kChunk] = Box{{{mn.x(), mn.y(), mn.z()}}, {{mx.x(), mx.y(), mx.z()}}};
        });
        Box region;
        for (size_t c = 0; c < chunks; ++c) {
            if (tooBig[c]) return; // cannot happen for Tc-sized inflows; refuse to write
            region = unite(region, boxes[c]);
        }
        rep.region = region;
        // Only the changed cells are written and read (round 6: edit() rescanned their bounds twice,
        // 3.5 % of a compress stroke frame); the same grid, sums and woken blocks.
        std::vector<Automaton::CellMass>& write = mB.write;
        write.resize(changed.size());
        for (size_t k = 0; k < changed.size(); ++k) {
            const size_t i = size_t(changed[k]);
            write[k].at = {{mCells[i].x(), mCells[i].y(), mCells[i].z()}};
            write[k].mass = cur[i] > 0 ? int32_t(cur[i]) : 0;
        }
        mA.setMasses(region, write);
        rep.overloadAfter = mA.residualOverload();
    }

    Automaton& mA;
    GlobalTransportOptions mOpt;
    int32_t mTc;
    int mDirs;
    const openvdb::Int32Tree& mMass;
    const openvdb::MaskTree* mObs;
    bool mSerial;
    /// Cached lookups for the serial flood and linking (the tree's own getValue starts at the root).
    mutable openvdb::tree::ValueAccessor<const openvdb::Int32Tree> mMassAcc;
    std::unique_ptr<openvdb::tree::ValueAccessor<const openvdb::MaskTree>> mObsAcc;

    Buffers& mB;
    bool mKeep; ///< the buffers outlive the call (a workspace): not freed before the routing
    std::unique_ptr<openvdb::Int32Tree> mIndex; ///< the cell index beyond the dense box (made on demand)
    std::unique_ptr<openvdb::tree::ValueAccessor<openvdb::Int32Tree>> mIndexAcc;
    bool mDense = false; ///< mB.denseIndex holds the index over the box at mDenseLo, mDenseDim
    Coord mDenseLo;
    int64_t mDenseDim[3] = {0, 0, 0};
    std::vector<Coord>& mCells;
    std::vector<int64_t>& mM0;
    std::vector<uint8_t>&mKind, &mHasNb;
    std::vector<int32_t>& mNb; ///< 6 per cell: neighbour cell, or -1 (wall)
    std::vector<int64_t>& mDist;
    std::vector<double>& mP;
    std::vector<int32_t>&mRow, &mRowCell;
    std::vector<int32_t>&mOldRow, &mJoined, &mLeft; ///< per-round scratch, kept (no fresh pages each round)
    std::vector<RowCoord>& mCoord;
    std::vector<double>& mInflow;
    std::vector<size_t>& mCounts;
    std::vector<int32_t>& mSolveNb; ///< the solve's matrix: 6 neighbour rows per row, -1: none
    std::vector<double>&mSolveDiag, &mSolveB, &mInv; ///< its diagonal, right-hand side, MIC(0) 1/pivots
    std::vector<double> (&mWork)[6];                 ///< the solve's x, r, z, p, q, w
    Multigrid* mSolveMg = nullptr;                   ///< the solve's multigrid (mB.mg), or none: MIC(0)
    bool mMgBuilt = false;        ///< mB.mg holds this call's hierarchy (of an earlier round)
    size_t mByCoordCells = 0;     ///< mB.byCoord lists the cells [0, this) (MIC(0)'s row order)
    std::vector<int32_t>& mMgRow; ///< cell -> its row in mB.mg's finest level, or -1
};

} // namespace

struct GlobalTransportWorkspace::Impl {
    Buffers buffers;
};

GlobalTransportWorkspace::GlobalTransportWorkspace() = default;
GlobalTransportWorkspace::~GlobalTransportWorkspace() = default;

void GlobalTransportWorkspace::release()
{
    mImpl.reset();
}

GlobalTransportReport transportGlobally(Automaton& automaton, const GlobalTransportOptions& optionsIn,
                                        GlobalTransportWorkspace* workspace)
{
    if (optionsIn.reach < 0)
        throw Error("transportGlobally: reach must be >= 0, got " + std::to_string(optionsIn.reach));
    if (optionsIn.maxRounds < 1) throw Error("transportGlobally: maxRounds must be >= 1");
    if (!(optionsIn.tolerance > 0 && optionsIn.tolerance < 1))
        throw Error("transportGlobally: tolerance must lie in (0, 1)");
    if (!(optionsIn.roundTolerance >= 0 && optionsIn.roundTolerance < 1))
        throw Error("transportGlobally: roundTolerance must lie in [0, 1)");
    const auto t0 = std::chrono::steady_clock::now();
    GlobalTransportReport rep;
    const GlobalTransportOptions& options = optionsIn;
    std::unique_ptr<GlobalTransportWorkspace::Impl> local;
    GlobalTransportWorkspace::Impl* impl = nullptr;
    if (workspace) {
        if (!workspace->mImpl) workspace->mImpl = std::make_unique<GlobalTransportWorkspace::Impl>();
        impl = workspace->mImpl.get();
    } else {
        local = std::make_unique<GlobalTransportWorkspace::Impl>();
        impl = local.get();
    }
    auto body = [&] {
        Solver s(automaton, options, impl->buffers, workspace != nullptr);
        rep = s.run();
    };
    if (options.threads > 1) {
        tbb::task_arena arena(options.threads);
        arena.execute(body);
    } else {
        body();
    }
    rep.seconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
    return rep;
}

} // namespace vdbclay
