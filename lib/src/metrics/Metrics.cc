// Whole-grid measurements (Metrics.h), whatever the tree's layout.
//
// totalMass, residualOverload and clayVoxelCount walk every value once, tiles included, in 64-bit
// integers; contentHash adds a hash of each voxel's coordinate and value (the automaton's block
// hash, rules_internal::hashKey), so the order of the walk does not matter and a tile gives the hash
// of its voxels (it hashes them in parallel, in AVX-512 where the CPU has it: a tile of clay is hashed
// as the same voxels in leaves would be). measureClay takes each leaf's and each tile's integer sums in
// parallel (a leaf's interior, and an 8^3 tile's, as bits: its voxels holding clay, shifted one face
// step each way, the facing layers of its neighbours across its faces; a larger tile's interior is its
// voxels off its faces, and those of its faces whose neighbours hold clay), then adds them up; the spread
// about the mean comes from exact integer sums of m and m^2: the same numbers on any thread count and any
// tree layout. compareShapes compares occupied sets as masks and measures the distances between their surface
// voxels with a static 3D tree of voxel centres (exact integer squared distances). metrics/ stands on core/,
// automaton/ (the hash) and shapes/ (rasterised reference shapes).
#include "vdbclay/Metrics.h"

#include "vdbclay/Shapes.h"
#include "vdbclay/Types.h"

#include "automaton/Cpu.h"
#include "automaton/RulesImpl.h"
#include "core/ParallelFor.h"
#include "shapes/Voxels.h"

#include <openvdb/openvdb.h>

#include <algorithm>
#include <array>
#include <climits>
#include <cmath>
#include <limits>
#include <memory>
#include <string>
#include <utility>
#include <vector>

