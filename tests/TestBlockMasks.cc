// The automaton's block-mask algebra (lib/src/BlockMasks.h) against brute force on coordinates:
// no OpenVDB in this translation unit.
#include "automaton/BlockMasks.h"

#include <gtest/gtest.h>

#include <algorithm>
#include <set>
#include <tuple>
#include <vector>

using namespace vdbclay::automaton_internal;

namespace {

using Corner = std::tuple<int, int, int>;

/// The minimum corners of the blocks in @a a (phase @a phase).
std::set<Corner> corners(const Anchor& a, int phase, bool d3)
{
    std::set<Corner> s;
    for (int b = 0; b < 64; ++b) {
        if (!((a.mask >> b) & 1u)) continue;
        const Origin o = blockOrigin(a.origin, b, phase, d3);
        s.emplace(o.x(), o.y(), o.z());
    }
    return s;
}

/// Brute force: every block of phase 1 - @a phase (minimum corner of that parity) sharing a cell
/// with a block in @a from. Blocks [o, o + 1] overlap when their corners differ by at most 1.
std::set<Corner> overlapping(const std::set<Corner>& from, int phase, bool d3)
{
    std::set<Corner> s;
    for (const Corner& c : from) {
        const int x = std::get<0>(c), y = std::get<1>(c), z = std::get<2>(c);
        for (int dx = -1; dx <= 1; ++dx)
            for (int dy = -1; dy <= 1; ++dy)
                for (int dz = d3 ? -1 : 0; dz <= (d3 ? 1 : 0); ++dz) {
                    const int ox = x + dx, oy = y + dy, oz = z + dz;
                    const int other = 1 - phase;
                    if (((ox & 1) != other) || ((oy & 1) != other) || (d3 && (oz & 1) != other)) continue;
                    s.emplace(ox, oy, d3 ? oz : 0);
                }
    }
    return s;
}

uint64_t xorshift(uint64_t& s)
{
    s ^= s << 13;
    s ^= s >> 7;
    s ^= s << 17;
    return s;
}

} // namespace

TEST(BlockMasks, BlockOriginsTileTheLeafInBothPhases)
{
    for (int d3 = 0; d3 < 2; ++d3) {
        for (int phase = 0; phase < 2; ++phase) {
            const Anchor a{Origin(-8, 16, d3 ? 8 : 0), fullMask(d3)};
            const std::set<Corner> s = corners(a, phase, d3);
            EXPECT_EQ(s.size(), d3 ? 64u : 16u);
            for (const Corner& c : s) {
                // The block's maximum corner lies in the anchor leaf.
                EXPECT_EQ((std::get<0>(c) + 1) & ~7, -8);
                EXPECT_EQ((std::get<1>(c) + 1) & ~7, 16);
                if (d3) {
                    EXPECT_EQ((std::get<2>(c) + 1) & ~7, 8);
                }
                EXPECT_EQ(std::get<0>(c) & 1, phase);
            }
        }
    }
}

TEST(BlockMasks, DilationAcrossThePhaseIsExactlyTheOverlappingBlocks)
{
    uint64_t rng = 12345;
    for (int d3 = 0; d3 < 2; ++d3) {
        for (int from = 0; from < 2; ++from) {
            for (int trial = 0; trial < 400; ++trial) {
                uint64_t mask = xorshift(rng) & xorshift(rng) & fullMask(d3);
                if (trial < 64) mask = (uint64_t(1) << trial) & fullMask(d3); // every single block
                if (!mask) continue;
                const Anchor a{Origin(8 * (int(xorshift(rng) % 5) - 2), 8 * (int(xorshift(rng) % 5) - 2),
                                      d3 ? 8 * (int(xorshift(rng) % 5) - 2) : 0),
                               mask};
                Anchor buf[8];
                int shift[8];
                const int n = dilateAcrossPhase(a, from, d3, buf, shift);
                std::set<Corner> got;
                for (int i = 0; i < n; ++i) {
                    EXPECT_NE(buf[i].mask, 0u);
                    EXPECT_EQ(buf[i].mask & ~fullMask(d3), 0u);
                    // shift[i] names the neighbour leaf buf[i] is anchored at.
                    const int sgn = from == 0 ? 8 : -8;
                    EXPECT_EQ(buf[i].origin.x(), a.origin.x() + ((shift[i] & 1) ? sgn : 0));
                    EXPECT_EQ(buf[i].origin.y(), a.origin.y() + ((shift[i] & 2) ? sgn : 0));
                    EXPECT_EQ(buf[i].origin.z(), a.origin.z() + ((shift[i] & 4) ? sgn : 0));
                    for (int j = 0; j < i; ++j)
                        EXPECT_NE(buf[i].origin, buf[j].origin);
                    const std::set<Corner> c = corners(buf[i], 1 - from, d3);
                    got.insert(c.begin(), c.end());
                }
                EXPECT_EQ(got, overlapping(corners(a, from, d3), from, d3)) << "mask " << mask;
            }
        }
    }
}

