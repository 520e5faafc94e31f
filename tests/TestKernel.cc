// The automaton's kernel (lib/src/automaton/Kernel.cc) on its own: the SIMD path (its AVX2 build
// where the CPU has it, and its baseline SSE2 build) and the portable path must give bit-identical
// grids, active masks, changed masks and totals on the same input (kernel_testing::Paths forces each).
// The inputs are random grids built to reach every branch of the pass: over cells next to empty ones
// (0 -> positive, active bits), E > A and E <= A blocks, obstacle voxels and an obstacle tile, odd
// blocks straddling into missing leaves (deferred), 2D and 3D, every rule, small and large Tc
// (Tc > 2^27 turns the SIMD branch off, so both paths must agree there trivially too).
#include "automaton/Kernel.h"
#include "automaton/KernelTesting.h"
#include "automaton/LeafTable.h"
#include "automaton/OverFilter.h"

#include <vdbclay/Automaton.h>
#include <vdbclay/Metrics.h>
#include <vdbclay/Rules.h>

#include <openvdb/openvdb.h>

#include <gtest/gtest.h>

#include <algorithm>
#include <cstdint>
#include <cstdio>
#include <vector>

#include "CandidatesTesting.h"
#include "TestRng.h"

using namespace vdbclay;
using namespace vdbclay::automaton_internal;
using openvdb::Coord;