namespace vdbclay {

using openvdb::Coord;

int64_t totalMass(const MassGrid& mass)
{
    int64_t sum = 0;
    for (auto it = mass.tree().cbeginValueAll(); it; ++it) {
        if (*it == 0) continue;
        // A tile of 4096^3 voxels holding 2^31 each is ~2^67: a file can ask for that.
        int64_t part = 0;
        if (__builtin_mul_overflow(int64_t(*it), int64_t(it.getVoxelCount()), &part) ||
            __builtin_add_overflow(sum, part, &sum)) {
            throw Error("totalMass: the total mass exceeds " +
                        std::to_string(std::numeric_limits<int64_t>::max()));
        }
    }
    return sum;
}

int64_t residualOverload(const MassGrid& mass, int32_t threshold, const ObstacleGrid* obstacles)
{
    int64_t sum = 0;
    openvdb::MaskGrid::ConstAccessor* oacc = nullptr;
    std::unique_ptr<openvdb::MaskGrid::ConstAccessor> holder;
    if (obstacles) {
        holder = std::make_unique<openvdb::MaskGrid::ConstAccessor>(obstacles->getConstAccessor());
        oacc = holder.get();
    }
    for (auto it = mass.tree().cbeginValueAll(); it; ++it) {
        if (*it <= threshold) continue;
        if (!it.isVoxelValue()) { // a tile over Tc: its voxels that are not obstacles
            openvdb::CoordBBox bb;
            it.getBoundingBox(bb);
            for (auto c = bb.begin(); c; ++c)
                if (!(oacc && oacc->isValueOn(*c))) sum += int64_t(*it) - threshold;
            continue;
        }
        if (oacc && oacc->isValueOn(it.getCoord())) continue;
        sum += int64_t(*it) - threshold;
    }
    return sum;
}

uint64_t clayVoxelCount(const MassGrid& mass)
{
    uint64_t n = 0;
    for (auto it = mass.tree().cbeginValueAll(); it; ++it) {
        if (*it != 0) n += it.getVoxelCount();
    }
    return n;
}

namespace {

/// The leaves of @a mass, in tree order.
std::vector<const MassGrid::TreeType::LeafNodeType*> leavesOf(const MassGrid& mass)
{
    std::vector<const MassGrid::TreeType::LeafNodeType*> leaves;
    leaves.reserve(mass.tree().leafCount());
    for (auto it = mass.tree().cbeginLeaf(); it; ++it)
        leaves.push_back(&*it);
    return leaves;
}

/// The tiles of @a mass holding clay (nonzero), by bounds and value.
struct ClayTile {
    openvdb::CoordBBox box;
    int32_t value;
};
std::vector<ClayTile> clayTiles(const MassGrid& mass)
{
    std::vector<ClayTile> tiles;
    auto it = mass.tree().cbeginValueAll();
    it.setMaxDepth(it.getLeafDepth() - 1); // tiles only
    for (; it; ++it) {
        if (*it == 0) continue;
        ClayTile t;
        it.getBoundingBox(t.box);
        t.value = *it;
        tiles.push_back(t);
    }
    return tiles;
}

/// contentHash hashes a tile's voxels one by one (one core: ~0.8 ns a voxel, ~0.13 ns in AVX-512): at most
/// this many.
constexpr uint64_t kHashTileVoxelsMax = uint64_t(1) << 35;

/// The sum of contentHash's term (rules_internal::finishHash of a value's prefix and a voxel) over the
/// voxels x0..x1 of @a box (one value's @a valuePrefix): finishHash unrolled, its first mix once per x,
/// the row in z a loop a compiler vectorises.
__attribute__((always_inline)) inline uint64_t slabHashSum(uint64_t valuePrefix, int32_t x0, int32_t x1,
                                                           const openvdb::CoordBBox& box)
{
    const uint32_t zCount = uint32_t(int64_t(box.max().z()) - box.min().z() + 1);
    uint64_t h = 0;
    for (int64_t x = x0; x <= x1; ++x) {
        const uint64_t hx = rules_internal::mix64(valuePrefix ^ uint64_t(uint32_t(int32_t(x))));
        for (int64_t y = box.min().y(); y <= box.max().y(); ++y) {
            const uint64_t row = hx ^ (uint64_t(uint32_t(int32_t(y))) << 32);
            for (uint32_t i = 0; i < zCount; ++i)
                h += rules_internal::mix64(row ^ uint64_t(uint32_t(box.min().z()) + i));
        }
    }
    return h;
}

uint64_t slabHashSumBase(uint64_t valuePrefix, int32_t x0, int32_t x1, const openvdb::CoordBBox& box)
{
    return slabHashSum(valuePrefix, x0, x1, box);
}

#if defined(VDBCLAY_HAVE_AVX512_BUILD)
/// slabHashSum in AVX-512 (eight 64-bit multiplies a vector): ~6x the baseline build's voxels a second.
__attribute__((target("avx512f,avx512dq"))) uint64_t
slabHashSumAvx512(uint64_t valuePrefix, int32_t x0, int32_t x1, const openvdb::CoordBBox& box)
{
    return slabHashSum(valuePrefix, x0, x1, box);
}
#endif

/// slabHashSum in the build this CPU runs: the same sum from each.
uint64_t slabHashSumDispatch(uint64_t valuePrefix, int32_t x0, int32_t x1, const openvdb::CoordBBox& box)
{
#if defined(VDBCLAY_HAVE_AVX512_BUILD)
    if (automaton_internal::cpuHasAvx512dq()) return slabHashSumAvx512(valuePrefix, x0, x1, box);
#endif
    return slabHashSumBase(valuePrefix, x0, x1, box);
}

} // namespace

uint64_t contentHash(const MassGrid& mass)
{
    // Order-independent: a sum of per-voxel hashes (mod 2^64), so the tree's layout and the order of
    // the parallel parts do not matter.
    using Leaf = MassGrid::TreeType::LeafNodeType;
    const std::vector<const Leaf*> leaves = leavesOf(mass);
    const std::vector<ClayTile> tiles = clayTiles(mass);
    // Tiles cut into x slabs of at most 2^15 voxels each, so one large tile spreads over the threads.
    struct Part {
        size_t tile;
        int32_t x0, x1;
    };
    std::vector<Part> parts;
    uint64_t tileVoxels = 0;
    for (const ClayTile& t : tiles) {
        tileVoxels += t.box.volume();
        if (tileVoxels > kHashTileVoxelsMax) {
            throw Error("contentHash: the grid holds tiles of more than 2^35 voxels of clay");
        }
    }
    for (size_t t = 0; t < tiles.size(); ++t) {
        const openvdb::CoordBBox& b = tiles[t].box;
        const int64_t plane = int64_t(b.dim().y()) * b.dim().z();
        const int32_t step = int32_t(std::max<int64_t>(1, (int64_t(1) << 15) / plane));
        for (int64_t x = b.min().x(); x <= b.max().x(); x += step)
            parts.push_back({t, int32_t(x), int32_t(std::min<int64_t>(b.max().x(), x + step - 1))});
    }
    std::vector<uint64_t> sums(leaves.size() + parts.size(), 0), counts(sums.size(), 0);
    parallel_internal::forEachIndex(sums.size(), 0, [&](size_t i) {
        uint64_t h = 0, n = 0;
        if (i < leaves.size()) {
            // finishHash with its first mix (of the value's prefix and x) once per run of one value along
            // y and z: a leaf's voxels mostly hold few values.
            const Leaf& leaf = *leaves[i];
            const int32_t* d = leaf.buffer().data();
            const Coord& o = leaf.origin();
            for (int x = 0; x < 8; ++x) {
                int32_t last = 0;
                uint64_t hx = 0;
                for (int b = 0; b < 64; ++b) {
                    const int32_t m = d[x * 64 + b];
                    if (m == 0) continue;
                    if (m != last) {
                        last = m;
                        hx = rules_internal::mix64(rules_internal::stepPrefix(uint64_t(uint32_t(m)), 0) ^
                                                   uint64_t(uint32_t(o.x() + x)));
                    }
                    const uint64_t y = uint32_t(o.y() + (b >> 3)), z = uint32_t(o.z() + (b & 7));
                    h += rules_internal::mix64(hx ^ ((y << 32) | z));
                    ++n;
                }
            }
        } else {
            const Part& p = parts[i - leaves.size()];
            const ClayTile& t = tiles[p.tile];
            h = slabHashSumDispatch(rules_internal::stepPrefix(uint64_t(uint32_t(t.value)), 0), p.x0, p.x1,
                                    t.box);
            n = uint64_t(p.x1 - p.x0 + 1) * uint64_t(t.box.dim().y()) * uint64_t(t.box.dim().z());
        }
        sums[i] = h;
        counts[i] = n;
    });
    uint64_t h = 0, count = 0;
    for (size_t i = 0; i < sums.size(); ++i) {
        h += sums[i];
        count += counts[i];
    }
    return rules_internal::mix64(h ^ rules_internal::mix64(count));
}

// ---- Accuracy metrics ---------------------------------------------------------------------------

namespace {

void checkArgs(const char* what, int32_t threshold, int dims)
{
    if (threshold <= 0) {
        throw Error(std::string(what) + ": the threshold Tc must be > 0, not " + std::to_string(threshold));
    }
    if (dims != 2 && dims != 3) {
        throw Error(std::string(what) + ": dimensions must be 2 or 3, not " + std::to_string(dims));
    }
}

/// The face neighbour offsets: the first 4 in 2D, all 6 in 3D.
const Coord kFaces[6] = {Coord(1, 0, 0),  Coord(-1, 0, 0), Coord(0, 1, 0),
                         Coord(0, -1, 0), Coord(0, 0, 1),  Coord(0, 0, -1)};
int faceCount(int dims)
{
    return dims == 3 ? 6 : 4;
}

/// 2 m >= Tc, in 64 bits.
inline bool occupied(int32_t m, int32_t threshold)
{
    return 2 * int64_t(m) >= int64_t(threshold);
}

/// Calls @a fn(coord, mass) for every voxel holding clay, a tile's voxels one by one.
template <typename Fn> void forEachClayVoxel(const MassGrid& mass, Fn&& fn)
{
    for (auto it = mass.tree().cbeginValueAll(); it; ++it) {
        if (*it == 0) continue;
        if (!it.isVoxelValue()) {
            openvdb::CoordBBox bb;
            it.getBoundingBox(bb);
            for (auto c = bb.begin(); c; ++c)
                fn(*c, *it);
            continue;
        }
        fn(it.getCoord(), *it);
    }
}

} // namespace

namespace {

/// The spread of @a n values about their mean from their exact sums (@a s1 = sum m, @a s2 = sum m^2):
/// sqrt(n s2 - s1^2) / n, in 128-bit integers where they hold it.
double spread(uint64_t n, int64_t s1, unsigned __int128 s2)
{
    unsigned __int128 ns2 = 0;
    const unsigned __int128 s1sq = (unsigned __int128)(uint64_t(s1)) * uint64_t(s1);
    if (!__builtin_mul_overflow((unsigned __int128)n, s2, &ns2) && ns2 >= s1sq)
        return std::sqrt(double(ns2 - s1sq)) / double(n);
    const long double mean = (long double)s1 / n;
    return double(std::sqrt(std::max<long double>(0, (long double)s2 / n - mean * mean)));
}

} // namespace

namespace {

/// Bit z = 0 of every row of a leaf's mask word (a word per x, bit y * 8 + z).
constexpr uint64_t kZ0 = 0x0101010101010101ull;

/// A leaf's voxels holding clay (a value other than 0) as bits: a word per x, bit y * 8 + z.
std::array<uint64_t, 8> clayBits(const int32_t* d)
{
    std::array<uint64_t, 8> w{};
    for (int x = 0; x < 8; ++x)
        for (int b = 0; b < 64; ++b)
            w[x] |= uint64_t(d[x * 64 + b] != 0) << b;
    return w;
}

/// Every bit, or none.
std::array<uint64_t, 8> uniformBits(bool on)
{
    std::array<uint64_t, 8> w;
    w.fill(on ? ~uint64_t(0) : 0);
    return w;
}

/// For each voxel of a leaf whose clay bits are @a self, whether its neighbour across face @a f
/// (kFaces' order: +x, -x, +y, -y, +z, -z) holds clay: from @a self inside the leaf, from the bits
/// of the leaf beyond that face, @a beyond, on the face.
std::array<uint64_t, 8> faceNeighbourBits(const std::array<uint64_t, 8>& self,
                                          const std::array<uint64_t, 8>& beyond, int f)
{
    std::array<uint64_t, 8> out;
    for (int x = 0; x < 8; ++x) {
        switch (f) {
        case 0: out[x] = x < 7 ? self[x + 1] : beyond[0]; break;
        case 1: out[x] = x > 0 ? self[x - 1] : beyond[7]; break;
        case 2: out[x] = (self[x] >> 8) | (beyond[x] << 56); break;
        case 3: out[x] = (self[x] << 8) | (beyond[x] >> 56); break;
        case 4: out[x] = ((self[x] >> 1) & ~(kZ0 << 7)) | ((beyond[x] & kZ0) << 7); break;
        default: out[x] = ((self[x] << 1) & ~kZ0) | ((beyond[x] >> 7) & kZ0); break;
        }
    }
    return out;
}

} // namespace

ClayMetrics measureClay(const MassGrid& mass, int32_t threshold, const ObstacleGrid* obstacles, int dims,
                        int threads)
{
    checkArgs("measureClay", threshold, dims);
    using MassLeaf = MassGrid::TreeType::LeafNodeType;
    const std::vector<const MassLeaf*> leaves = leavesOf(mass);
    const std::vector<ClayTile> tiles = clayTiles(mass);
    openvdb::CoordBBox obstacleBounds; // empty without obstacles
    if (obstacles) obstacleBounds = obstacles->evalActiveVoxelBoundingBox();
    struct Sums {
        int64_t mass = 0, residualOverload = 0, interiorSum = 0;
        uint64_t clayVoxels = 0, occupiedVoxels = 0, interiorCells = 0;
        unsigned __int128 interiorSquares = 0;
        int32_t maxCell = 0;
        /// One voxel of clay @a m at @a c: @a obstacle, @a interior (not an obstacle, all its face
        /// neighbours hold clay, z = 0 in 2D).
        void add(int32_t m, int32_t tc, bool obstacle, bool interior, uint64_t count = 1)
        {
            mass += int64_t(m) * int64_t(count);
            maxCell = std::max(maxCell, m);
            clayVoxels += count;
            if (occupied(m, tc)) occupiedVoxels += count;
            if (!obstacle && m > tc) residualOverload += (int64_t(m) - tc) * int64_t(count);
            if (interior) {
                interiorCells += count;
                interiorSum += int64_t(m) * int64_t(count);
                interiorSquares += (unsigned __int128)(uint64_t(int64_t(m) * m)) * count;
            }
        }
    };
    std::vector<Sums> sums(leaves.size() + tiles.size());
    const int faces = faceCount(dims);
    parallel_internal::forEachIndex(sums.size(), threads, [&](size_t i) {
        Sums& out = sums[i];
        // Accessors not registered with their trees (registering one a leaf would cost more than
        // the leaf's sums): the trees do not change while they are read.
        auto acc = mass.getConstUnsafeAccessor();
        std::unique_ptr<openvdb::MaskGrid::ConstUnsafeAccessor> oacc;
        if (obstacles)
            oacc =
                std::make_unique<openvdb::MaskGrid::ConstUnsafeAccessor>(obstacles->getConstUnsafeAccessor());
        // The voxels of the 8^3 block at @a o whose neighbours across every face hold clay, given the
        // block's own clay bits: inside it from its bits, across its faces from the facing layer of
        // the neighbouring leaf (or the tile or background there, one value); none on obstacles
        // (the block's: a leaf, an active tile or none, in @a obstacle), and in 2D none off z = 0.
        auto interiorBits = [&](const std::array<uint64_t, 8>& clay, const Coord& o,
                                std::array<uint64_t, 8>& obstacle) {
            std::array<uint64_t, 8> interior = clay;
            for (int f = 0; f < faces; ++f) {
                const Coord across(o.x() + 8 * kFaces[f].x(), o.y() + 8 * kFaces[f].y(),
                                   o.z() + 8 * kFaces[f].z());
                const MassLeaf* nl = acc.probeConstLeaf(across);
                const std::array<uint64_t, 8> beyond =
                    nl ? clayBits(nl->buffer().data()) : uniformBits(acc.getValue(across) != 0);
                const std::array<uint64_t, 8> next = faceNeighbourBits(clay, beyond, f);
                for (int x = 0; x < 8; ++x)
                    interior[x] &= next[x];
            }
            obstacle = uniformBits(false);
            if (obstacles) {
                if (const openvdb::MaskTree::LeafNodeType* ol = obstacles->tree().probeConstLeaf(o)) {
                    for (int x = 0; x < 8; ++x)
                        obstacle[x] = ol->getValueMask().template getWord<uint64_t>(openvdb::Index(x));
                } else if (oacc->isValueOn(o)) {
                    obstacle = uniformBits(true);
                }
            }
            uint64_t plane = ~uint64_t(0);
            if (dims == 2) plane = o.z() <= 0 && 0 < o.z() + 8 ? kZ0 << (-o.z()) : 0;
            for (int x = 0; x < 8; ++x)
                interior[x] &= ~obstacle[x] & plane;
            return interior;
        };
        auto interiorAt = [&](const Coord& c) {
            for (int f = 0; f < faces; ++f)
                if (acc.getValue(c + kFaces[f]) == 0) return false;
            return true;
        };
        if (i >= leaves.size()) {
            // A tile (3D: the automaton and makeClay make none in 2D): its voxels off its faces are
            // interior unless obstacles; those on its faces by their neighbours.
            const ClayTile& t = tiles[i - leaves.size()];
            const openvdb::CoordBBox& b = t.box;
            if (b.dim() == Coord(8)) { // a leaf's size (most tiles next to leaves): as a leaf of one value
                std::array<uint64_t, 8> obstacle;
                const std::array<uint64_t, 8> interior = interiorBits(uniformBits(true), b.min(), obstacle);
                uint64_t onObstacles = 0, inside = 0;
                for (int x = 0; x < 8; ++x) {
                    onObstacles += uint64_t(__builtin_popcountll(obstacle[x]));
                    inside += uint64_t(__builtin_popcountll(interior[x]));
                }
                out.add(t.value, threshold, true, false, onObstacles);
                out.add(t.value, threshold, false, true, inside);
                out.add(t.value, threshold, false, false, 512 - onObstacles - inside);
                return;
            }
            const bool anyObstacle = obstacles && obstacleBounds.hasOverlap(b);
            if (anyObstacle || dims == 2 || b.dim().x() < 3) {
                for (auto c = b.begin(); c; ++c) {
                    const bool obstacle = oacc && oacc->isValueOn(*c);
                    out.add(t.value, threshold, obstacle,
                            !obstacle && !(dims == 2 && (*c).z() != 0) && interiorAt(*c));
                }
                return;
            }
            // Which of its faces hold clay all along beyond them: the layer of voxels just outside
            // the face, read 8^3 slot by slot (a tile's box is slot-aligned), each slot a tile of clay
            // (one value: the accessor answers from a node above the leaves) or else voxel by voxel.
            const Coord lo = b.min(), hi = b.max();
            const int leafDepth = int(MassGrid::TreeType::DEPTH) - 1;
            bool backed[6];
            for (int f = 0; f < 6; ++f) {
                const int axis = f >> 1;
                openvdb::CoordBBox layer = b;
                const int32_t at = (f & 1) ? lo[axis] - 1 : hi[axis] + 1; // kFaces: +axis, then -axis
                layer.min()[axis] = layer.max()[axis] = at;
                backed[f] = true;
                for (auto slot = layer.min(); backed[f] && slot.x() <= layer.max().x(); slot.x() += 8)
                    for (slot.y() = layer.min().y(); backed[f] && slot.y() <= layer.max().y(); slot.y() += 8)
                        for (slot.z() = layer.min().z(); backed[f] && slot.z() <= layer.max().z();
                             slot.z() += 8) {
                            const int depth = acc.getValueDepth(slot);
                            if (depth >= 0 && depth < leafDepth) {
                                backed[f] = acc.getValue(slot) != 0;
                                continue;
                            }
                            openvdb::CoordBBox part(slot, slot.offsetBy(7));
                            part.intersect(layer);
                            for (auto c = part.begin(); backed[f] && c; ++c)
                                backed[f] = acc.getValue(*c) != 0;
                        }
            }
            if (std::all_of(backed, backed + 6, [](bool x) { return x; })) {
                out.add(t.value, threshold, false, true, b.volume());
                return;
            }
            const openvdb::CoordBBox inner(lo.offsetBy(1), hi.offsetBy(-1));
            out.add(t.value, threshold, false, true, inner.volume());
            // The voxels on its faces alone: whole planes at the x ends, the ring of y and z between;
            // each reads the neighbours beyond the faces it lies on that are not backed.
            auto faceInterior = [&](const Coord& c) {
                for (int f = 0; f < 6; ++f) {
                    const int axis = f >> 1;
                    if (backed[f] || c[axis] != ((f & 1) ? lo[axis] : hi[axis])) continue;
                    if (acc.getValue(c + kFaces[f]) == 0) return false;
                }
                return true;
            };
            for (int32_t x = lo.x(); x <= hi.x(); ++x) {
                const bool plane = x == lo.x() || x == hi.x();
                for (int32_t y = lo.y(); y <= hi.y(); ++y) {
                    const bool row = plane || y == lo.y() || y == hi.y();
                    const int32_t step = row ? 1 : hi.z() - lo.z();
                    for (int32_t z = lo.z(); z <= hi.z(); z += step)
                        out.add(t.value, threshold, false, faceInterior(Coord(x, y, z)));
                }
            }
            return;
        }
        const MassLeaf& leaf = *leaves[i];
        // The voxels holding clay as bits, their interior as bits (interiorBits), then one pass over
        // the values adds them up.
        const int32_t* d = leaf.buffer().data();
        const std::array<uint64_t, 8> clay = clayBits(d);
        std::array<uint64_t, 8> obstacle;
        const std::array<uint64_t, 8> interior = interiorBits(clay, leaf.origin(), obstacle);
        // Every value, without a branch: a 0 adds nothing to the sums (not clay, not occupied, not
        // over Tc, never interior; the largest cell starts at 0).
        int64_t massSum = 0, overload = 0, interiorSum = 0;
        uint64_t occupiedCount = 0, clayCount = 0, interiorCount = 0;
        unsigned __int128 interiorSquares = 0;
        int32_t largest = 0;
        for (int x = 0; x < 8; ++x) {
            clayCount += uint64_t(__builtin_popcountll(clay[x]));
            interiorCount += uint64_t(__builtin_popcountll(interior[x]));
            for (int bit = 0; bit < 64; ++bit) {
                const int64_t m = d[x * 64 + bit];
                const int64_t in = int64_t((interior[x] >> bit) & 1);
                massSum += m;
                largest = std::max(largest, int32_t(m));
                occupiedCount += uint64_t(2 * m >= threshold);
                overload += int64_t(((obstacle[x] >> bit) & 1) == 0 && m > threshold) * (m - threshold);
                interiorSum += in * m;
                interiorSquares += (unsigned __int128)(uint64_t(in * m * m));
            }
        }
        out.mass += massSum;
        out.maxCell = std::max(out.maxCell, largest);
        out.clayVoxels += clayCount;
        out.occupiedVoxels += occupiedCount;
        out.residualOverload += overload;
        out.interiorCells += interiorCount;
        out.interiorSum += interiorSum;
        out.interiorSquares += interiorSquares;
    });
    ClayMetrics r;
    int64_t interiorSum = 0;
    unsigned __int128 interiorSquares = 0;
    for (const Sums& l : sums) {
        r.mass += l.mass;
        r.maxCell = std::max(r.maxCell, l.maxCell);
        r.clayVoxels += l.clayVoxels;
        r.occupiedVoxels += l.occupiedVoxels;
        r.residualOverload += l.residualOverload;
        r.interiorCells += l.interiorCells;
        interiorSum += l.interiorSum;
        interiorSquares += l.interiorSquares;
    }
    if (r.mass > 0) {
        const int64_t cellsAtRest = (r.mass + threshold - 1) / threshold;
        r.compaction = double(r.clayVoxels) / double(cellsAtRest);
    }
    if (r.interiorCells == 0) return r;
    const double mean = double(interiorSum) / double(r.interiorCells);
    r.interiorMeanDensity = mean / double(threshold);
    r.heterogeneityCV = spread(r.interiorCells, interiorSum, interiorSquares) / mean;
    return r;
}

namespace {

using Point = std::array<int32_t, 3>;

int64_t squaredDistance(const Point& a, const Point& b)
{
    int64_t s = 0;
    for (int i = 0; i < 3; ++i) {
        const int64_t d = int64_t(a[i]) - int64_t(b[i]);
        s += d * d;
    }
    return s;
}

/// A static 3D tree for exact nearest-neighbour queries on voxel centres (integer distances).
class PointTree {
public:
    explicit PointTree(std::vector<Point> points) : mPoints(std::move(points))
    {
        build(0, mPoints.size(), 0);
    }