TEST(BlockMasks, MergeOrFoldsEqualOriginsAndKeepsLayerOrder)
{
    const std::vector<Anchor> a = {{Origin(0, 0, 0), 1}, {Origin(8, 0, 0), 2}, {Origin(0, 8, 0), 4}};
    const std::vector<Anchor> b = {{Origin(8, 0, 0), 8}, {Origin(0, 0, 8), 16}, {Origin(-8, 8, 0), 32}};
    std::vector<Anchor> out;
    mergeOr(a.data(), a.data() + a.size(), b.data(), b.data() + b.size(), out);
    ASSERT_EQ(out.size(), 5u);
    EXPECT_EQ(out[0].origin, Origin(0, 0, 0));
    EXPECT_EQ(out[1].origin, Origin(8, 0, 0));
    EXPECT_EQ(out[1].mask, 2u | 8u);
    EXPECT_EQ(out[2].origin, Origin(0, 0, 8));
    EXPECT_EQ(out[3].origin, Origin(-8, 8, 0));
    EXPECT_EQ(out[4].origin, Origin(0, 8, 0));
    for (size_t i = 1; i < out.size(); ++i)
        EXPECT_TRUE(layerLess(out[i - 1].origin, out[i].origin));
}

TEST(BlockMasks, AddressingTablesPointAtEachCorner)
{
    const BlockTables& t = blockTables();
    for (int d3 = 0; d3 < 2; ++d3) {
        for (int p = 0; p < 2; ++p) {
            for (int b = 0; b < (d3 ? 64 : 16); ++b) {
                const Origin anchor(16, -8, d3 ? 24 : 0);
                const Origin o = blockOrigin(anchor, b, p, d3);
                for (int c = 0; c < (d3 ? 8 : 4); ++c) {
                    const int x = o.x() + (c & 1), y = o.y() + ((c >> 1) & 1), z = o.z() + (c >> 2);
                    const Origin leaf = leafOrigin(anchor, t.leaf[d3][p][b][c]);
                    EXPECT_EQ(leaf, Origin(x & ~7, y & ~7, z & ~7)) << d3 << p << b << c;
                    EXPECT_EQ(t.offset[d3][p][b][c], ((x & 7) << 6) | ((y & 7) << 3) | (z & 7));
                    // A block touches neighbour leaf w only if neededLeaves says so (the even
                    // phase's corners all lie in the anchor's leaf, w = 0, which it always holds).
                    const int w = t.leaf[d3][p][b][c];
                    const uint64_t one = uint64_t(1) << b;
                    EXPECT_TRUE(((d3 ? neededLeaves<true>(one) : neededLeaves<false>(one)) >> w) & 1u);
                }
            }
        }
    }
}

TEST(BlockMasks, NeededLeavesAreTheLeavesTheBlocksTouch)
{
    // Every mask of one block, and random masks: bit w iff a corner of some block of the mask lies
    // in leaf w (BlockTables::leaf, checked against the corners' coordinates above).
    const BlockTables& t = blockTables();
    std::vector<uint64_t> masks;
    for (int b = 0; b < 64; ++b)
        masks.push_back(uint64_t(1) << b);
    uint64_t x = 0x9E3779B97F4A7C15ull;
    for (int i = 0; i < 2000; ++i) {
        x ^= x << 13, x ^= x >> 7, x ^= x << 17;
        masks.push_back(x & (x >> 11) & (x >> 23)); // sparse: about 8 blocks
        masks.push_back(x);
    }
    for (const uint64_t m3 : masks) {
        for (int d3 = 0; d3 < 2; ++d3) {
            const uint64_t m = d3 ? m3 : (m3 & 0xFFFFull);
            uint32_t expected = 1u; // the anchor's leaf, even for an empty mask
            for (uint64_t left = m; left; left &= left - 1)
                for (int c = 0; c < (d3 ? 8 : 4); ++c)
                    expected |= 1u << t.leaf[d3][1][__builtin_ctzll(left)][c];
            EXPECT_EQ(d3 ? neededLeaves<true>(m) : neededLeaves<false>(m), expected)
                << std::hex << m << " " << d3;
        }
    }
}

