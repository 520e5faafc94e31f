// The global transport's domain (Domain.h: the design): seeds, the flood, the cell index, the parts
// with no room.

#include "transport/Domain.h"
#include "transport/Chunks.h"
#include "transport/SolverTuning.h"

#include "vdbclay/Automaton.h"

#include <openvdb/openvdb.h>
#include <openvdb/tree/ValueAccessor.h>

#include <algorithm>
#include <climits>
#include <cstdlib>
#include <optional>

namespace vdbclay {
namespace transport_internal {

namespace {

using openvdb::Coord;

/// What the flood found at an unknown cell's face (Domain::link): linked or a wall (an obstacle, or a
/// face the dimensions leave out), a cell with room, full clay beyond the reach.
enum FaceFound : uint8_t { kFaceDone = 0, kFaceRoom = 1, kFaceFull = 2 };

Coord toCoord(const CellCoord& c)
{
    return Coord(c.x, c.y, c.z);
}

CellCoord toCell(const Coord& c)
{
    return CellCoord{c.x(), c.y(), c.z()};
}

/// What the flood finds at @a q, not a cell of the domain (FaceFound), through @a at's lookups
/// (isObstacle, massAt): an obstacle, room (m < @a tc), or full clay; its mass in @a m.
template <typename Lookups> uint8_t faceFound(const Lookups& at, const Coord& q, int32_t tc, int32_t& m)
{
    if (at.isObstacle(q)) return kFaceDone;
    m = at.massAt(q);
    return m < tc ? kFaceRoom : kFaceFull;
}

} // namespace

struct Domain::Grids {
    explicit Grids(const Automaton& a)
        : mass(a.mass()->constTree()), massAcc(mass),
          obs(a.obstacles() ? &a.obstacles()->constTree() : nullptr)
    {
        if (obs) obsAcc = std::make_unique<openvdb::tree::ValueAccessor<const openvdb::MaskTree>>(*obs);
    }
    bool isObstacle(const Coord& c) const { return obsAcc && obsAcc->isValueOn(c); }
    int32_t massAt(const Coord& c) const { return massAcc.getValue(c); }

    /// The lookups of one chunk of a parallel pass (the flood's batches, the seeds' test): accessors of
    /// its own, unregistered (the trees do not change while the pass reads them).
    struct Readers {
        explicit Readers(const Grids& g) : mass(g.mass)
        {
            if (g.obs) obs.emplace(*g.obs);
            if (g.index) beyond.emplace(*g.index);
        }
        bool isObstacle(const Coord& c) const { return obs && obs->isValueOn(c); }
        int32_t massAt(const Coord& c) const { return mass.getValue(c); }
        /// The cell index beyond the dense box (Domain::indexBeyond).
        int32_t indexBeyond(const Coord& c) const { return beyond ? beyond->getValue(c) : -1; }

        openvdb::tree::ValueAccessor<const openvdb::Int32Tree, false> mass;
        std::optional<openvdb::tree::ValueAccessor<const openvdb::MaskTree, false>> obs;
        std::optional<openvdb::tree::ValueAccessor<const openvdb::Int32Tree, false>> beyond;
    };

