// The automaton's kernel (lib/src/Kernel.cc) on its own: the SIMD path and the portable path
// (PassInput::portable) must give bit-identical grids, active masks, changed masks and totals on the
// same input. The inputs are random grids built to reach every branch of the pass: over cells next to
// empty ones (0 -> positive, active bits), E > A and E <= A blocks, obstacle voxels and an obstacle
// tile, odd blocks straddling into missing leaves (deferred), 2D and 3D, every rule, small and
// large Tc (Tc > 2^27 turns the SIMD branch off, so both paths must agree there trivially too).
#include "Kernel.h"

#include <vdbclay/Automaton.h>
#include <vdbclay/Metrics.h>
#include <vdbclay/Rules.h>

#include <openvdb/openvdb.h>

#include <gtest/gtest.h>

#include <cstdint>
#include <vector>

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
Scene makeScene(uint64_t seed, bool is3D, int32_t tc)
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
                    const int kind = g.range(0, 9);
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
               bool useTable = false)
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
    in.portable = portable;
    in.table = useTable ? &table : nullptr;
    // Two ranges, as two tasks would get them, joined in order.
    const size_t half = work.size() / 2;
    PassTotals second;
    processRange(in, work.data(), 0, half, r.tot);
    processRange(in, work.data(), half, work.size(), second);
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
                }
}

/// The flat leaf table (PassInput::table) only replaces the accessor probes: the same passes with and
/// without it, on the SIMD and the portable path, must agree bit for bit. The work list holds anchors
/// the table indexes (every leaf, and the upper neighbours reaching into one) and anchors it does not
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
        Result r[2];
        for (int portable = 0; portable < 2; ++portable) {
            r[portable].mass = std::make_shared<openvdb::Int32Tree>(*s.mass);
            std::vector<WorkItem> work{WorkItem{Origin(0, 0, 0), 1, 0}};
            RuleParams p;
            p.rule = rule;
            p.threshold = tc;
            PassInput in;
            in.tree = r[portable].mass.get();
            in.obstacles = s.obstacles.get();
            in.rule = compileRule(p);
            in.is3D = is3D;
            in.phase = 0;
            in.step = uint64_t(trial);
            in.seed = 3;
            in.portable = portable == 1;
            processRange(in, work.data(), 0, 1, r[portable].tot);
            r[portable].changed.push_back(work[0].changed);
        }
        updated += int(r[1].tot.updated);
        expectSame(r[0], r[1], "trial " + std::to_string(trial));
        if (HasFailure()) break;
    }
    EXPECT_GT(updated, 2000); // most random blocks hold an over cell and an under one
}

} // namespace