namespace {
template <int P, bool D3> void dilateCornersAt(const uint64_t act[8], uint64_t out[8])
{
    dilateCorners<P, D3>(act, out);
}
void dilateCornersRun(int phase, bool is3D, const uint64_t act[8], uint64_t out[8])
{
    if (is3D)
        phase ? dilateCornersAt<1, true>(act, out) : dilateCornersAt<0, true>(act, out);
    else
        phase ? dilateCornersAt<1, false>(act, out) : dilateCornersAt<0, false>(act, out);
}
} // namespace

TEST(BlockMasks, DilateCornersSendsEachCellToTheOneBlockOfTheOtherPhaseHoldingIt)
{
    // The pruned sink follows single cells: corner k (bit 0 = +x, 1 = +y, 2 = +z) of block b of
    // phase P is the cell at local 2 b - P + d along each axis; the block of phase Q = 1 - P holding
    // it is the one whose two cells 2 c - Q and 2 c - Q + 1 (c = 0..3, in the anchor's leaf or in the
    // neighbour the dilation spills to: +8 on the even phase, -8 on the odd) include it.
    for (int is3D = 0; is3D < 2; ++is3D) {
        const int axes = is3D ? 3 : 2;
        for (int phase = 0; phase < 2; ++phase) {
            const int q = 1 - phase;
            for (int b = 0; b < (is3D ? 64 : 16); ++b) {
                const int bc[3] = {b & 3, (b >> 2) & 3, b >> 4};
                for (int k = 0; k < (1 << axes); ++k) {
                    uint64_t act[8] = {0, 0, 0, 0, 0, 0, 0, 0}, out[8];
                    act[k] = uint64_t(1) << b;
                    dilateCornersRun(phase, is3D != 0, act, out);
                    int s = 0, bit = 0;
                    for (int ax = 0; ax < axes; ++ax) {
                        int u = 2 * bc[ax] - phase + ((k >> ax) & 1); // the cell, in the anchor's frame
                        const int shift = phase == 0 ? 8 : -8;        // the neighbour the dilation reaches
                        if (u + q < 0 || u + q > 7) {
                            u -= shift;
                            s |= 1 << ax;
                        }
                        const int c = (u + q) / 2;
                        ASSERT_GE(c, 0);
                        ASSERT_LE(c, 3);
                        bit += c << (2 * ax);
                    }
                    for (int t = 0; t < (1 << axes); ++t)
                        EXPECT_EQ(out[t], t == s ? uint64_t(1) << bit : 0u)
                            << (is3D ? "3D" : "2D") << " phase " << phase << " block " << b << " corner " << k
                            << " anchor " << t;
                }
            }
        }
    }
}

TEST(BlockMasks, DilateCornersWithEveryCornerFollowedIsDilateAll)
{
    uint64_t x = 0x9E3779B97F4A7C15ull;
    for (int trial = 0; trial < 2000; ++trial) {
        x ^= x << 13, x ^= x >> 7, x ^= x << 17;
        for (int is3D = 0; is3D < 2; ++is3D) {
            const uint64_t m = is3D ? x : (x & 0xFFFFull);
            for (int phase = 0; phase < 2; ++phase) {
                uint64_t act[8], out[8], want[8];
                for (uint64_t& a : act)
                    a = m;
                dilateCornersRun(phase, is3D != 0, act, out);
                if (is3D)
                    phase ? dilateAll<1, true>(m, want) : dilateAll<0, true>(m, want);
                else
                    phase ? dilateAll<1, false>(m, want) : dilateAll<0, false>(m, want);
                for (int s = 0; s < (is3D ? 8 : 4); ++s)
                    ASSERT_EQ(out[s], want[s]) << trial << " phase " << phase << " anchor " << s;
            }
        }
    }
}
