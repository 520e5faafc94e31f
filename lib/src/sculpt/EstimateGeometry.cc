// The estimate's geometry (EstimateGeometry.h): boxes, tightened bounds, tools' sweeps.
#include "sculpt/EstimateGeometry.h"

#include <algorithm>
#include <array>
#include <climits>
#include <cmath>
#include <utility>

namespace vdbclay {
namespace memory_internal {

using frame_policy::growBox;

int64_t leafIndex(int32_t v, int log2)
{
    return int64_t(v) >> log2;
}

uint64_t nodesIn(const Box& b, int log2)
{
    if (b.empty()) return 0;
    uint64_t n = 1;
    for (int a = 0; a < 3; ++a)
        n *= uint64_t(leafIndex(b.max[a], log2) - leafIndex(b.min[a], log2) + 1);
    return n;
}
uint64_t voxelsIn(const Box& b)
{
    if (b.empty()) return 0;
    uint64_t n = 1;
    for (int a = 0; a < 3; ++a)
        n *= uint64_t(int64_t(b.max[a]) - int64_t(b.min[a]) + 1);
    return n;
}
Box clip2D(Box b, int dims)
{
    if (dims == 2) {
        b.min[2] = std::max(b.min[2], 0);
        b.max[2] = std::min(b.max[2], 0);
    }
    return b;
}
/// tighten()'s lattice on a large face.
constexpr uint64_t kFaceLattice = 8, kFaceSamples = 1 + (kFaceLattice + 1) * (kFaceLattice + 1);
Box tighten(const Shape& shape, Box b, int dims, uint64_t& budget)
{
    auto inside = [&](int64_t x, int64_t y, int64_t z) {
        --budget;
        return shape.distance(Vec3{{double(x), double(y), double(z)}}) < 0;
    };
    auto anyInside = [&](const Box& face, bool sample) {
        auto at = [&](int a, uint64_t i, uint64_t n) { // point i of n + 1 spread over the face's axis a
            return int64_t(face.min[a]) + int64_t(uint64_t(int64_t(face.max[a]) - face.min[a]) * i / n);
        };
        if (sample) {
            if (inside(at(0, 1, 2), at(1, 1, 2), at(2, 1, 2))) return true;
            // The face is flat along one axis; the lattice spans the others (2D: one, z = 0 is flat too).
            int free[2] = {-1, -1}, nFree = 0;
            for (int a = 0; a < 3; ++a)
                if (face.min[a] != face.max[a] && nFree < 2) free[nFree++] = a;
            for (uint64_t i = 0; i <= kFaceLattice; ++i)
                for (uint64_t j = 0; j <= (nFree == 2 ? kFaceLattice : 0); ++j) {
                    int64_t c[3] = {face.min[0], face.min[1], face.min[2]};
                    if (nFree > 0) c[free[0]] = at(free[0], i, kFaceLattice);
                    if (nFree > 1) c[free[1]] = at(free[1], j, kFaceLattice);
                    if (inside(c[0], c[1], c[2])) return true;
                }
        }
        for (int64_t x = face.min[0]; x <= face.max[0]; ++x)
            for (int64_t y = face.min[1]; y <= face.max[1]; ++y)
                for (int64_t z = face.min[2]; z <= face.max[2]; ++z)
                    if (inside(x, y, z)) return true;
        return false;
    };
    for (int a = 0; a < (dims == 2 ? 2 : 3); ++a) {
        for (int side = 0; side < 2; ++side) {
            for (int k = 0; k < 4 && b.min[a] < b.max[a]; ++k) {
                Box face = b;
                if (side == 0)
                    face.max[a] = b.min[a];
                else
                    face.min[a] = b.max[a];
                const uint64_t n = voxelsIn(face);
                const bool sample = n > 4 * kFaceSamples;
                if (n > budget || (sample && budget - n < kFaceSamples) || anyInside(face, sample)) break;
                if (side == 0)
                    ++b.min[a];
                else
                    --b.max[a];
            }
        }
    }
    return b;
}

uint64_t voxelsInsideShape(const Shape& shape, const Box& b, uint64_t& budget)
{
    const uint64_t all = voxelsIn(b);
    if (b.empty() || nodesIn(b, 3) > budget) return all;
    uint64_t in = 0;
    const Box start = b;
    for (int64_t x = int64_t(b.min[0]) & ~int64_t(7); x <= b.max[0]; x += 8)
        for (int64_t y = int64_t(b.min[1]) & ~int64_t(7); y <= b.max[1]; y += 8)
            for (int64_t z = int64_t(b.min[2]) & ~int64_t(7); z <= b.max[2]; z += 8) {
                const Box leaf = intersect(start, Box{{{int32_t(x), int32_t(y), int32_t(z)}},
                                                      {{int32_t(x + 7), int32_t(y + 7), int32_t(z + 7)}}});
                if (budget == 0) return all;
                --budget;
                const double d = shape.distance(Vec3{{double(x) + 3.5, double(y) + 3.5, double(z) + 3.5}});
                if (d >= 6.07) continue; // no voxel centre of the leaf inside (3.5 sqrt 3 = 6.06)
                if (d <= -6.07) {
                    in += voxelsIn(leaf);
                    continue;
                }
                if (budget < voxelsIn(leaf)) return all;
                budget -= voxelsIn(leaf);
                for (int64_t vx = leaf.min[0]; vx <= leaf.max[0]; ++vx)
                    for (int64_t vy = leaf.min[1]; vy <= leaf.max[1]; ++vy)
                        for (int64_t vz = leaf.min[2]; vz <= leaf.max[2]; ++vz)
                            in += shape.distance(Vec3{{double(vx), double(vy), double(vz)}}) < 0 ? 1 : 0;
            }
    return in;
}

bool touches(const Box& a, const Box& b)
{
    return !intersect(a, b).empty();
}

uint64_t distinctNodes(const std::vector<Box>& boxes, int log2)
{
    uint64_t sum = 0;
    Box all;
    for (const Box& b : boxes) {
        sum += nodesIn(b, log2);
        all = unite(all, b);
    }
    if (sum > (uint64_t(1) << 20)) return std::min(sum, nodesIn(all, log2));
    std::vector<std::array<int64_t, 3>> keys;
    keys.reserve(size_t(sum));
    for (const Box& b : boxes) {
        if (b.empty()) continue;
        for (int64_t x = leafIndex(b.min[0], log2); x <= leafIndex(b.max[0], log2); ++x)
            for (int64_t y = leafIndex(b.min[1], log2); y <= leafIndex(b.max[1], log2); ++y)
                for (int64_t z = leafIndex(b.min[2], log2); z <= leafIndex(b.max[2], log2); ++z)
                    keys.push_back({{x, y, z}});
    }
    std::sort(keys.begin(), keys.end());
    return uint64_t(std::unique(keys.begin(), keys.end()) - keys.begin());
}

std::vector<std::vector<size_t>> groupsOfTouching(const std::vector<Box>& boxes)
{
    std::vector<size_t> parent(boxes.size());
    for (size_t i = 0; i < parent.size(); ++i)
        parent[i] = i;
    auto root = [&](size_t i) {
        while (parent[i] != i)
            i = parent[i] = parent[parent[i]];
        return i;
    };
    // Pairwise: beyond 4000 boxes (16 million pairs) they are taken as one group.
    for (size_t i = 0; i < boxes.size(); ++i)
        for (size_t j = i + 1; j < boxes.size(); ++j)
            if (boxes.size() > 4000 || touches(boxes[i], boxes[j])) parent[root(j)] = root(i);
    std::vector<std::vector<size_t>> groups(boxes.size());
    for (size_t i = 0; i < boxes.size(); ++i)
        groups[root(i)].push_back(i);
    groups.erase(
        std::remove_if(groups.begin(), groups.end(), [](const std::vector<size_t>& g) { return g.empty(); }),
        groups.end());
    return groups;
}

uint64_t unionLeaves(const std::vector<Box>& boxes)
{
    struct LeafBox {
        int64_t lo[3], hi[3]; // half-open, in leaves
    };
    std::vector<LeafBox> lb;
    Box all;
    for (const Box& b : boxes) {
        if (b.empty()) continue;
        all = unite(all, b);
        LeafBox l;
        for (int a = 0; a < 3; ++a) {
            l.lo[a] = leafIndex(b.min[a], 3);
            l.hi[a] = leafIndex(b.max[a], 3) + 1;
        }
        lb.push_back(l);
    }
    if (lb.size() > 40) return distinctNodes(boxes, 3);
    std::vector<int64_t> cuts[3];
    for (int a = 0; a < 3; ++a) {
        for (const LeafBox& l : lb) {
            cuts[a].push_back(l.lo[a]);
            cuts[a].push_back(l.hi[a]);
        }
        std::sort(cuts[a].begin(), cuts[a].end());
        cuts[a].erase(std::unique(cuts[a].begin(), cuts[a].end()), cuts[a].end());
    }
    uint64_t n = 0;
    for (size_t i = 0; i + 1 < cuts[0].size(); ++i)
        for (size_t j = 0; j + 1 < cuts[1].size(); ++j)
            for (size_t k = 0; k + 1 < cuts[2].size(); ++k) {
                const int64_t c[3] = {cuts[0][i], cuts[1][j], cuts[2][k]};
                const bool in = std::any_of(lb.begin(), lb.end(), [&](const LeafBox& l) {
                    return l.lo[0] <= c[0] && c[0] < l.hi[0] && l.lo[1] <= c[1] && c[1] < l.hi[1] &&
                           l.lo[2] <= c[2] && c[2] < l.hi[2];
                });
                if (in) {
                    n += uint64_t(cuts[0][i + 1] - c[0]) * uint64_t(cuts[1][j + 1] - c[1]) *
                         uint64_t(cuts[2][k + 1] - c[2]);
                }
            }
    return n;
}

namespace {

/// Whether @a x is a multiple of 2^-20 below 2^30 in magnitude: sums and differences of such values
/// and of voxel coordinates (below 2^31) are exact in a double.
bool exactCoordinate(double x)
{
    const double s = std::ldexp(x, 20);
    return std::abs(x) < 1073741824.0 && s == std::floor(s);
}

/// Whether pose @a b is pose @a a moved by a whole number of voxels @a d (same rotation, same pivot,
/// exact coordinates): a shape placed at @a b then holds exactly the voxels it holds at @a a, moved by
/// @a d (Shapes.cc: a transformed shape's distance at p is the inner shape's at R^T (p - t - c) + c,
/// which for p + d and t + d is the same double; a pose that is the identity uses the shape itself,
/// the same only with no rotation at all).
bool wholeVoxelMove(const Pose& a, const Pose& b, int dims, int64_t d[3])
{
    const bool identity = a.isIdentity() || b.isIdentity();
    for (int i = 0; i < 3; ++i) {
        if (a.rotationDeg[i] != b.rotationDeg[i] || a.pivot[i] != b.pivot[i]) return false;
        if (identity && a.rotationDeg[i] != 0.0) return false;
        if (!exactCoordinate(a.translation[i]) || !exactCoordinate(b.translation[i]) ||
            !exactCoordinate(a.pivot[i]))
            return false;
        const double diff = b.translation[i] - a.translation[i];
        if (diff != std::floor(diff)) return false;
        d[i] = int64_t(diff);
    }
    return dims == 3 || d[2] == 0;
}

/// The voxels of @a b (a shape's tightened bounds) inside @a shape (2D: @a b is clipped to z = 0),
/// counted while @a budget lasts; voxelsIn(@a b) when it does not.
uint64_t voxelsInside(const Shape& shape, const Box& b, uint64_t& budget)
{
    const uint64_t n = voxelsIn(b);
    if (n > budget) return n;
    budget -= n;
    uint64_t in = 0;
    for (int64_t x = b.min[0]; x <= b.max[0]; ++x)
        for (int64_t y = b.min[1]; y <= b.max[1]; ++y)
            for (int64_t z = b.min[2]; z <= b.max[2]; ++z)
                in += shape.distance(Vec3{{double(x), double(y), double(z)}}) < 0 ? 1 : 0;
    return in;
}

} // namespace

ToolSweep sweep(const ToolSpec& tool, uint64_t frames, int dims, bool countInside, uint64_t& budget)
{
    const uint64_t end = std::min(frames, tool.pathFrames()); // then the tool stays where it is
    ToolSweep out;
    bool sampled = false;
    struct Tightened {
        Pose pose;
        Box box;
        uint64_t inside;
    };
    std::vector<Tightened> tightened; // poses tightened (at most 16: a short search)
    Box last;
    auto at = [&](uint64_t f) {
        const Pose pose = tool.poseAt(f);
        Box b;
        uint64_t inside = 0;
        bool moved = false;
        for (const Tightened& t : tightened) {
            int64_t d[3];
            if (!wholeVoxelMove(t.pose, pose, dims, d)) continue;
            b = t.box;
            for (int a = 0; a < 3 && !b.empty(); ++a) {
                b.min[a] = int32_t(std::max<int64_t>(INT32_MIN, int64_t(b.min[a]) + d[a]));
                b.max[a] = int32_t(std::min<int64_t>(INT32_MAX, int64_t(b.max[a]) + d[a]));
            }
            inside = t.inside;
            moved = true;
            break;
        }
        if (!moved) {
            const ShapePtr s = makeTransformed(tool.shape.shape, pose);
            b = tighten(*s, clip2D(s->bounds(), dims), dims, budget);
            inside = countInside ? voxelsInside(*s, b, budget) : voxelsIn(b);
            if (tightened.size() < 16) tightened.push_back({pose, b, inside});
        }
        out.all = unite(out.all, b);
        out.most = std::max(out.most, voxelsIn(b));
        out.inside = std::max(out.inside, inside);
        if (!b.empty()) {
            uint64_t side[3];
            for (int a = 0; a < 3; ++a)
                side[a] = uint64_t(int64_t(b.max[a]) - b.min[a] + 1);
            out.face = std::max(
                out.face, dims == 2 ? std::max(side[0], side[1])
                                    : std::max({side[0] * side[1], side[1] * side[2], side[0] * side[2]}));
        }
        out.slotsMost = std::max(out.slotsMost, nodesIn(unite(last, b), 3));
        last = b;
        if (!sampled) out.frames.push_back(b);
    };
    const uint64_t stride = std::max<uint64_t>(1, end / 100000);
    for (uint64_t f = 0; f <= end; f += stride)
        at(f);
    if (stride > 1) {
        out.frames.clear();
        sampled = true;
        uint64_t f = 0;
        for (const PathSegment& seg : tool.path) {
            f += seg.frames;
            if (f <= end) at(f);
        }
        at(end);
    }
    return out;
}

Box neighbourhood(Box b, bool neighbours, int dims)
{
    if (!neighbours || b.empty()) return b;
    for (int a = 0; a < (dims == 2 ? 2 : 3); ++a) {
        b.min[a] = int32_t(std::max<int64_t>(INT32_MIN, int64_t(b.min[a]) - 8));
        b.max[a] = int32_t(std::min<int64_t>(INT32_MAX, int64_t(b.max[a]) + 4));
    }
    return b;
}

} // namespace memory_internal
} // namespace vdbclay
