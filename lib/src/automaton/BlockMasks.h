// Block-mask algebra of the automaton: pure integer functions, no OpenVDB (tests/TestBlockMasks.cc
// includes this header alone).
//
// Blocks and anchors. OpenVDB leaves are 8^3 voxels. On even steps a Margolus block starts at even
// coordinates, so the 4x4x4 = 64 even blocks of a leaf lie inside it. On odd steps blocks start at
// odd coordinates, (2i-1, 2i), and the blocks whose maximum corner lies in a leaf L are again 64:
// their minimum corners sit at local -1, 1, 3, 5 along each axis, so the blocks with local -1 reach
// into L's lower neighbours (-x, -y, -z and their combinations: the 7 "straddling" leaves). Every
// block therefore has one anchor leaf (the leaf of its maximum corner; for even blocks the leaf that
// holds it whole) and one bit in a 64-bit mask per anchor: bit = bx + 4 by + 16 bz. In 2D the clay
// lives in z = 0, blocks are 2x2, and only the 16 bits with bz = 0 are used.
//
// Candidates. Each block of one phase overlaps 8 (2D: 4) blocks of the other: a shift-and-or on
// the masks, with bits that fall off a face going to the neighbouring anchor (dilateAcrossPhase).
// Candidate lists are kept in layer order (y, then z, then x: the paper's horizontal layers) with
// one entry per anchor, so lists merge (mergeOr) instead of being sorted.
//
// Addressing. BlockTables gives, per phase, block bit and corner, which of the anchor's 8 leaves
// holds the cell (0 = the anchor, bit 0 = its -x, bit 1 = -y, bit 2 = -z neighbour) and the cell's
// offset in that leaf (x << 6 | y << 3 | z, OpenVDB's order).
#pragma once

#include <cstdint>
#include <vector>

