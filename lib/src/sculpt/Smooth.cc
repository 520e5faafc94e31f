// Surface tension (Smooth.h): convex surface voxels hand their clay to concave ones nearby (the
// threshold step), then pairs of face neighbours inside a region exchange clay, from the less
// sheltered voxel to the more sheltered one (the exchange step). Both read the shelters of the
// clay's solid shape (its voxels at or over Tc/2). The region's masses are copied into a dense
// block (the region grown by two voxels, read once through accessors), the passes run on it, and the voxels
// that changed are written back through Automaton::setMasses over their bounds. The shelters and the
// surface marks are computed over the block once; after each step (the threshold step, each exchange
// sub-pass) only the neighbourhoods of the voxels it changed are brought up to date (refresh), which
// gives exactly what recomputing them over the block would: the work of a pass follows the block once
// and the clay that moves, not the block seven times over.
#include "vdbclay/Smooth.h"
#include "sculpt/SmoothInternal.h"
#include "vdbclay/Automaton.h"

#include <openvdb/openvdb.h>

#include <algorithm>
#include <array>
#include <cmath>
#include <cstdlib>
#include <memory>
#include <string>

namespace vdbclay {

namespace {

using openvdb::Coord;

constexpr int64_t kFace = 6, kEdge = 3, kCorner = 2;

/// Weight of neighbour offset (dx, dy, dz) (not all 0) in surfaceEnergy.
inline int64_t weight(int dx, int dy, int dz)
{
    const int n = (dx != 0) + (dy != 0) + (dz != 0);
    return n == 1 ? kFace : n == 2 ? kEdge : kCorner;
}

/// The shelter's kernel along one axis: (1 2 3 2 1), so a voxel's shelter weighs the fills of its
/// 5^3 neighbourhood (5^2 in 2D) by the product of these, its own fill left out.
constexpr int64_t kTent[5] = {1, 2, 3, 2, 1};
constexpr int kReach = smooth_internal::kShelterReach;

/// A dense copy of a box grown by kReach voxels, the shelters' reach (2D: in x and y only).
struct Block {
    Box inner, outer;
    int64_t nx = 0, ny = 0, nz = 0;
    bool is2D = false;
    std::vector<int64_t> mass;  ///< clay (outer box)
    std::vector<char> obstacle; ///< half full in the shelters, never changes
    std::vector<char> member;   ///< may change (inner box only)
    std::vector<int32_t> part;  ///< the member voxels' connected part (face neighbours), -1 elsewhere