    /// The squared distance from @a q to the nearest point; the tree must not be empty.
    int64_t nearest(const Point& q) const
    {
        int64_t best = INT64_MAX;
        search(0, mPoints.size(), 0, q, best);
        return best;
    }

private:
    // The median of [lo, hi) along axis (depth % 3) sits at the middle; each half is a subtree.
    void build(size_t lo, size_t hi, int depth)
    {
        if (hi - lo <= 1) return;
        const size_t mid = lo + (hi - lo) / 2;
        const int axis = depth % 3;
        std::nth_element(mPoints.begin() + lo, mPoints.begin() + mid, mPoints.begin() + hi,
                         [axis](const Point& a, const Point& b) { return a[axis] < b[axis]; });
        build(lo, mid, depth + 1);
        build(mid + 1, hi, depth + 1);
    }

    void search(size_t lo, size_t hi, int depth, const Point& q, int64_t& best) const
    {
        if (lo >= hi) return;
        const size_t mid = lo + (hi - lo) / 2;
        const Point& p = mPoints[mid];
        best = std::min(best, squaredDistance(p, q));
        const int axis = depth % 3;
        const int64_t d = int64_t(q[axis]) - int64_t(p[axis]);
        // Near side first; the far side only if the splitting plane is closer than the best.
        if (d < 0) {
            search(lo, mid, depth + 1, q, best);
            if (d * d < best) search(mid + 1, hi, depth + 1, q, best);
        } else {
            search(mid + 1, hi, depth + 1, q, best);
            if (d * d < best) search(lo, mid, depth + 1, q, best);
        }
    }