namespace vdbclay {
namespace automaton_internal {

// bit = bx + 4 by + 16 bz, each in 0..3.
constexpr uint64_t kX0 = 0x1111111111111111ull, kX3 = 0x8888888888888888ull;
constexpr uint64_t kY0 = 0x000F000F000F000Full, kY3 = 0xF000F000F000F000ull;
constexpr uint64_t kZ0 = 0x000000000000FFFFull, kZ3 = 0xFFFF000000000000ull;

/// Every block of an anchor (3D: 64; 2D: the 16 with bz = 0).
inline uint64_t fullMask(bool is3D)
{
    return is3D ? ~0ull : 0xFFFFull;
}

/// A leaf origin (multiples of 8), like openvdb::Coord without the include.
struct Origin {
    int32_t v[3] = {0, 0, 0};
    Origin() = default;
    Origin(int32_t x, int32_t y, int32_t z) : v{x, y, z} {}
    int32_t x() const { return v[0]; }
    int32_t y() const { return v[1]; }
    int32_t z() const { return v[2]; }
    int32_t& operator[](int i) { return v[i]; }
    int32_t operator[](int i) const { return v[i]; }
    bool operator==(const Origin& o) const { return v[0] == o.v[0] && v[1] == o.v[1] && v[2] == o.v[2]; }
    bool operator!=(const Origin& o) const { return !(*this == o); }
};

/// A set of candidate (or changed) blocks anchored at one leaf.
struct Anchor {
    Origin origin;
    uint64_t mask;
};

/// Horizontal layers: order by y, then z, then x.
inline bool layerLess(const Origin& a, const Origin& b)
{
    if (a.y() != b.y()) return a.y() < b.y();
    if (a.z() != b.z()) return a.z() < b.z();
    return a.x() < b.x();
}

/// layerLess on anchors (the merged lists' order).
inline bool anchorLayerLess(const Anchor& a, const Anchor& b)
{
    return layerLess(a.origin, b.origin);
}

/// The leaf table's anchor order (AnchorIndex; the dense candidates' work lists): columns, x first,
/// then y, then z. Any lexicographic order with every axis ascending keeps a phase-0 pass's writes
/// at entries at or after its items', and column order cuts a pass into slabs that meet on a y-z face.
inline bool indexLess(const Origin& a, const Origin& b)
{
    if (a.x() != b.x()) return a.x() < b.x();
    if (a.y() != b.y()) return a.y() < b.y();
    return a.z() < b.z();
}

/// The blocks of the other phase that overlap the blocks in @a a, which belong to phase
/// @a fromPhase. Even block b overlaps odd blocks b and b+1 along each axis (b+1 = 4 is block 0 of
/// the +axis neighbour); odd block c overlaps even blocks c-1 and c (c-1 = -1 is block 3 of the
/// -axis neighbour). Writes up to 8 anchors to @a buf, and to @a shift[i] which neighbour leaf
/// buf[i] is (bit 0 = x, 1 = y, 2 = z; 0 = a's own leaf). Returns how many.
inline int dilateAcrossPhase(const Anchor& a, int fromPhase, bool is3D, Anchor buf[8], int shift[8])
{
    int n = 1;
    buf[0] = a;
    shift[0] = 0;
    const uint64_t lo[3] = {kX0, kY0, kZ0}, hi[3] = {kX3, kY3, kZ3};
    const int unit[3] = {1, 4, 16};
    const int axes = is3D ? 3 : 2;
    for (int ax = 0; ax < axes; ++ax) {
        const int cnt = n;
        for (int i = 0; i < cnt; ++i) {
            const uint64_t m = buf[i].mask;
            uint64_t within, spill;
            Origin nb = buf[i].origin;
            if (fromPhase == 0) {
                within = m | ((m & ~hi[ax]) << unit[ax]);
                spill = (m & hi[ax]) >> (3 * unit[ax]);
                nb[ax] += 8;
            } else {
                within = m | ((m & ~lo[ax]) >> unit[ax]);
                spill = (m & lo[ax]) << (3 * unit[ax]);
                nb[ax] -= 8;
            }
            buf[i].mask = within;
            if (spill) {
                shift[n] = shift[i] | (1 << ax);
                buf[n++] = Anchor{nb, spill};
            }
        }
    }
    return n;
}

/// dilateAcrossPhase without branches or loops: @a out[s] is the mask of the neighbour anchor with
/// shift s (bit 0 = x, 1 = y, 2 = z; 0 = a's own leaf), zero where nothing spills there. 2D fills
/// out[0..3] only. (The axes act on separate bit fields, so the order of the folds is free.)
template <int FromPhase, bool D3> inline void dilateAll(uint64_t m, uint64_t out[8])
{
    constexpr uint64_t lo[3] = {kX0, kY0, kZ0}, hi[3] = {kX3, kY3, kZ3};
    constexpr int unit[3] = {1, 4, 16};
    out[0] = m;
    int n = 1;
    for (int ax = 0; ax < (D3 ? 3 : 2); ++ax, n *= 2) { // unrolled by the compiler: constant bounds
        for (int i = 0; i < n; ++i) {
            const uint64_t v = out[i];
            if (FromPhase == 0) {
                out[i] = v | ((v & ~hi[ax]) << unit[ax]);
                out[i + n] = (v & hi[ax]) >> (3 * unit[ax]);
            } else {
                out[i] = v | ((v & ~lo[ax]) >> unit[ax]);
                out[i + n] = (v & lo[ax]) << (3 * unit[ax]);
            }
        }
    }
}

/// dilateAll cell by cell: @a act[k] holds the blocks (phase @a FromPhase) whose corner k (bit 0 =
/// +x, 1 = +y, 2 = +z within the block, as BlockTables' corners) is to be followed; @a out[s] gets
/// the blocks of the other phase that hold those corners, per neighbour anchor s as in dilateAll.
/// Each cell lies in exactly one block of the other phase: on the even phase corner k's cell moves
/// one block up along the axes where k's bit is 1, on the odd phase one block down where it is 0.
/// With every act[k] equal to m this is dilateAll(m). 2D reads act[0..3] and fills out[0..3].
template <int FromPhase, bool D3> inline void dilateCorners(const uint64_t act[8], uint64_t out[8])
{
    constexpr uint64_t lo[3] = {kX0, kY0, kZ0}, hi[3] = {kX3, kY3, kZ3};
    constexpr int unit[3] = {1, 4, 16};
    constexpr int axes = D3 ? 3 : 2;
    // Axis by axis (unrolled: constant bounds). Before axis ax is folded, bit ax of out's index is
    // the corner's; after, the neighbour anchor's: the cells of corner bit 0 and 1 along ax meet.
    for (int k = 0; k < (1 << axes); ++k)
        out[k] = act[k];
    for (int ax = 0; ax < axes; ++ax) {
        const int bit = 1 << ax;
        for (int j = 0; j < (1 << axes); ++j) {
            if (j & bit) continue;
            const uint64_t a = out[j], b = out[j | bit]; // corner bit 0, 1 along ax
            if (FromPhase == 0) {                        // bit 1 moves one block up
                out[j] = a | ((b & ~hi[ax]) << unit[ax]);
                out[j | bit] = (b & hi[ax]) >> (3 * unit[ax]);
            } else { // bit 0 moves one block down
                out[j] = b | ((a & ~lo[ax]) >> unit[ax]);
                out[j | bit] = (a & lo[ax]) << (3 * unit[ax]);
            }
        }
    }
}

/// Appends to @a out the merge of two runs sorted by layerLess with distinct origins; anchors with
/// the same origin in both become one, their masks ORed. The result has distinct origins too.
inline void mergeOr(const Anchor* a, const Anchor* ae, const Anchor* b, const Anchor* be,
                    std::vector<Anchor>& out)
{
    while (a != ae && b != be) {
        if (layerLess(a->origin, b->origin)) {
            out.push_back(*a++);
        } else if (layerLess(b->origin, a->origin)) {
            out.push_back(*b++);
        } else {
            out.push_back(Anchor{a->origin, a->mask | b->mask});
            ++a, ++b;
        }
    }
    out.insert(out.end(), a, ae);
    out.insert(out.end(), b, be);
}

/// The origin of neighbour leaf @a which (bit 0 = -x, 1 = -y, 2 = -z) of the anchor at @a anchor.
inline Origin leafOrigin(const Origin& anchor, int which)
{
    return Origin(anchor.x() - ((which & 1) ? 8 : 0), anchor.y() - ((which & 2) ? 8 : 0),
                  anchor.z() - ((which & 4) ? 8 : 0));
}

/// The minimum corner of block @a bit of phase @a phase anchored at @a anchor.
inline Origin blockOrigin(const Origin& anchor, int bit, int phase, bool is3D)
{
    return Origin(anchor.x() + 2 * (bit & 3) - phase, anchor.y() + 2 * ((bit >> 2) & 3) - phase,
                  is3D ? anchor.z() + 2 * (bit >> 4) - phase : 0);
}

/// Per-block addressing, see the top of this file.
struct BlockTables {
    uint16_t offset[2][2][64][8]; // [dims3][phase][bit][corner]
    uint8_t leaf[2][2][64][8];
    BlockTables()
    {
        for (int d3 = 0; d3 < 2; ++d3) {
            for (int p = 0; p < 2; ++p) {
                for (int b = 0; b < 64; ++b) {
                    const int bx = b & 3, by = (b >> 2) & 3, bz = b >> 4;
                    for (int c = 0; c < 8; ++c) {
                        const int dx = c & 1, dy = (c >> 1) & 1, dz = c >> 2;
                        int lx = 2 * bx - p + dx, ly = 2 * by - p + dy;
                        int lz = d3 ? 2 * bz - p + dz : 0;
                        const int which = (lx < 0 ? 1 : 0) | (ly < 0 ? 2 : 0) | (lz < 0 ? 4 : 0);
                        lx &= 7, ly &= 7, lz &= 7;
                        leaf[d3][p][b][c] = uint8_t(which);
                        offset[d3][p][b][c] = uint16_t((lx << 6) | (ly << 3) | lz);
                    }
                }
            }
        }
    }
};

inline const BlockTables& blockTables()
{
    static const BlockTables t;
    return t;
}

/// The leaves the odd-phase blocks of @a mask read, as bits w of leafOrigin(anchor, w): bit w is set
/// iff a corner of a block of the mask lies in that leaf (BlockTables::leaf), i.e. the block lies at
/// the low end (bx, by or bz = 0) of every axis in w. Bit 0, the anchor's own leaf, is always set.
template <bool D3> inline uint32_t neededLeaves(uint64_t mask)
{
    const uint64_t x = mask & kX0, y = mask & kY0, xy = x & kY0;
    uint32_t need = 1u | (uint32_t(x != 0) << 1) | (uint32_t(y != 0) << 2) | (uint32_t(xy != 0) << 3);
    if constexpr (D3) {
        need |= (uint32_t((mask & kZ0) != 0) << 4) | (uint32_t((x & kZ0) != 0) << 5) |
                (uint32_t((y & kZ0) != 0) << 6) | (uint32_t((xy & kZ0) != 0) << 7);
    }
    return need;
}

/// Addressing of the over-cell filter (OverFilter.cc, overBlocks), 3D. A column is the 4 blocks of one
/// phase with the same (bx, by), numbered col = bx + 4 by (so block bit = col + 16 bz). Its cells lie
/// in 4 z-rows of a leaf (8 consecutive int32, z = 0-7), row r = dx + 2 dy at local x = 2 bx - phase
/// + dx, y = 2 by - phase + dy: in the anchor's leaf, or on the odd phase at local -1 in its -x / -y
/// neighbours (x, y taken mod 8 there). zFold turns the over mask of the column's cells along z (bit
/// z: a cell at that z in one of the 4 rows is over Tc) into the column's blocks holding one, as bits
/// 16 bz (shift left by col to place them in the anchor's mask). Even phase: block bz holds z = 2 bz
/// and 2 bz + 1. Odd phase: z = 2 bz - 1 and 2 bz, so bit 7 (z = 7) belongs to the +z anchor's
/// block and is ignored, and the cells z = -1 of block bz = 0 lie in the -z neighbours' rows at
/// z = 7 (the filter adds that block's bit from them).
struct ColumnTables {
    uint16_t rowOffset[2][16][4]; // [phase][col][row]: x << 6 | y << 3, the row's z = 0 cell
    uint8_t rowLeaf[2][16][4];    // which of the anchor's leaves holds the row (bit 0 = -x, bit 1 = -y)
    uint64_t zFold[2][256];       // [phase][over cells along z]
    constexpr ColumnTables() : rowOffset{}, rowLeaf{}, zFold{}
    {
        for (int p = 0; p < 2; ++p) {
            for (int col = 0; col < 16; ++col) {
                for (int r = 0; r < 4; ++r) {
                    const int x = 2 * (col & 3) - p + (r & 1), y = 2 * (col >> 2) - p + (r >> 1);
                    rowLeaf[p][col][r] = uint8_t((x < 0 ? 1 : 0) | (y < 0 ? 2 : 0));
                    rowOffset[p][col][r] = uint16_t(((x & 7) << 6) | ((y & 7) << 3));
                }
            }
            for (int m = 0; m < 256; ++m) {
                uint64_t f = 0;
                for (int bz = 0; bz < 4; ++bz) {
                    const int lo = 2 * bz - p, hi = 2 * bz - p + 1; // the block's two z
                    const bool over = (lo >= 0 && ((m >> lo) & 1)) || ((m >> hi) & 1);
                    if (over) f |= uint64_t(1) << (16 * bz);
                }
                zFold[p][m] = f;
            }
        }
    }
};

inline constexpr ColumnTables kColumns{};

/// Bits set in a 64-bit mask (SWAR, inline: the builtin is a call into libgcc where the build targets
/// no POPCNT instruction, the default x86-64; the pass and the pass engine count every item's blocks).
inline uint64_t popcount64(uint64_t x)
{
    x = x - ((x >> 1) & 0x5555555555555555ull);
    x = (x & 0x3333333333333333ull) + ((x >> 2) & 0x3333333333333333ull);
    x = (x + (x >> 4)) & 0x0F0F0F0F0F0F0F0Full;
    return (x * 0x0101010101010101ull) >> 56;
}

/// The columns (col = bx + 4 by) that hold a block of @a mask.
inline uint32_t columnsOf(uint64_t mask)
{
    return uint32_t((mask | (mask >> 16) | (mask >> 32) | (mask >> 48)) & 0xFFFFu);
}

} // namespace automaton_internal
} // namespace vdbclay