    const openvdb::Int32Tree& mass;
    /// Cached lookups for the serial flood and linking (the tree's own getValue starts at the root).
    openvdb::tree::ValueAccessor<const openvdb::Int32Tree> massAcc;
    const openvdb::MaskTree* obs;
    std::unique_ptr<openvdb::tree::ValueAccessor<const openvdb::MaskTree>> obsAcc;
    std::unique_ptr<openvdb::Int32Tree> index; ///< the cell index beyond the dense box (made on demand)
    std::unique_ptr<openvdb::tree::ValueAccessor<openvdb::Int32Tree>> indexAcc;
};

Domain::Domain(const Automaton& automaton, DomainArrays& arrays, bool reachFromContact,
               uint64_t floodBatchMin, bool serial)
    : mTc(automaton.options().rule.threshold), mDirs(automaton.options().dimensions == 2 ? 4 : 6),
      mFromContact(reachFromContact), mFloodBatchMin(floodBatchMin), mSerial(serial), mB(arrays),
      mC(arrays.cells), mGrids(std::make_unique<Grids>(automaton)), mIndex(arrays.index)
{
}

Domain::~Domain() = default;

inline bool Domain::isObstacle(const CellCoord& c) const
{
    return mGrids->isObstacle(toCoord(c));
}

inline int32_t Domain::massAt(const CellCoord& c) const
{
    return mGrids->massAt(toCoord(c));
}

int64_t Domain::seeds(const Box& region, std::vector<CellCoord>& seeds) const
{
    int64_t overload = 0;
    auto seed = [&](const Coord& c, int32_t m) {
        if (m > mTc && !mGrids->isObstacle(c)) {
            seeds.push_back(toCell(c));
            overload += int64_t(m) - mTc;
        }
    };
    const openvdb::Int32Tree& mass = mGrids->mass;
    if (region.empty()) {
        for (auto it = mass.cbeginValueOn(); it; ++it)
            seed(it.getCoord(), *it);
        return overload;
    }
    // The leaves that meet the region, in x, y, z order of their origins.
    const Box& r = region;
    openvdb::tree::ValueAccessor<const openvdb::Int32Tree> acc(mass);
    const int32_t lo[3] = {r.min[0] & ~7, r.min[1] & ~7, r.min[2] & ~7};
    for (int32_t x = lo[0]; x <= r.max[0]; x += 8)
        for (int32_t y = lo[1]; y <= r.max[1]; y += 8)
            for (int32_t z = lo[2]; z <= r.max[2]; z += 8) {
                const auto* leaf = acc.probeConstLeaf(Coord(x, y, z));
                if (!leaf) continue;
                for (auto it = leaf->cbeginValueOn(); it; ++it) {
                    const Coord c = it.getCoord();
                    if (c.x() < r.min[0] || c.x() > r.max[0] || c.y() < r.min[1] || c.y() > r.max[1] ||
                        c.z() < r.min[2] || c.z() > r.max[2])
                        continue;
                    seed(c, *it);
                }
            }
    return overload;
}

bool Domain::fitsNearby(const std::vector<CellCoord>& seeds, int64_t excess) const
{
    std::vector<Coord> near;
    for (int dx = -2; dx <= 2; ++dx)
        for (int dy = -2; dy <= 2; ++dy)
            for (int dz = mDirs == 6 ? -2 : 0; dz <= (mDirs == 6 ? 2 : 0); ++dz) {
                const int l1 = std::abs(dx) + std::abs(dy) + std::abs(dz);
                if (l1 >= 1 && l1 <= 2) near.emplace_back(dx, dy, dz);
            }
    openvdb::tree::ValueAccessor<const openvdb::Int32Tree> acc(mGrids->mass);
    std::vector<Coord> room;
    for (const CellCoord& s : seeds) {
        const Coord c = toCoord(s);
        bool any = false;
        for (const Coord& o : near) {
            const Coord q = c + o;
            if (acc.getValue(q) >= mTc || mGrids->isObstacle(q)) continue;
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

int32_t Domain::indexBeyond(const CellCoord& c) const
{
    return mGrids->indexAcc ? mGrids->indexAcc->getValue(toCoord(c)) : -1;
}

void Domain::setIndexBeyond(const CellCoord& c, int32_t i)
{
    Grids& g = *mGrids;
    if (!g.indexAcc) {
        g.index = std::make_unique<openvdb::Int32Tree>(-1);
        g.indexAcc = std::make_unique<openvdb::tree::ValueAccessor<openvdb::Int32Tree>>(*g.index);
    }
    g.indexAcc->setValue(toCoord(c), i);
}

void Domain::resetIndex(const std::vector<CellCoord>& seeds, int64_t reach)
{
    mGrids->indexAcc.reset();
    mGrids->index.reset();
    mIndex.clear();
    if (reach <= 0 || seeds.empty() || reach > (int64_t(1) << 20)) return;
    CellCoord lo = seeds.front(), hi = lo;
    for (const CellCoord& c : seeds) {
        lo.minComponent(c);
        hi.maxComponent(c);
    }
    const int64_t g = reach + 2, gz = mDirs == 4 ? 0 : g;
    const int64_t boxLo[3] = {int64_t(lo.x) - g, int64_t(lo.y) - g, int64_t(lo.z) - gz};
    const int64_t boxHi[3] = {int64_t(hi.x) + g, int64_t(hi.y) + g, int64_t(hi.z) + gz};
    for (int a = 0; a < 3; ++a)
        if (boxLo[a] < INT32_MIN || boxHi[a] > INT32_MAX) return;
    mIndex.reset(CellCoord{int32_t(boxLo[0]), int32_t(boxLo[1]), int32_t(boxLo[2])},
                 CellCoord{int32_t(boxHi[0]), int32_t(boxHi[1]), int32_t(boxHi[2])}, kCellIndexSlotsMax);
}

inline int32_t Domain::addCell(const CellCoord& c, uint8_t kind, int32_t m)
{
    const int32_t i = int32_t(mC.size());
    mC.at.push_back(c);
    mC.m0.push_back(m);
    mC.kind.push_back(kind);
    mC.nb.insert(mC.nb.end(), 6, -1);
    mC.hasNb.push_back(0);
    setIndex(c, i);
    return i;
}

inline int32_t Domain::addCell(const CellCoord& c, uint8_t kind)
{
    return addCell(c, kind, massAt(c));
}

inline uint8_t Domain::faceAt(const CellCoord& q, int32_t& m) const
{
    return faceFound(*mGrids, toCoord(q), mTc, m);
}

bool Domain::link(int32_t i, const uint8_t* face)
{
    bool cut = false;
    const CellCoord c = mC.at[size_t(i)];
    for (int d = 0; d < mDirs; ++d) {
        if (face && face[d] == kFaceDone) continue;
        const CellCoord q = c.offsetBy(kDir[d][0], kDir[d][1], kDir[d][2]);
        int32_t j = indexOf(q);
        if (j < 0) {
            int32_t m = 0;
            const uint8_t found = face ? face[d] : faceAt(q, m);
            if (found == kFaceDone) continue;
            if (found == kFaceFull) {
                cut = true; // beyond the reach: a wall for this solve
                continue;
            }
            j = addCell(q, kDirichlet);
        }
        linkPair(i, d, j);
    }
    mC.hasNb[size_t(i)] = 1;
    return cut;
}

template <typename Find> void Domain::floodBatch(size_t head, size_t end, int64_t reach, const Find& find)
{
    std::vector<int32_t>& comp = mB.comp;
    std::vector<int32_t>& parent = mB.compParent;
    mB.face.resize(end * 6, kFaceDone);
    const size_t n = end - head, chunks = (n + kChunk - 1) / kChunk;
    if (mB.finds.size() < chunks) {
        mB.finds.resize(chunks);
        mB.meets.resize(chunks);
    }
    // Probes, in parallel: reads only, and each cell writes its own faces. The face back from a cell
    // already in the domain is that cell's to link: when the flood took it (this cell was there, or
    // it added this cell), or in the link pass (it found full clay beyond the reach here).
    const Grids& g = *mGrids;
    forChunks(n, mSerial, [&](size_t lo, size_t hi) {
        std::vector<int32_t>& finds = mB.finds[lo / kChunk];
        std::vector<int32_t>& meets = mB.meets[lo / kChunk];
        finds.clear();
        meets.clear();
        const Grids::Readers at(g);
        for (size_t i = head + lo; i < head + hi; ++i) {
            const CellCoord c = mC.at[i];
            const int64_t di = mB.dist[i];
            const int32_t part = comp[i];
            for (int d = 0; d < mDirs; ++d) {
                const CellCoord q = c.offsetBy(kDir[d][0], kDir[d][1], kDir[d][2]);
                const int32_t k =
                    indexOf(q, [&at](const CellCoord& b) { return at.indexBeyond(toCoord(b)); });
                if (k >= 0) {
                    mC.nb[i * 6 + size_t(d)] = k;
                    if (comp[size_t(k)] != part) {
                        meets.push_back(int32_t(i));
                        meets.push_back(k);
                    }
                    continue;
                }
                int32_t m = 0;
                const uint8_t found = faceFound(at, toCoord(q), mTc, m);
                if (found == kFaceDone) continue;
                if (found == kFaceRoom || (reach > 0 && di >= reach)) {
                    mB.face[i * 6 + size_t(d)] = found;
                    continue;
                }
                finds.push_back(int32_t(i));
                finds.push_back(d);
                finds.push_back(m);
            }
        }
    });
    // The finds added, serially in cell-then-face order: a cell found twice is added by its first
    // finder and linked to the others, as the one-by-one flood does.
    auto unite = [&](int32_t a, int32_t b) {
        a = find(comp[size_t(a)]);
        b = find(comp[size_t(b)]);
        if (a != b) parent[size_t(std::max(a, b))] = std::min(a, b);
    };
    for (size_t ch = 0; ch < chunks; ++ch) {
        const std::vector<int32_t>& meets = mB.meets[ch];
        for (size_t e = 0; e < meets.size(); e += 2)
            unite(meets[e], meets[e + 1]);
        const std::vector<int32_t>& finds = mB.finds[ch];
        for (size_t e = 0; e < finds.size(); e += 3) {
            const int32_t i = finds[e];
            const int d = finds[e + 1];
            const CellCoord q = mC.at[size_t(i)].offsetBy(kDir[d][0], kDir[d][1], kDir[d][2]);
            const int32_t k = indexOf(q);
            if (k >= 0) {
                linkPair(i, d, k);
                unite(i, k);
                continue;
            }
            linkPair(i, d, addCell(q, kUnknown, finds[e + 2]));
            mB.dist.push_back(mB.dist[size_t(i)] + 1);
            comp.push_back(find(comp[size_t(i)]));
        }
    }
}

bool Domain::build(const std::vector<CellCoord>& seeds, int64_t reach, int64_t margin, bool& cut)
{
    std::vector<int32_t>& comp = mB.comp;
    std::vector<int32_t>& parent = mB.compParent;
    std::vector<uint8_t>& face = mB.face;
    comp.clear();
    parent.clear();
    face.clear();
    auto find = [&](int32_t a) {
        while (parent[size_t(a)] != a) {
            parent[size_t(a)] = parent[size_t(parent[size_t(a)])];
            a = parent[size_t(a)];
        }
        return a;
    };
    mC.at.clear();
    mC.m0.clear();
    mC.kind.clear();
    mC.nb.clear();
    mC.hasNb.clear();
    mB.dist.clear();
    resetIndex(seeds, reach);
    // The queue is the cells themselves: the flood appends the unknown cells in the order it
    // reaches them (the Dirichlet cells come after it, in link()), so cells [head, size) are queued.
    size_t head = 0;
    auto start = [&](const CellCoord& s, int64_t dist) {
        addCell(s, kUnknown);
        mB.dist.push_back(dist);
        comp.push_back(int32_t(parent.size()));
        parent.push_back(int32_t(parent.size()));
    };
    // The reach counts from the contact: the seeds on the clay's boundary (a face on an obstacle,
    // a tool, or a cell with room) start the flood; a seed inside the full clay (down a compress
    // chain) is reached through it at its depth. One the reach did not get to (a chain deeper, in
    // face steps, than the reach: a diagonal one) starts a flood of its own afterwards, with a
    // margin of @a margin steps around it (it already lies in the plastic zone). So a compress
    // push's chains add next to no reach beyond the contact.
    const bool fromContact = mFromContact;
    const int64_t innerDist = reach > margin ? reach - margin : 0;
    bool innerStarted = !fromContact;
    if (fromContact) {
        std::vector<int32_t>& inner = mB.innerSeeds;
        inner.clear();
        // Which seeds lie on the boundary: probed over fixed chunks (in parallel for many seeds),
        // then started in their order.
        std::vector<uint8_t>& boundary = mB.seedOnBoundary;
        boundary.resize(seeds.size());
        const Grids& g = *mGrids;
        forChunks(seeds.size(), mSerial || seeds.size() < mFloodBatchMin, [&](size_t lo, size_t hi) {
            const Grids::Readers at(g);
            for (size_t si = lo; si < hi; ++si) {
                bool on = false; // a face on an obstacle or room
                for (int d = 0; d < mDirs && !on; ++d) {
                    int32_t m = 0;
                    const Coord q = toCoord(seeds[si].offsetBy(kDir[d][0], kDir[d][1], kDir[d][2]));
                    on = faceFound(at, q, mTc, m) != kFaceFull;
                }
                boundary[si] = on;
            }
        });
        for (size_t si = 0; si < seeds.size(); ++si) {
            const CellCoord& s = seeds[si];
            if (indexOf(s) >= 0) continue;
            if (boundary[si])
                start(s, 0);
            else
                inner.push_back(int32_t(si));
        }
    } else {
        for (const CellCoord& s : seeds)
            if (indexOf(s) < 0) start(s, 0);
    }
    cut = false;
    for (;;) {
        if (head == mC.size()) { // the seeds the contact's flood did not reach start their own
            if (innerStarted) break;
            innerStarted = true;
            for (const int32_t si : mB.innerSeeds)
                if (indexOf(seeds[size_t(si)]) < 0) start(seeds[size_t(si)], innerDist);
            continue;
        }
        // A whole layer of the flood queued (one distance) and large enough: looked at together.
        const size_t end = mC.size();
        if (!mSerial && end - head >= mFloodBatchMin && mB.dist[head] == mB.dist[end - 1]) {
            floodBatch(head, end, reach, find);
            head = end;
            continue;
        }
        const int32_t i = int32_t(head++);
        const CellCoord c = mC.at[size_t(i)];
        const int64_t di = mB.dist[size_t(i)];
        face.resize(size_t(i + 1) * 6, kFaceDone); // cells are taken in index order
        // The cell's part by its root; the cells it adds are labelled by it, so a label is most
        // often a root and one comparison finds two cells in one part.
        int32_t root = find(comp[size_t(i)]);
        for (int d = 0; d < mDirs; ++d) {
            const CellCoord q = c.offsetBy(kDir[d][0], kDir[d][1], kDir[d][2]);
            const int32_t k = indexOf(q);
            if (k >= 0) { // every face between two domain cells is seen here, from one side
                linkPair(i, d, k);
                if (comp[size_t(k)] == root) continue; // one label: one part already
                const int32_t b = find(comp[size_t(k)]);
                if (b != root) {
                    parent[size_t(std::max(root, b))] = std::min(root, b);
                    root = std::min(root, b);
                }
                continue;
            }
            int32_t m = 0;
            const uint8_t found = faceAt(q, m);
            if (found == kFaceDone) continue;
            // Room, or full clay beyond the reach: link() makes the Dirichlet cell or marks the cut
            // (unless a later flood gets there).
            if (found == kFaceRoom || (reach > 0 && di >= reach)) {
                face[size_t(i) * 6 + size_t(d)] = found;
                continue;
            }
            linkPair(i, d, addCell(q, kUnknown, m));
            mB.dist.push_back(di + 1);
            comp.push_back(root);
        }
        comp[size_t(i)] = root;
    }
    // Link every unknown cell (Dirichlet cells appear here, after the unknowns), and mark
    // the parts that touch a Dirichlet cell. Only a cell the flood left a face to (room, or full clay
    // beyond the reach) has anything to link, or can touch a Dirichlet cell: those are listed over
    // fixed chunks, and linked in their order.
    std::vector<uint8_t>& room = mB.compRoom;
    room.assign(parent.size(), 0);
    const size_t unknowns = mC.size();
    std::vector<int32_t>& open = mB.openCells;
    std::fill(mC.hasNb.begin(), mC.hasNb.end(), uint8_t(1)); // link()'s mark: every face looked at
    selectIndices(unknowns, mSerial, mB.counts, open, [&](size_t i) {
        for (int d = 0; d < mDirs; ++d)
            if (face[i * 6 + size_t(d)] != kFaceDone) return true;
        return false;
    });
    for (const int32_t o : open) {
        const size_t i = size_t(o);
        cut |= link(int32_t(i), &face[i * 6]);
        for (int d = 0; d < mDirs; ++d) {
            const int32_t j = mC.nb[i * 6 + size_t(d)];
            if (j >= 0 && mC.kind[size_t(j)] == kDirichlet) {
                room[size_t(find(comp[i]))] = 1;
                break;
            }
        }
    }
    for (size_t r = 0; r < parent.size(); ++r)
        if (parent[r] == int32_t(r) && !room[r]) return false;
    return true;
}

void Domain::freezeSingular(bool cut, bool& grow, GlobalTransportReport& rep)
{
    grow = false;
    std::vector<uint8_t>& seen = mB.seen;
    seen.assign(mC.size(), 0);
    std::vector<int32_t>& part = mB.part;
    for (size_t s = 0; s < mC.size(); ++s) {
        if (mC.kind[s] != kUnknown || seen[s]) continue;
        part.clear();
        part.push_back(int32_t(s));
        seen[s] = 1;
        bool room = false, partCut = false;
        for (size_t k = 0; k < part.size(); ++k) {
            const size_t i = size_t(part[k]);
            const CellCoord c = mC.at[i];
            for (int d = 0; d < mDirs; ++d) {
                const int32_t j = mC.nb[i * 6 + size_t(d)];
                if (j < 0) {
                    const CellCoord q = c.offsetBy(kDir[d][0], kDir[d][1], kDir[d][2]);
                    if (!isObstacle(q)) partCut = true; // a full cell beyond the reach
                    continue;
                }
                if (mC.kind[size_t(j)] == kDirichlet)
                    room = true;
                else if (mC.kind[size_t(j)] == kUnknown && !seen[size_t(j)]) {
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
            mC.kind[size_t(i)] = kFrozen;
            rep.massNoRoom += std::max<int64_t>(0, mC.m0[size_t(i)] - mTc);
        }
    }
}

} // namespace transport_internal
} // namespace vdbclay