    std::vector<Point> mPoints;
};

/// The surface voxels of the active set of @a set: active voxels with an inactive face neighbour.
std::vector<Point> surfaceVoxels(const openvdb::MaskGrid& set, int dims)
{
    std::vector<Point> out;
    auto acc = set.getConstAccessor();
    const int faces = faceCount(dims);
    for (auto it = set.tree().cbeginValueOn(); it; ++it) {
        openvdb::CoordBBox box;
        it.getBoundingBox(box); // a voxel, or an active tile of the mask
        for (auto c = box.begin(); c; ++c) {
            for (int f = 0; f < faces; ++f) {
                if (!acc.isValueOn(*c + kFaces[f])) {
                    const Coord v = *c;
                    out.push_back(Point{{v.x(), v.y(), v.z()}});
                    break;
                }
            }
        }
    }
    return out;
}

/// Sum and maximum over @a from of the distance to the nearest point of @a to (not empty).
void accumulateDistances(const std::vector<Point>& from, const PointTree& to, double& sum, double& max)
{
    for (const Point& p : from) {
        const double d = std::sqrt(double(to.nearest(p)));
        sum += d;
        max = std::max(max, d);
    }
}

openvdb::MaskGrid::Ptr occupiedSet(const MassGrid& mass, int32_t threshold, int dims, const char* what)
{
    auto set = openvdb::MaskGrid::create(false);
    auto acc = set->getAccessor();
    (void)what;
    forEachClayVoxel(mass, [&](const Coord& c, int32_t m) {
        if (dims == 2 && c.z() != 0) return;
        if (occupied(m, threshold)) acc.setValueOn(c);
    });
    return set;
}

ShapeError compareSets(const openvdb::MaskGrid& clay, const openvdb::MaskGrid& reference, int dims)
{
    ShapeError e;
    e.clayVoxels = clay.tree().activeVoxelCount();
    e.referenceVoxels = reference.tree().activeVoxelCount();
    openvdb::MaskTree both(clay.tree());
    both.topologyIntersection(reference.tree());
    e.intersection = both.activeVoxelCount();
    e.unionVoxels = e.clayVoxels + e.referenceVoxels - e.intersection;
    e.iou = e.unionVoxels == 0 ? 1.0 : double(e.intersection) / double(e.unionVoxels);

    std::vector<Point> a = surfaceVoxels(clay, dims), b = surfaceVoxels(reference, dims);
    e.claySurface = a.size();
    e.referenceSurface = b.size();
    if (a.empty() && b.empty()) return e;
    if (a.empty() || b.empty()) {
        e.meanSurfaceDistance = e.maxSurfaceDistance = std::numeric_limits<double>::infinity();
        return e;
    }
    double sum = 0, max = 0;
    {
        const PointTree tb(b);
        accumulateDistances(a, tb, sum, max);
    }
    const PointTree ta(std::move(a));
    accumulateDistances(b, ta, sum, max);
    e.meanSurfaceDistance = sum / double(e.claySurface + e.referenceSurface);
    e.maxSurfaceDistance = max;
    return e;
}

} // namespace

ShapeError compareShapes(const MassGrid& clay, int32_t threshold, const MassGrid& reference,
                         int32_t referenceThreshold, int dims)
{
    checkArgs("compareShapes", threshold, dims);
    checkArgs("compareShapes (reference)", referenceThreshold, dims);
    return compareSets(*occupiedSet(clay, threshold, dims, "compareShapes"),
                       *occupiedSet(reference, referenceThreshold, dims, "compareShapes (reference)"), dims);
}

ShapeError compareShapes(const MassGrid& clay, int32_t threshold, const Shape& reference, int dims)
{
    checkArgs("compareShapes", threshold, dims);
    auto ref = openvdb::MaskGrid::create(false);
    auto acc = ref->getAccessor();
    shapes_internal::forEachVoxelInside(
        reference, dims, [&](int32_t x, int32_t y, int32_t z) { acc.setValueOn(Coord(x, y, z)); });
    return compareSets(*occupiedSet(clay, threshold, dims, "compareShapes"), *ref, dims);
}

} // namespace vdbclay