namespace {

class KernelTest : public ::testing::Test {
protected:
    static void SetUpTestSuite() { openvdb::initialize(); }
};

struct Scene {
    openvdb::Int32Tree::Ptr mass;
    openvdb::MaskTree::Ptr obstacles;
    std::vector<WorkItem> work;
};

/// A random clay grid over 4x4x4 leaves (2D: 4x4, z = 0), a few of them missing, with obstacles;
/// every block of both phases a candidate (the work list has one item per anchor, in layer order).
/// @a sparseOver: over cells are rare (about 1 in 120 cells), so most blocks hold none (the
/// over-cell filter's case); otherwise about 3 in 10 cells are over.
Scene makeScene(uint64_t seed, bool is3D, int32_t tc, bool sparseOver = false)
{
    vdbclay_test::Rng g(seed);
    Scene s;
    s.mass = std::make_shared<openvdb::Int32Tree>(0);
    s.obstacles = std::make_shared<openvdb::MaskTree>(false);
    const int nz = is3D ? 4 : 1;
    for (int lx = 0; lx < 4; ++lx)
        for (int ly = 0; ly < 4; ++ly)
            for (int lz = 0; lz < nz; ++lz) {
                if (g.range(0, 5) == 0) continue; // a missing leaf
                const Coord o(lx * 8, ly * 8, lz * 8);
                openvdb::Int32Tree::LeafNodeType* leaf = s.mass->touchLeaf(o);
                for (int i = 0; i < 512; ++i) {
                    if (!is3D && (i & 7) != 0) continue; // 2D: z = 0 only
                    int kind = g.range(0, 9);
                    if (sparseOver && kind >= 7 && g.range(0, 39) != 0) kind = 6;
                    int32_t v = 0;
                    if (kind <= 2)
                        v = 0; // empty
                    else if (kind <= 5)
                        v = g.range(0, tc); // under, room
                    else if (kind == 6)
                        v = tc; // full
                    else if (kind <= 8)
                        v = tc + g.range(1, tc > 8 ? tc / 4 : 3); // a little over
                    else
                        v = g.range(tc, tc > 100000 ? tc + 100000 : 4 * tc); // far over
                    if (v) leaf->setValueOn(i, v);
                }
            }
    for (int i = 0; i < 400; ++i) {
        const Coord c(g.range(-1, 32), g.range(-1, 32), is3D ? g.range(-1, 32) : 0);
        s.obstacles->setValueOn(c);
    }
    if (is3D) s.obstacles->addTile(1, Coord(8, 16, 8), true, true); // one leaf-sized obstacle tile
    return s;
}

std::vector<WorkItem> allBlocks(bool is3D)
{
    std::vector<WorkItem> work;
    const int nz = is3D ? 5 : 1; // odd anchors one leaf past the clay reach back into it
    for (int ly = 0; ly < 5; ++ly)
        for (int lz = 0; lz < nz; ++lz)
            for (int lx = 0; lx < 5; ++lx)
                work.push_back(WorkItem{Origin(lx * 8, ly * 8, lz * 8), fullMask(is3D), 0});
    return work;
}

struct Result {
    openvdb::Int32Tree::Ptr mass;
    std::vector<uint64_t> changed;
    PassTotals tot;
};

Result runPass(const Scene& s, Rule rule, int32_t tc, bool is3D, int phase, uint64_t step, bool portable,
               bool useTable = false, OverFilter filter = OverFilter::Auto, bool avx2 = true)
{
    Result r;
    r.mass = std::make_shared<openvdb::Int32Tree>(*s.mass); // deep copy
    LeafTable table;
    if (useTable) table.build(*r.mass, s.obstacles.get(), is3D);
    std::vector<WorkItem> work = allBlocks(is3D);
    RuleParams p;
    p.rule = rule;
    p.threshold = tc;
    p.alpha = 0.37;
    PassInput in;
    in.tree = r.mass.get();
    in.obstacles = s.obstacles.get();
    in.rule = compileRule(p);
    in.is3D = is3D;
    in.phase = phase;
    in.step = step;
    in.seed = 7;
    in.table = useTable ? &table : nullptr;
    kernel_testing::Paths paths;
    paths.portable = portable;
    paths.filter = filter;
    paths.avx2 = avx2;
    // Two ranges, as two tasks would get them, joined in order.
    const size_t half = work.size() / 2;
    PassTotals second;
    kernel_testing::processRange(in, paths, work.data(), 0, half, r.tot);
    kernel_testing::processRange(in, paths, work.data(), half, work.size(), second);
    r.tot.join(second);
    for (const WorkItem& w : work)
        r.changed.push_back(w.changed);
    return r;
}

void expectSame(const Result& a, const Result& b, const std::string& what)
{
    EXPECT_EQ(a.tot.examined, b.tot.examined) << what;
    EXPECT_EQ(a.tot.overTc, b.tot.overTc) << what;
    EXPECT_EQ(a.tot.updated, b.tot.updated) << what;
    EXPECT_EQ(a.tot.overloadDelta, b.tot.overloadDelta) << what;
    EXPECT_EQ(a.tot.maxWritten, b.tot.maxWritten) << what;
    EXPECT_EQ(a.tot.overflow, b.tot.overflow) << what;
    ASSERT_EQ(a.tot.deferred.size(), b.tot.deferred.size()) << what;
    for (size_t i = 0; i < a.tot.deferred.size(); ++i) {
        EXPECT_EQ(a.tot.deferred[i].item, b.tot.deferred[i].item) << what;
        EXPECT_EQ(a.tot.deferred[i].bit, b.tot.deferred[i].bit) << what;
        EXPECT_EQ(a.tot.deferred[i].cells, b.tot.deferred[i].cells) << what;
    }
    EXPECT_EQ(a.changed, b.changed) << what;
    EXPECT_EQ(a.mass->leafCount(), b.mass->leafCount()) << what;
    int leavesDiffering = 0;
    for (auto it = a.mass->cbeginLeaf(); it; ++it) {
        const auto* other = b.mass->probeConstLeaf(it->origin());
        ASSERT_NE(other, nullptr) << what;
        bool same = it->getValueMask() == other->getValueMask();
        for (int i = 0; i < 512 && same; ++i)
            same = it->getValue(i) == other->getValue(i);
        if (!same) ++leavesDiffering;
    }
    EXPECT_EQ(leavesDiffering, 0) << what;
}

TEST_F(KernelTest, SimdAndPortablePathsGiveIdenticalPasses)
{
    const Rule rules[] = {Rule::Arata, Rule::Bingham, Rule::Sorted, Rule::Prorata};
    const int32_t tcs[] = {1, 7, 1000, (1 << 27), (1 << 27) + 1};
    uint64_t seed = 1;
    for (int d3 = 0; d3 < 2; ++d3)
        for (const int32_t tc : tcs)
            for (const Rule rule : rules)
                for (int phase = 0; phase < 2; ++phase) {
                    const bool is3D = d3 == 1;
                    const Scene s = makeScene(seed++, is3D, tc);
                    const uint64_t step = 100 + uint64_t(phase) + 2 * seed;
                    const Result simd = runPass(s, rule, tc, is3D, phase, step, false);
                    const Result sse2 =
                        runPass(s, rule, tc, is3D, phase, step, false, false, OverFilter::Auto,
                                /*avx2=*/false);
                    const Result portable = runPass(s, rule, tc, is3D, phase, step, true);
                    const std::string what = std::string(is3D ? "3D" : "2D") + " tc " + std::to_string(tc) +
                                             " rule " + std::to_string(int(rule)) + " phase " +
                                             std::to_string(phase);
                    // The scene must exercise the pass: many blocks updated, some deferred on odd
                    // steps (clay flowing into a missing leaf).
                    EXPECT_GT(portable.tot.updated, is3D ? 1000u : 40u) << what;
                    if (phase == 1) {
                        EXPECT_GT(portable.tot.deferred.size(), 0u) << what;
                    }
                    expectSame(simd, portable, what);
                    expectSame(sse2, portable, what + " (baseline build)");
                }
    std::printf("the pass's build on this machine: %s\n", kernel_testing::avx2Pass() ? "AVX2" : "baseline");
}

/// The flat leaf table (LeafTable.h, PassInput::table) only replaces the accessor probes: the same passes
/// with and without it, on the SIMD and the portable path, must agree bit for bit. The work list holds
/// anchors the table indexes (every leaf, and the upper neighbours reaching into one) and anchors it does not
/// (an anchor all of whose leaves are missing), which fall back to the accessors.
TEST_F(KernelTest, LeafTableGivesIdenticalPasses)
{
    const Rule rules[] = {Rule::Arata, Rule::Sorted, Rule::Prorata};
    uint64_t seed = 1000;
    for (int d3 = 0; d3 < 2; ++d3)
        for (const int32_t tc : {7, 1000})
            for (const Rule rule : rules)
                for (int phase = 0; phase < 2; ++phase)
                    for (int portable = 0; portable < 2; ++portable) {
                        const bool is3D = d3 == 1;
                        const Scene s = makeScene(seed++, is3D, tc);
                        const uint64_t step = 40 + uint64_t(phase) + 2 * seed;
                        const Result plain = runPass(s, rule, tc, is3D, phase, step, portable == 1, false);
                        const Result table = runPass(s, rule, tc, is3D, phase, step, portable == 1, true);
                        const std::string what = std::string(is3D ? "3D" : "2D") + " tc " +
                                                 std::to_string(tc) + " rule " + std::to_string(int(rule)) +
                                                 " phase " + std::to_string(phase) +
                                                 (portable ? " portable" : " simd");
                        EXPECT_GT(plain.tot.updated, is3D ? 1000u : 40u) << what;
                        if (phase == 1) {
                            EXPECT_GT(plain.tot.deferred.size(), 0u) << what;
                        }
                        expectSame(plain, table, what);
                    }
}

/// The over-cell filter (OverFilter.h, overBlocks) against brute force on coordinates: the anchor's 8
/// leaves as plain arrays, each block's 8 cells found from its minimum corner (blockOrigin), not
/// through the filter's column tables. First one over cell at each corner of each block of both
/// phases (so every corner position, and on the odd phase every cell that lies across a leaf border
/// into the -x, -y, -z neighbours and their combinations), then random sparse over cells and random
/// candidate masks. The filter must return exactly the candidate blocks that hold an over cell, on
/// each instruction set; in 2D (no filter) the mask unchanged.
TEST_F(KernelTest, OverFilterFindsExactlyTheBlocksHoldingAnOverCell)
{
    std::vector<int32_t> leaves(8 * 512);
    const int32_t* read[8];
    for (int w = 0; w < 8; ++w)
        read[w] = leaves.data() + 512 * w;
    // The value of the cell at anchor-relative (x, y, z), x, y, z in -8..7.
    auto cell = [&](int x, int y, int z) -> int32_t& {
        const int w = (x < 0 ? 1 : 0) | (y < 0 ? 2 : 0) | (z < 0 ? 4 : 0);
        return leaves[512 * w + ((x & 7) << 6) + ((y & 7) << 3) + (z & 7)];
    };
    auto expected = [&](uint64_t mask, int phase, int32_t tc) {
        uint64_t out = 0;
        for (int b = 0; b < 64; ++b) {
            if (!((mask >> b) & 1u)) continue;
            const Origin o = blockOrigin(Origin(0, 0, 0), b, phase, true);
            for (int c = 0; c < 8; ++c)
                if (cell(o.x() + (c & 1), o.y() + ((c >> 1) & 1), o.z() + (c >> 2)) > tc)
                    out |= uint64_t(1) << b;
        }
        return out;
    };
    std::vector<OverFilter> filters{OverFilter::Sse2};
    if (bestOverFilter() == OverFilter::Avx2) filters.push_back(OverFilter::Avx2);
    if (bestOverFilter() == OverFilter::None) filters = {OverFilter::None}; // a build without SSE2
    std::printf("over-cell filter on this machine: %s\n", bestOverFilter() == OverFilter::Avx2   ? "AVX2"
                                                          : bestOverFilter() == OverFilter::Sse2 ? "SSE2"
                                                                                                 : "none");
    int checked = 0;
    for (const OverFilter f : filters) {
        const int32_t tc = 1000;
        for (int phase = 0; phase < 2; ++phase)
            for (int b = 0; b < 64; ++b)
                for (int c = 0; c < 8; ++c) {
                    std::fill(leaves.begin(), leaves.end(), tc); // full: not over
                    const Origin o = blockOrigin(Origin(0, 0, 0), b, phase, true);
                    cell(o.x() + (c & 1), o.y() + ((c >> 1) & 1), o.z() + (c >> 2)) = tc + 1;
                    const uint64_t want = expected(~0ull, phase, tc);
                    ASSERT_EQ(want >> b & 1u, 1u);
                    const uint64_t got = overBlocks(read, ~0ull, tc, true, phase, f);
                    if (f == OverFilter::None) {
                        ASSERT_EQ(got, ~0ull);
                        continue;
                    }
                    ASSERT_EQ(got, want)
                        << "filter " << int(f) << " phase " << phase << " block " << b << " corner " << c;
                    // Only the candidates are returned.
                    const uint64_t some = 0x9A5C3E1F70B6D248ull ^ (uint64_t(b) * 0x2545F4914F6CDD1Dull);
                    ASSERT_EQ(overBlocks(read, some, tc, true, phase, f), want & some);
                    ++checked;
                }
        vdbclay_test::Rng g(5 + int(f));
        for (int trial = 0; trial < 3000; ++trial) {
            const int32_t t = trial % 3 == 0 ? 1 : trial % 3 == 1 ? 1000 : INT32_MAX - 1;
            const int rate = g.range(10, 400); // one over cell in `rate`
            for (int32_t& v : leaves) {
                const int k = g.range(0, rate);
                v = k == 0   ? (t == INT32_MAX - 1 ? INT32_MAX : t + g.range(1, 100))
                    : k == 1 ? t
                             : g.range(0, t);
            }
            const int phase = trial & 1;
            uint64_t mask = g.next() & g.next();
            if (trial % 5 == 0) mask = ~0ull;
            const uint64_t got = overBlocks(read, mask, t, true, phase, f);
            if (f == OverFilter::None) {
                ASSERT_EQ(got, mask);
                continue;
            }
            ASSERT_EQ(got, expected(mask, phase, t)) << "filter " << int(f) << " trial " << trial;
            ++checked;
        }
        // 2D: no filter, the mask as given.
        EXPECT_EQ(overBlocks(read, 0xFFFFu, 1000, false, 1, f), 0xFFFFu);
    }
    if (filters[0] != OverFilter::None) {
        EXPECT_GT(checked, 2 * 8 * 64);
    }
}

/// The same passes with the filter on each instruction set and off (OverFilter::None), with and
/// without the leaf table: identical grids, masks and totals, blocksVisited included (it counts the
/// candidates before the filter). Scenes with rare over cells, so that most blocks are filtered out,
/// and the usual dense ones; 2D too (where the filter is off on every setting).
TEST_F(KernelTest, OverFilterGivesIdenticalPasses)
{
    std::vector<OverFilter> filters{OverFilter::Sse2, OverFilter::Auto};
    if (bestOverFilter() == OverFilter::Avx2) filters.push_back(OverFilter::Avx2);
    const Rule rules[] = {Rule::Arata, Rule::Bingham, Rule::Sorted, Rule::Prorata};
    uint64_t seed = 5000;
    for (int d3 = 0; d3 < 2; ++d3)
        for (int sparse = 0; sparse < 2; ++sparse)
            for (const int32_t tc : {7, 1000})
                for (const Rule rule : rules)
                    for (int phase = 0; phase < 2; ++phase) {
                        const bool is3D = d3 == 1;
                        const Scene s = makeScene(seed++, is3D, tc, sparse == 1);
                        const uint64_t step = 60 + uint64_t(phase) + 2 * seed;
                        const bool useTable = seed % 2 == 0;
                        const Result none =
                            runPass(s, rule, tc, is3D, phase, step, false, useTable, OverFilter::None);
                        const std::string what = std::string(is3D ? "3D" : "2D") +
                                                 (sparse ? " sparse" : " dense") + " tc " +
                                                 std::to_string(tc) + " rule " + std::to_string(int(rule)) +
                                                 " phase " + std::to_string(phase);
                        if (is3D || !sparse) { // (a sparse 2D scene has a handful of over cells)
                            EXPECT_GT(none.tot.updated, is3D ? (sparse ? 100u : 1000u) : 40u) << what;
                        }
                        if (sparse) {
                            // Most candidates hold no over cell: the filter has work to do.
                            EXPECT_GT(none.tot.examined, 3 * none.tot.overTc) << what;
                        }
                        for (const OverFilter f : filters) {
                            const Result r = runPass(s, rule, tc, is3D, phase, step, false, useTable, f);
                            expectSame(none, r, what + " filter " + std::to_string(int(f)));
                        }
                        const Result portable = runPass(s, rule, tc, is3D, phase, step, true, useTable);
                        expectSame(none, portable, what + " portable");
                    }
}

TEST_F(KernelTest, LeafTableIndexesEveryAnchorThatReachesALeaf)
{
    // Two leaves far apart (one at negative coordinates) and an obstacle tile: every leaf's origin and
    // its upper neighbours' are indexed (8 each in 3D, 4 in 2D, none shared), nothing else.
    openvdb::Int32Tree mass(0);
    mass.touchLeaf(Coord(0, 0, 0));
    mass.touchLeaf(Coord(-800, 8000, -16));
    openvdb::MaskTree obs(false);
    obs.addTile(1, Coord(8, 8, 8), true, true);
    LeafTable t;
    EXPECT_FALSE(t.valid());
    EXPECT_EQ(t.size(), 0u);
    t.build(mass, &obs, true);
    EXPECT_TRUE(t.valid());
    EXPECT_EQ(t.size(), 16u);
    t.build(mass, nullptr, false);
    EXPECT_EQ(t.size(), 8u);
    t.clear();
    EXPECT_FALSE(t.valid());
    EXPECT_EQ(t.size(), 0u);
    openvdb::Int32Tree none(0);
    t.build(none, nullptr, true);
    EXPECT_TRUE(t.valid());
    EXPECT_EQ(t.size(), 0u);
}

/// The Automaton must drop its table when an edit adds a leaf: a stale table would hand the anchors
/// next to the new leaf "missing" (zeros) for it. Each edit below puts overloaded clay into a new
/// leaf beside clay whose table is built; the run must match a fresh Automaton started
/// on a copy of the edited grid (the automaton is exact: which blocks it examines never changes the
/// result), on 1 and 3 threads.
TEST_F(KernelTest, EditsThatAddLeavesDropTheLeafTable)
{
    for (const int threads : {1, 3}) {
        auto grid = MassGrid::create(0);
        grid->tree().fill(openvdb::CoordBBox(Coord(0, 0, 0), Coord(15, 15, 15)), 3000, true);
        AutomatonOptions opts;
        opts.rule.threshold = 1000;
        opts.threads = threads;
        Automaton a(grid, opts);
        a.run(41); // the table is built after a few steps
        for (int e = 0; e < 3; ++e) {
            // The leaf just past the clay along +x: missing, but its -x neighbour holds clay, so the
            // table indexes the anchor there (with that slot missing).
            int x = 0;
            while (grid->tree().probeConstLeaf(Coord(x, 8, 8)))
                x += 8;
            ASSERT_NE(grid->tree().probeConstLeaf(Coord(x - 8, 8, 8)), nullptr);
            a.edit(Box{{{x, 8, 8}}, {{x + 1, 9, 9}}}, [&](MassGrid& g) {
                g.tree().setValueOn(Coord(x, 8, 8), 9000);
                g.tree().setValueOn(Coord(x + 1, 9, 9), 7000);
            });
            auto copy = grid->deepCopy();
            Automaton b(copy, opts);
            b.setStepCount(a.stepCount());
            a.run(30);
            b.run(30);
            EXPECT_EQ(contentHash(*grid), contentHash(*copy)) << "edit " << e << ", threads " << threads;
        }
    }
}

/// The block at the origin of @a s passed once through each build: r[0] the AVX2 build (where the CPU
/// has it), r[1] the portable path, r[2] the baseline (SSE2) build.
void passOneBlockEveryBuild(const Scene& s, const RuleParams& p, bool is3D, uint64_t step, uint64_t seed,
                            Result r[3])
{
    for (int build = 0; build < 3; ++build) {
        r[build].mass = std::make_shared<openvdb::Int32Tree>(*s.mass);
        std::vector<WorkItem> work{WorkItem{Origin(0, 0, 0), 1, 0}};
        PassInput in;
        in.tree = r[build].mass.get();
        in.obstacles = s.obstacles.get();
        in.rule = compileRule(p);
        in.is3D = is3D;
        in.phase = 0;
        in.step = step;
        in.seed = seed;
        kernel_testing::Paths paths;
        paths.portable = build == 1;
        paths.avx2 = build != 2;
        kernel_testing::processRange(in, paths, work.data(), 0, 1, r[build].tot);
        r[build].changed.push_back(work[0].changed);
    }
}

/// One block at a time, so that the totals of each block (the largest value written and the
/// overload delta, which a whole pass sums or maxes away) are compared block by block.
TEST_F(KernelTest, SingleBlocksGiveIdenticalTotals)
{
    vdbclay_test::Rng g(99);
    int updated = 0;
    for (int trial = 0; trial < 4000; ++trial) {
        const bool is3D = trial % 2 == 0;
        const Rule rule = (trial / 2) % 2 ? Rule::Prorata : Rule::Sorted;
        const int32_t tc = (trial / 4) % 3 == 0 ? 7 : 1000;
        const int n = is3D ? 8 : 4;
        Scene s;
        s.mass = std::make_shared<openvdb::Int32Tree>(0);
        s.obstacles = std::make_shared<openvdb::MaskTree>(false);
        s.mass->touchLeaf(Coord(0, 0, 0));
        for (int c = 0; c < n; ++c) {
            const Coord xyz(c & 1, (c >> 1) & 1, (c >> 2) & 1);
            const int kind = g.range(0, 9);
            int32_t v = kind <= 1 ? 0 : kind <= 5 ? g.range(0, tc) : kind == 6 ? tc : g.range(tc + 1, 3 * tc);
            if (v) s.mass->setValueOn(xyz, v);
            if (g.range(0, 15) == 0) s.obstacles->setValueOn(xyz);
        }
        RuleParams p;
        p.rule = rule;
        p.threshold = tc;
        Result r[3];
        passOneBlockEveryBuild(s, p, is3D, uint64_t(trial), 3, r);
        updated += int(r[1].tot.updated);
        expectSame(r[0], r[1], "trial " + std::to_string(trial));
        expectSame(r[2], r[1], "trial " + std::to_string(trial) + " (baseline build)");
        if (HasFailure()) break;
    }
    EXPECT_GT(updated, 2000); // most random blocks hold an over cell and an under one
}

/// The branches in registers (BlockSimd.h: surplusBranch, roomBranch) against the scalar rule on single
/// blocks built from edge values: cells at 0, 1, Tc - 1, Tc (no room), Tc + 1, 2 Tc and INT32_MAX / 8 (the
/// largest a pass without overflow checks sees), so that blocks with every cell over, none under, no room
/// at all (A = 0), E = A and E = A + 1, ties everywhere and empty cells that become active all occur;
/// obstacles on random corners of either half; every rule, 2D and 3D, Tc 1, 2, 1000, 2^27 and 2^27 + 1.
/// Each block is one pass, so its overload delta and largest value are compared alone.
TEST_F(KernelTest, EdgeValueBlocksGiveIdenticalResults)
{
    vdbclay_test::Rng g(2026);
    const Rule rules[] = {Rule::Arata, Rule::Bingham, Rule::Sorted, Rule::Prorata};
    const int32_t tcs[] = {1, 2, 1000, 1 << 27, (1 << 27) + 1};
    int updated = 0, surplus = 0, equal = 0;
    for (int trial = 0; trial < 5000; ++trial) {
        const bool is3D = trial % 2 == 0;
        const Rule rule = rules[(trial / 2) % 4];
        const int32_t tc = tcs[(trial / 8) % 5];
        const int n = is3D ? 8 : 4;
        const int32_t edge[] = {0, 1, tc - 1, tc, tc + 1, 2 * tc, INT32_MAX / 8};
        int32_t v[8] = {};
        const int style = g.range(0, 3); // 0: any edge values; 1: no room (under cells at Tc); 2: E = A (+1)
        for (int c = 0; c < n; ++c)
            v[c] = std::min<int32_t>(edge[g.range(0, 6)], INT32_MAX / 8);
        if (style == 1) {
            for (int c = 0; c < n; ++c)
                if (v[c] <= tc) v[c] = tc;
        } else if (style == 2) {
            // One over cell holding exactly the block's room (or one unit more).
            int64_t room = 0;
            for (int c = 1; c < n; ++c) {
                v[c] = std::min(v[c], tc);
                room += tc - v[c];
            }
            v[0] = int32_t(std::min<int64_t>(tc + room + g.range(0, 1), INT32_MAX / 8));
        }
        Scene s;
        s.mass = std::make_shared<openvdb::Int32Tree>(0);
        s.obstacles = std::make_shared<openvdb::MaskTree>(false);
        s.mass->touchLeaf(Coord(0, 0, 0));
        int64_t e = 0, a = 0;
        for (int c = 0; c < n; ++c) {
            const Coord xyz(c & 1, (c >> 1) & 1, (c >> 2) & 1);
            if (v[c]) s.mass->setValueOn(xyz, v[c]);
            if (g.range(0, 9) == 0) {
                s.obstacles->setValueOn(xyz);
            } else {
                e += std::max<int64_t>(v[c] - tc, 0);
                a += std::max<int64_t>(tc - v[c], 0);
            }
        }
        RuleParams p;
        p.rule = rule;
        p.threshold = tc;
        p.alpha = 0.5;
        Result r[3];
        passOneBlockEveryBuild(s, p, is3D, uint64_t(trial) * 7, 11, r);
        updated += int(r[1].tot.updated);
        if (r[1].tot.updated && e > a) ++surplus;
        if (r[1].tot.updated && e == a) ++equal;
        const std::string what = "trial " + std::to_string(trial) + " rule " + std::to_string(int(rule)) +
                                 " tc " + std::to_string(tc) + (is3D ? " 3D" : " 2D");
        expectSame(r[0], r[1], what);
        expectSame(r[2], r[1], what + " (baseline build)");
        if (HasFailure()) break;
    }
    std::printf("edge-value blocks: %d updated, %d with E > A, %d with E = A\n", updated, surplus, equal);
    EXPECT_GT(updated, 2000);
    EXPECT_GT(surplus, 1000);
    EXPECT_GT(equal, 100);
}

// Candidates' dense mode (per-anchor accumulators over the leaf table's anchors, filled by record()
// or by the pass through DenseSink, one sink or one lane per thread) against the merged lists, over
// random step sequences with edits, resets, quiet steps and attach/detach at random steps: the same
// work lists (anchors, masks, layer order), except anchors the index lacks (no leaf within reach:
// they read zeros and never change).
TEST_F(KernelTest, DenseCandidatesMatchTheMergedLists)
{
    for (int is3D = 0; is3D < 2; ++is3D) {
        for (uint64_t seed = 1; seed <= 12; ++seed) {
            vdbclay_test::Rng g(seed * 31 + uint64_t(is3D));
            // Leaves in a 6^3 (2D: 6^2) box of leaves, some missing; the index is what LeafTable
            // holds: every leaf's origin and its upper neighbours', in layer order.
            const vdbclay_test::RandomAnchorIndex table(g, 6, is3D != 0, 2);
            const std::vector<Origin>& keys = table.keys;
            const AnchorIndex& index = table.index;
            auto less = vdbclay_test::RandomAnchorIndex::less;
            ASSERT_EQ(index.find(Origin(-8, 0, 0)), kNoEntry);

            Candidates merged, dense;
            std::vector<Origin> hot;
            for (int i = 0; i < 4; ++i)
                hot.push_back(keys[size_t(g.range(0, int(keys.size()) - 1))]);
            std::sort(hot.begin(), hot.end(), less);
            hot.erase(std::unique(hot.begin(), hot.end()), hot.end());
            merged.reset(hot);
            dense.reset(hot);
            uint64_t denseSteps = 0, sunkSteps = 0, laneSteps = 0, droppedBlocks = 0;
            for (int t = 0; t < 60; ++t) {
                const int phase = t & 1;
                const int event = g.range(0, 19);
                if (event == 0) { // an edit
                    const int x0 = g.range(-4, 40), y0 = g.range(-4, 40), z0 = is3D ? g.range(-4, 40) : 0;
                    const Box b{{x0, y0, z0},
                                {x0 + g.range(0, 9), y0 + g.range(0, 9), is3D ? z0 + g.range(0, 9) : 0}};
                    merged.addRegion(b);
                    dense.addRegion(b);
                } else if (event == 1) {
                    merged.reset(hot);
                    dense.reset(hot);
                } else if (event == 2) {
                    dense.detach();
                }
                if (!dense.attached() && g.range(0, 2) == 0) dense.attach(index, phase, is3D);
                std::vector<WorkItem> wm, wd;
                merged.gather(phase, is3D, wm);
                dense.gather(phase, is3D, wd);
                // The dense list is the merged one less the anchors outside the index; the dense
                // list is in index order (columns), the merged one in layer order.
                const auto layerOrder = [](const WorkItem& a, const WorkItem& b) {
                    return automaton_internal::layerLess(a.anchor, b.anchor);
                };
                if (dense.attached()) {
                    EXPECT_TRUE(std::is_sorted(
                        wd.begin(), wd.end(),
                        [](const WorkItem& a, const WorkItem& b) { return a.entry < b.entry; }))
                        << "seed " << seed << " step " << t;
                }
                std::vector<WorkItem> wdl = wd;
                std::sort(wdl.begin(), wdl.end(), layerOrder);
                size_t j = 0;
                for (const WorkItem& m : wm) {
                    const uint32_t e = index.find(m.anchor);
                    if (dense.attached() && e == kNoEntry) {
                        droppedBlocks += uint64_t(__builtin_popcountll(m.mask));
                        continue;
                    }
                    ASSERT_LT(j, wdl.size()) << "seed " << seed << " step " << t;
                    ASSERT_EQ(wdl[j].anchor, m.anchor) << "seed " << seed << " step " << t;
                    ASSERT_EQ(wdl[j].mask, m.mask) << "seed " << seed << " step " << t;
                    if (wdl[j].entry != kNoEntry) {
                        EXPECT_EQ(wdl[j].entry, e);
                    }
                    ++j;
                }
                ASSERT_EQ(j, wdl.size()) << "seed " << seed << " step " << t;
                denseSteps += dense.attached();
                if (event == 3) { // a step with no over cell
                    merged.clearChanges();
                    dense.clearChanges();
                } else {
                    // Some candidate blocks of anchors that hold a leaf change (the same in both).
                    for (WorkItem& m : wm) {
                        m.changed = index.find(m.anchor) == kNoEntry ? 0 : m.mask & (g.next() & g.next());
                    }
                    for (WorkItem& d : wd) {
                        const auto it = std::lower_bound(wm.begin(), wm.end(), d, layerOrder);
                        ASSERT_TRUE(it != wm.end() && it->anchor == d.anchor);
                        d.changed = it->changed;
                    }
                    // Most dense steps record through the sink, as the pass does: one sink, or 1-4
                    // lanes (a pass on several threads: each item in a random lane,
                    // as a thread of the pass would take it), some items recorded twice.
                    if (dense.attached() && g.range(0, 3) != 0) {
                        const int mode = g.range(0, 2);
                        const int lanes = mode == 2 ? g.range(1, 4) : 1;
                        const DenseSink* sink = mode == 2 ? dense.lanes(lanes) : dense.sink();
                        ASSERT_NE(sink, nullptr);
                        for (const WorkItem& d : wd) {
                            if (!d.changed || d.entry == kNoEntry) continue;
                            for (int rep = g.range(0, 9) == 0 ? 2 : 1; rep > 0; --rep) {
                                const DenseSink& s = sink[g.range(0, lanes - 1)];
                                vdbclay_test::sinkChangesAt(phase, is3D != 0, s, d.entry, d.changed);
                            }
                        }
                        ++sunkSteps;
                        laneSteps += lanes > 1;
                    }
                    merged.record(wm);
                    dense.record(wd);
                }
                merged.endStep();
                dense.endStep();
            }
            EXPECT_GT(denseSteps, 10u) << "seed " << seed;
            EXPECT_GT(sunkSteps, 3u) << "seed " << seed;
            EXPECT_GT(laneSteps, 0u) << "seed " << seed;
            if (seed == 1) {
                EXPECT_GT(droppedBlocks, 0u) << "the test reaches anchors outside the index";
            }
        }
    }
}

// dilateAll (the dense mode's dilation) against dilateAcrossPhase on random masks.
TEST_F(KernelTest, DilateAllMatchesDilateAcrossPhase)
{
    vdbclay_test::Rng g(5);
    for (int i = 0; i < 20000; ++i) {
        const bool is3D = (i & 1) != 0;
        const int from = (i >> 1) & 1;
        uint64_t m = g.next() & g.next() & (i % 5 == 0 ? g.next() : ~0ull);
        if (!is3D) m &= 0xFFFFull;
        uint64_t out[8] = {};
        if (is3D)
            from ? dilateAll<1, true>(m, out) : dilateAll<0, true>(m, out);
        else
            from ? dilateAll<1, false>(m, out) : dilateAll<0, false>(m, out);
        uint64_t expect[8] = {};
        Anchor buf[8];
        int shift[8];
        const int n = dilateAcrossPhase(Anchor{Origin(8, 16, 24), m}, from, is3D, buf, shift);
        for (int k = 0; k < n; ++k) {
            expect[shift[k]] = buf[k].mask;
            const int sgn = from == 0 ? 8 : -8;
            EXPECT_EQ(buf[k].origin, Origin(8 + ((shift[k] & 1) ? sgn : 0), 16 + ((shift[k] & 2) ? sgn : 0),
                                            24 + ((shift[k] & 4) ? sgn : 0)));
        }
        for (int k = 0; k < 8; ++k)
            ASSERT_EQ(out[k], expect[k]) << "mask " << m << " shift " << k << " from phase " << from;
    }
}

} // namespace