    Block(const Box& region, bool twoD) : inner(region), outer(region), is2D(twoD)
    {
        for (int i = 0; i < 3; ++i) {
            if (twoD && i == 2) continue;
            outer.min[i] -= kReach;
            outer.max[i] += kReach;
        }
        nx = int64_t(outer.max[0]) - outer.min[0] + 1;
        ny = int64_t(outer.max[1]) - outer.min[1] + 1;
        nz = int64_t(outer.max[2]) - outer.min[2] + 1;
        const size_t n = size_t(nx * ny * nz);
        mass.assign(n, 0);
        obstacle.assign(n, 0);
        member.assign(n, 0);
        part.assign(n, -1);
    }
    int64_t index(int64_t x, int64_t y, int64_t z) const
    {
        return ((x - outer.min[0]) * ny + (y - outer.min[1])) * nz + (z - outer.min[2]);
    }
};

/// Whether the shelters read the voxel at index @a k as filled (fillOf above 0): an obstacle, or a
/// voxel of the clay's solid shape (holding at least Tc/2).
inline bool filled(const Block& b, int64_t tc, size_t k)
{
    return b.obstacle[k] || 2 * b.mass[k] >= tc;
}

/// A voxel's fill as the shelters read it: the clay's solid shape, Tc for a voxel holding at least
/// Tc/2 and 0 for one holding less (a film of clay under Tc/2 on a face does not shelter its
/// neighbours, so it neither gathers into lumps nor makes the face look concave), Tc/2 for an
/// obstacle.
inline int64_t fillOf(const Block& b, int64_t tc, size_t k)
{
    if (!filled(b, tc, k)) return 0;
    return b.obstacle[k] ? tc / 2 : tc;
}

/// Every voxel's shelter (@a g, over the outer box): the tent-weighted fills (fillOf) of its
/// neighbourhood, its own left out. Separable: a pass along each axis, voxels beyond the outer box
/// empty.
void shelters(const Block& b, int64_t tc, std::vector<int64_t>& g, std::vector<int64_t>& tmp)
{
    const size_t n = b.mass.size();
    g.resize(n);
    tmp.resize(n);
    for (size_t k = 0; k < n; ++k)
        g[k] = fillOf(b, tc, k);
    const std::vector<int64_t> fill = g;
    const int64_t dimsN[3] = {b.nx, b.ny, b.nz};
    const int64_t stride[3] = {b.ny * b.nz, b.nz, 1};
    for (int axis = 0; axis < (b.is2D ? 2 : 3); ++axis) {
        for (int64_t x = 0; x < b.nx; ++x)
            for (int64_t y = 0; y < b.ny; ++y)
                for (int64_t z = 0; z < b.nz; ++z) {
                    const int64_t c[3] = {x, y, z};
                    const int64_t k = (x * b.ny + y) * b.nz + z;
                    int64_t sum = 0;
                    for (int d = -kReach; d <= kReach; ++d) {
                        const int64_t at = c[axis] + d;
                        if (at < 0 || at >= dimsN[axis]) continue;
                        sum += kTent[d + kReach] * g[size_t(k + d * stride[axis])];
                    }
                    tmp[size_t(k)] = sum;
                }
        g.swap(tmp);
    }
    const int64_t self =
        b.is2D ? kTent[kReach] * kTent[kReach] : kTent[kReach] * kTent[kReach] * kTent[kReach];
    for (size_t k = 0; k < n; ++k)
        g[k] -= self * fill[k];
}

/// Labels the member voxels' connected parts (face neighbours, in index order): clay moves between
/// voxels of one part only, so it never crosses an obstacle, a solid or the region's edge.
void label(Block& b)
{
    const int64_t stride[3] = {b.ny * b.nz, b.nz, 1};
    const int64_t dimsN[3] = {b.nx, b.ny, b.nz};
    std::vector<int64_t> stack;
    int32_t parts = 0;
    for (size_t k = 0; k < b.member.size(); ++k) {
        if (!b.member[k] || b.part[k] >= 0) continue;
        b.part[k] = parts;
        stack.assign(1, int64_t(k));
        while (!stack.empty()) {
            const int64_t p = stack.back();
            stack.pop_back();
            const int64_t c[3] = {p / stride[0], (p / stride[1]) % b.ny, p % b.nz};
            for (int axis = 0; axis < 3; ++axis)
                for (const int d : {-1, 1}) {
                    if (c[axis] + d < 0 || c[axis] + d >= dimsN[axis]) continue;
                    const int64_t q = p + d * stride[axis];
                    if (!b.member[size_t(q)] || b.part[size_t(q)] >= 0) continue;
                    b.part[size_t(q)] = parts;
                    stack.push_back(q);
                }
        }
        ++parts;
    }
}

/// The shelters of the voxels on either side of a flat face of the clay (the tent's half-sums: 1+2+3
/// inside, 1+2 outside, the other axes' 9 each, the voxel's own 3^dims left out). A voxel of the
/// clay with a lower shelter than @a in is more convex than a flat face; a voxel outside the clay
/// with a higher one than @a out is more concave, one with a lower one more convex.
struct FlatFace {
    int64_t in = 0, out = 0;
};
FlatFace flatFace(const Block& b, int64_t tc)
{
    const int64_t across = b.is2D ? 9 : 81, self = b.is2D ? 9 : 27;
    return FlatFace{tc * (across * 6 - self), tc * across * 3};
}

/// How far (voxels, along each axis) a surface voxel's clay may go in one threshold step: far enough
/// to reach from a bump's or terrace's convex edge to the crease at its foot. Measured (TestSmooth,
/// 8 passes): reach 2 takes 70.9 % of the full-cell bumps' excess roughness and 54.9 % of the
/// terraced top's, reach 4 71.8 % and 60.6 %; a match over the whole connected part (any reach)
/// 71.8 % and 65.3 %, but it carries clay across the whole region in one step.
constexpr int kSwapReach = 4;

/// The threshold step (file comment): the voxels of the clay's surface holding at least Tc/2 (and at
/// most Tc) that are more convex than a flat face give their clay, least sheltered first, then the
/// voxels of its surface under Tc/2 holding clay that are more convex than a flat face, least
/// sheltered first; each gives to the most sheltered voxel under Tc/2 on the surface within
/// kSwapReach of it, more concave than a flat face, of its connected part, not yet chosen, and more
/// sheltered without the giver's own fill than the giver. A pair whose giver holds at least Tc/2
/// keeps one voxel at or over Tc/2, so it keeps the volume.
int64_t swapSurface(Block& b, int64_t tc, const std::vector<int64_t>& g, std::vector<int64_t>& changed)
{
    const int64_t stride[3] = {b.ny * b.nz, b.nz, 1};
    const int64_t dimsN[3] = {b.nx, b.ny, b.nz};
    const int axes = b.is2D ? 2 : 3;
    std::vector<char> taker(b.mass.size(), 0);
    // Only a voxel more convex than a flat face gives and only one more concave receives, so a flat
    // face keeps its voxels, and a film on it stays where it is.
    const FlatFace flat = flatFace(b, tc);
    std::vector<int64_t> givers;
    for (size_t k = 0; k < b.member.size(); ++k) {
        if (!b.member[k]) continue;
        const bool in = filled(b, tc, k);
        if (in && b.mass[k] > tc) continue; // an overloaded voxel is left to the automaton
        const int64_t c[3] = {int64_t(k) / stride[0], (int64_t(k) / stride[1]) % b.ny, int64_t(k) % b.nz};
        bool edge = false;
        for (int axis = 0; axis < axes && !edge; ++axis)
            for (const int d : {-1, 1}) {
                if (c[axis] + d < 0 || c[axis] + d >= dimsN[axis]) continue;
                if (filled(b, tc, size_t(int64_t(k) + d * stride[axis])) != in) edge = true;
            }
        if (!edge) continue;
        if (in ? g[k] < flat.in : g[k] < flat.out && b.mass[k] > 0)
            givers.push_back(int64_t(k));
        else if (!in && g[k] > flat.out)
            taker[k] = 1;
    }
    // Whole voxels first, then the film's clay into the creases they leave.
    std::sort(givers.begin(), givers.end(), [&](int64_t x, int64_t y) {
        const bool inX = filled(b, tc, size_t(x)), inY = filled(b, tc, size_t(y));
        if (inX != inY) return inX;
        return g[size_t(x)] != g[size_t(y)] ? g[size_t(x)] < g[size_t(y)] : x < y;
    });
    const int rz = b.is2D ? 0 : kSwapReach;
    int64_t moved = 0;
    for (const int64_t p : givers) {
        const int64_t c[3] = {p / stride[0], (p / stride[1]) % b.ny, p % b.nz};
        int64_t best = -1;
        for (int dx = -kSwapReach; dx <= kSwapReach; ++dx)
            for (int dy = -kSwapReach; dy <= kSwapReach; ++dy)
                for (int dz = -rz; dz <= rz; ++dz) {
                    const int64_t x = c[0] + dx, y = c[1] + dy, z = c[2] + dz;
                    if (x < 0 || y < 0 || z < 0 || x >= b.nx || y >= b.ny || z >= b.nz) continue;
                    const int64_t q = p + dx * stride[0] + dy * stride[1] + dz * stride[2];
                    if (!taker[size_t(q)] || b.part[size_t(q)] != b.part[size_t(p)]) continue;
                    // The giver's own fill leaves the taker's shelter with it: a move that only
                    // rolls a bump or a step over its own foot gains nothing and is not made.
                    int64_t own = 0;
                    if (std::abs(dx) <= kReach && std::abs(dy) <= kReach && std::abs(dz) <= kReach)
                        own = kTent[dx + kReach] * kTent[dy + kReach] * (b.is2D ? 1 : kTent[dz + kReach]);
                    if (g[size_t(q)] - own * fillOf(b, tc, size_t(p)) <= g[size_t(p)]) continue;
                    if (best < 0 || g[size_t(q)] > g[size_t(best)]) best = q;
                }
        if (best < 0) continue;
        taker[size_t(best)] = 0;
        changed.push_back(p);
        changed.push_back(best);
        int64_t& from = b.mass[size_t(p)];
        int64_t& to = b.mass[size_t(best)];
        const int64_t t = std::min(from, tc - to);
        from -= t;
        to += t;
        moved += t;
    }
    return moved;
}

/// Whether the voxel at index @a k (coordinates @a c in the block) has a face neighbour under Tc/2
/// that is not an obstacle: a voxel of the clay's surface, the only voxels the exchange step fills,
/// so clay under Tc inside is not packed.
bool opensOnto(const Block& b, int64_t tc, int64_t k, const int64_t c[3])
{
    const int64_t stride[3] = {b.ny * b.nz, b.nz, 1};
    const int64_t dimsN[3] = {b.nx, b.ny, b.nz};
    for (int axis = 0; axis < (b.is2D ? 2 : 3); ++axis)
        for (const int d : {-1, 1}) {
            if (c[axis] + d < 0 || c[axis] + d >= dimsN[axis]) continue;
            const size_t q = size_t(k + d * stride[axis]);
            if (!filled(b, tc, q)) return true;
        }
    return false;
}

/// Marks (@a open) the voxels of the clay's surface (opensOnto).
void surface(const Block& b, int64_t tc, std::vector<char>& open)
{
    open.assign(b.mass.size(), 0);
    for (int64_t x = 0; x < b.nx; ++x)
        for (int64_t y = 0; y < b.ny; ++y)
            for (int64_t z = 0; z < b.nz; ++z) {
                const int64_t c[3] = {x, y, z};
                const int64_t k = (x * b.ny + y) * b.nz + z;
                open[size_t(k)] = opensOnto(b, tc, k, c);
            }
}

/// After voxels @a changed (block indices, a voxel possibly listed twice) changed their mass: brings
/// the shelters @a g (computed from the fills @a fill) and the surface marks @a open up to date, as
/// shelters() and surface() over the whole block would give. A voxel's fill enters its
/// neighbours' shelters linearly, so a change of fill adds its tent weight times the change to each
/// of its 5^3 neighbours (5^2 in 2D); a voxel's mark reads its face neighbours' masses. The work
/// follows the voxels changed, not the block.
void refresh(const Block& b, int64_t tc, std::vector<int64_t>& g, std::vector<int64_t>& fill,
             std::vector<char>& open, std::vector<int64_t>& changed)
{
    const int64_t stride[3] = {b.ny * b.nz, b.nz, 1};
    const int64_t dimsN[3] = {b.nx, b.ny, b.nz};
    const int rz = b.is2D ? 0 : kReach;
    for (const int64_t k : changed) {
        const int64_t c[3] = {k / stride[0], (k / stride[1]) % b.ny, k % b.nz};
        const int64_t f = fillOf(b, tc, size_t(k));
        const int64_t df = f - fill[size_t(k)];
        fill[size_t(k)] = f;
        if (df != 0) {
            for (int dx = -kReach; dx <= kReach; ++dx)
                for (int dy = -kReach; dy <= kReach; ++dy)
                    for (int dz = -rz; dz <= rz; ++dz) {
                        if (!dx && !dy && !dz) continue;
                        const int64_t x = c[0] + dx, y = c[1] + dy, z = c[2] + dz;
                        if (x < 0 || y < 0 || z < 0 || x >= b.nx || y >= b.ny || z >= b.nz) continue;
                        const int64_t w =
                            kTent[dx + kReach] * kTent[dy + kReach] * (b.is2D ? 1 : kTent[dz + kReach]);
                        g[size_t(k + dx * stride[0] + dy * stride[1] + dz * stride[2])] += w * df;
                    }
        }
        for (int axis = 0; axis < (b.is2D ? 2 : 3); ++axis)
            for (const int d : {-1, 1}) {
                if (c[axis] + d < 0 || c[axis] + d >= dimsN[axis]) continue;
                int64_t n[3] = {c[0], c[1], c[2]};
                n[axis] += d;
                const int64_t q = k + d * stride[axis];
                open[size_t(q)] = opensOnto(b, tc, q, n);
            }
    }
    changed.clear();
}

/// The passes on @a b's block; returns what they did and the cells they changed, unwritten.
smooth_internal::Smoothed run(const Automaton& automaton, Block& b, double strength, int passes)
{
    const int64_t tc = automaton.options().rule.threshold;
    const std::vector<int64_t> before = b.mass;
    std::vector<int64_t> g, tmp;
    std::vector<char> open;
    const Box& in = b.inner;
    const int axes = b.is2D ? 2 : 3;
    const FlatFace flat = flatFace(b, tc);
    // Twice a face neighbour's weight: strength 1 evens the shelters of a pair in one exchange.
    const int64_t divisor =
        2 * (b.is2D ? kTent[kReach] * kTent[kReach + 1] : kTent[kReach] * kTent[kReach] * kTent[kReach + 1]);
    label(b);
    // The shelters and the surface marks once; then each step's changes update them (refresh), so
    // each sub-pass reads them as computed from the masses at its start.
    shelters(b, tc, g, tmp);
    surface(b, tc, open);
    std::vector<int64_t> fill(b.mass.size()), changed;
    for (size_t k = 0; k < fill.size(); ++k)
        fill[k] = fillOf(b, tc, k);
    for (int pass = 0; pass < passes; ++pass) {
        swapSurface(b, tc, g, changed);
        refresh(b, tc, g, fill, open, changed);
        for (int axis = 0; axis < axes; ++axis)
            for (int parity = 0; parity < 2; ++parity) {
                const int64_t step = axis == 0 ? b.ny * b.nz : axis == 1 ? b.nz : 1;
                for (int64_t x = in.min[0]; x <= in.max[0]; ++x)
                    for (int64_t y = in.min[1]; y <= in.max[1]; ++y)
                        for (int64_t z = in.min[2]; z <= in.max[2]; ++z) {
                            const int64_t c[3] = {x, y, z};
                            if (((c[axis] % 2) + 2) % 2 != parity || c[axis] >= in.max[axis]) continue;
                            const size_t p = size_t(b.index(x, y, z)), q = size_t(int64_t(p) + step);
                            if (!b.member[p] || !b.member[q]) continue;
                            const int64_t d = g[q] - g[p];
                            if (d == 0) continue;
                            const size_t from = d > 0 ? p : q, to = d > 0 ? q : p;
                            if (!open[to]) continue; // clay inside is not packed
                            int64_t t =
                                int64_t(std::floor(strength * double(std::llabs(d)) / double(divisor)));
                            t = std::min(t, b.mass[from]);
                            t = std::min(t, std::max<int64_t>(0, tc - b.mass[to]));
                            // The solid shape grows only where it is concave and shrinks only
                            // where it is convex: a film under Tc/2 does not gather into voxels
                            // over it on a flat face, nor does a flat face thin below it.
                            if (!filled(b, tc, to) && g[to] <= flat.out)
                                t = std::min(t, (tc - 1) / 2 - b.mass[to]);
                            if (filled(b, tc, from) && g[from] >= flat.in)
                                t = std::min(t, b.mass[from] - (tc + 1) / 2);
                            if (t <= 0) continue;
                            b.mass[from] -= t;
                            b.mass[to] += t;
                            changed.push_back(int64_t(from));
                            changed.push_back(int64_t(to));
                        }
                refresh(b, tc, g, fill, open, changed);
            }
    }
    smooth_internal::Smoothed out;
    SmoothReport& r = out.report;
    std::vector<Automaton::CellMass>& cells = out.cells;
    r.visited = b.mass.size();
    for (int64_t x = in.min[0]; x <= in.max[0]; ++x)
        for (int64_t y = in.min[1]; y <= in.max[1]; ++y)
            for (int64_t z = in.min[2]; z <= in.max[2]; ++z) {
                const size_t k = size_t(b.index(x, y, z));
                if (b.mass[k] == before[k]) continue;
                const std::array<int32_t, 3> at{{int32_t(x), int32_t(y), int32_t(z)}};
                cells.push_back(Automaton::CellMass{at, int32_t(b.mass[k])});
                r.region = unite(r.region, Box{at, at});
                if (b.mass[k] > before[k]) r.massMoved += b.mass[k] - before[k];
            }
    r.voxels = cells.size();
    return out;
}

void check(double strength, int passes)
{
    if (!(strength > 0 && strength <= kMaxSmoothStrength))
        throw Error("smooth: the strength must lie in (0, 1], got " + std::to_string(strength));
    if (passes < 1) throw Error("smooth: passes must be >= 1, got " + std::to_string(passes));
}

/// Reads the masses and obstacles of @a b's outer box; @a inside decides membership of the inner
/// voxels that are not obstacles.
template <typename Inside> void load(const Automaton& automaton, Block& b, Inside&& inside)
{
    auto acc = automaton.mass()->getConstAccessor();
    std::unique_ptr<openvdb::tree::ValueAccessor<const ObstacleGrid::TreeType>> oacc;
    if (const ObstacleGridPtr& obs = automaton.obstacles())
        oacc = std::make_unique<openvdb::tree::ValueAccessor<const ObstacleGrid::TreeType>>(obs->constTree());
    const Box& o = b.outer;
    for (int64_t x = o.min[0]; x <= o.max[0]; ++x)
        for (int64_t y = o.min[1]; y <= o.max[1]; ++y)
            for (int64_t z = o.min[2]; z <= o.max[2]; ++z) {
                const Coord c{int32_t(x), int32_t(y), int32_t(z)};
                const size_t k = size_t(b.index(x, y, z));
                b.mass[k] = acc.getValue(c);
                const bool obstacle = oacc && oacc->isValueOn(c);
                b.obstacle[k] = obstacle;
                const bool inner = x >= b.inner.min[0] && x <= b.inner.max[0] && y >= b.inner.min[1] &&
                                   y <= b.inner.max[1] && z >= b.inner.min[2] && z <= b.inner.max[2];
                if (inner && !obstacle) b.member[k] = inside(c);
                if (!inner || b.member[k]) continue;
                if (!obstacle && !b.obstacle[k]) b.obstacle[k] = inside.solid(c);
            }
}

struct InsideTool {
    const Shape& tool;
    const std::vector<ShapePtr>& solids;
    static bool in(const Shape& s, const Coord& c)
    {
        const Box bb = s.bounds();
        if (c.x() < bb.min[0] || c.x() > bb.max[0] || c.y() < bb.min[1] || c.y() > bb.max[1] ||
            c.z() < bb.min[2] || c.z() > bb.max[2])
            return false;
        return s.distance(Vec3{{double(c.x()), double(c.y()), double(c.z())}}) < 0;
    }
    bool solid(const Coord& c) const
    {
        for (const ShapePtr& s : solids)
            if (in(*s, c)) return true;
        return false;
    }
    bool operator()(const Coord& c) const { return in(tool, c) && !solid(c); }
};

struct InsideRegion {
    const std::vector<ShapePtr>& solids;
    bool solid(const Coord& c) const
    {
        for (const ShapePtr& s : solids)
            if (InsideTool::in(*s, c)) return true;
        return false;
    }
    bool operator()(const Coord& c) const { return !solid(c); }
};

} // namespace

SmoothReport smooth(Automaton& automaton, const Shape& tool, double strength, int passes,
                    const std::vector<ShapePtr>& solids)
{
    check(strength, passes);
    const bool is2D = automaton.options().dimensions == 2;
    Box region = tool.bounds();
    if (is2D)
        region =
            intersect(region, Box{{{INT32_MIN / 2, INT32_MIN / 2, 0}}, {{INT32_MAX / 2, INT32_MAX / 2, 0}}});
    if (region.empty()) return SmoothReport();
    Block b(region, is2D);
    load(automaton, b, InsideTool{tool, solids});
    const smooth_internal::Smoothed s = run(automaton, b, strength, passes);
    smooth_internal::write(automaton, s);
    return s.report;
}

SmoothReport smoothRegion(Automaton& automaton, const Box& region, double strength, int passes,
                          const std::vector<ShapePtr>& solids)
{
    const smooth_internal::Smoothed s =
        smooth_internal::smoothedRegion(automaton, region, strength, passes, solids);
    smooth_internal::write(automaton, s);
    return s.report;
}

namespace smooth_internal {

Smoothed smoothedRegion(const Automaton& automaton, const Box& region, double strength, int passes,
                        const std::vector<ShapePtr>& solids)
{
    check(strength, passes);
    const bool is2D = automaton.options().dimensions == 2;
    Box r = region;
    if (is2D) r = intersect(r, Box{{{INT32_MIN / 2, INT32_MIN / 2, 0}}, {{INT32_MAX / 2, INT32_MAX / 2, 0}}});
    if (r.empty()) return Smoothed();
    Block b(r, is2D);
    load(automaton, b, InsideRegion{solids});
    return run(automaton, b, strength, passes);
}

void write(Automaton& automaton, const Smoothed& s)
{
    if (!s.cells.empty()) automaton.setMasses(s.report.region, s.cells);
}

} // namespace smooth_internal

int64_t surfaceEnergy(const MassGrid& mass, const Box& region, int32_t threshold, int dimensions)
{
    const bool is2D = dimensions == 2;
    Box r = region;
    if (is2D) r = intersect(r, Box{{{INT32_MIN / 2, INT32_MIN / 2, 0}}, {{INT32_MAX / 2, INT32_MAX / 2, 0}}});
    if (r.empty()) return 0;
    const int64_t tc = threshold;
    auto acc = mass.getConstAccessor();
    auto fill = [&](int64_t x, int64_t y, int64_t z) {
        return std::min<int64_t>(acc.getValue(Coord(int32_t(x), int32_t(y), int32_t(z))), tc);
    };
    const int dzr = is2D ? 0 : 1;
    int64_t total = 0;
    for (int64_t x = r.min[0]; x <= r.max[0]; ++x)
        for (int64_t y = r.min[1]; y <= r.max[1]; ++y)
            for (int64_t z = r.min[2]; z <= r.max[2]; ++z) {
                const int64_t f = fill(x, y, z);
                if (f <= 0) continue;
                for (int dx = -1; dx <= 1; ++dx)
                    for (int dy = -1; dy <= 1; ++dy)
                        for (int dz = -dzr; dz <= dzr; ++dz) {
                            if (!dx && !dy && !dz) continue;
                            total += weight(dx, dy, dz) * f * (tc - fill(x + dx, y + dy, z + dz));
                        }
            }
    return total / tc;
}

} // namespace vdbclay
