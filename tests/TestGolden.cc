// Golden values: the block hash, the rules on random blocks and whole runs of the automaton, each
// pinned to exact numbers that must never change: any kernel, leaf table or gather must reproduce
// every one of them bit for bit. A change here means results changed.
//
// The scenes are built here, from this file's own generator, so no helper elsewhere can move them.
#include <vdbclay/Automaton.h>
#include <vdbclay/Metrics.h>
#include <vdbclay/Rules.h>

#include <openvdb/openvdb.h>

#include <gtest/gtest.h>

#include <string>
#include "TestRng.h"

using namespace vdbclay;
using openvdb::Coord;
using openvdb::CoordBBox;

namespace {

/// The generator of every golden scene (TestRng.h). Never change it.
using Gen = vdbclay_test::Rng;

const Rule kRules[] = {Rule::Arata, Rule::Bingham, Rule::Sorted, Rule::Prorata};

TEST(Golden, BlockHash)
{
    struct Case {
        BlockKey key;
        uint64_t hash;
    };
    const Case cases[] = {
        {{0, 0, 0, 0, 0}, 0x1957a7604e215178ull},
        {{-1, -1, -1, 1, 1}, 0xb270795ba7d66c71ull},
        {{7, -8, 9, 12345, 42}, 0x368957c6c9f7e152ull},
        {{INT32_MAX, INT32_MIN, 0, UINT64_MAX, 0xDEADBEEFCAFEF00Dull}, 0x0cedf6d08dd8dabeull},
        {{-1000000, 3, -7, (uint64_t(1) << 40) + 3, 7}, 0x516024aef8c2208aull},
    };
    for (const Case& c : cases) {
        const uint64_t h = blockHash(c.key);
        EXPECT_EQ(h, c.hash) << c.key.x << "," << c.key.y << "," << c.key.z << " step " << c.key.step;
    }
}

/// Folds every output of @a count random blocks into one hash: the rule, the remainder's rotation
/// and the ties of sorted, on blocks with obstacles, no under cell, E < A, E = A and E > A.
uint64_t blockRunHash(Rule rule, int n, int count)
{
    RuleParams p;
    p.rule = rule;
    p.threshold = 1000;
    p.alpha = 0.37;
    const CompiledRule cr = compileRule(p);
    Gen g(uint64_t(int(rule)) * 16 + uint64_t(n));
    uint64_t h = 0;
    for (int i = 0; i < count; ++i) {
        int32_t m[8];
        const int kind = g.range(0, 3);
        for (int c = 0; c < n; ++c) {
            switch (kind) {
            case 0: m[c] = g.range(0, 2000); break;   // around Tc
            case 1: m[c] = g.range(900, 1100); break; // a saturated lump
            case 2: m[c] = g.range(0, 3) ? g.range(990, 1000) : g.range(1001, 40000); break;
            default: m[c] = g.range(0, 1) ? g.range(0, 5) : g.range(0, INT32_MAX / 8); break;
            }
        }
        const uint32_t valid = g.range(0, 3) ? (1u << n) - 1 : uint32_t(g.next()) & ((1u << n) - 1);
        BlockKey k;
        k.x = g.range(-100000, 100000);
        k.y = g.range(-100000, 100000);
        k.z = g.range(-100000, 100000);
        k.step = g.next() >> g.range(0, 63);
        k.seed = g.next();
        int64_t out[8];
        const uint32_t changed = repartitionBlock(cr, n, m, valid, k, out);
        h = blockHash(BlockKey{int32_t(changed), 0, 0, h, 0});
        for (int c = 0; c < n; ++c)
            h = blockHash(BlockKey{int32_t(out[c]), int32_t(out[c] >> 32), c, h, 1});
    }
    return h;
}

TEST(Golden, RulesOnRandomBlocks)
{
    const uint64_t expected[4][2] = {
        {0x61e945c428d061e9ull, 0x8a62c5e8b29bf1e6ull},
        {0x377bdc2e9647cb66ull, 0xe0c93c769b61687dull},
        {0x468a2cb793bdf20full, 0x006cfe99b8f80970ull},
        {0x6512ef57db10545cull, 0x87c482802a618ec7ull},
    };
    for (Rule rule : kRules) {
        for (int n : {4, 8}) {
            const uint64_t h = blockRunHash(rule, n, 20000);
            EXPECT_EQ(h, expected[int(rule)][n / 8]) << ruleName(rule) << " n " << n;
        }
    }
}

struct RunResult {
    uint64_t hash;
    uint64_t updated;
    uint64_t grown;
    int64_t overload;
};

/// A scene with everything the kernel distinguishes: random clay and obstacles (some holding frozen
/// clay) around the leaf boundaries at -8, 0 and 8, a lump at Tc with a strong overload that must
/// flow out into leaves that do not exist yet, an obstacle tile (a whole 8^3 region), a walled-in
/// cell so large that every step checks for overflow first, and a step counter past 2^40.
RunResult goldenRun(Rule rule, int dims, int threads, uint64_t steps)
{
    Gen g(7 + 10 * uint64_t(int(rule)) + uint64_t(dims));
    auto mass = openvdb::Int32Grid::create(0);
    auto obs = openvdb::MaskGrid::create(false);
    const bool d3 = dims == 3;
    auto acc = mass->getAccessor();
    const CoordBBox region(Coord(-11, -9, d3 ? -10 : 0), Coord(10, 12, d3 ? 9 : 0));
    for (auto it = region.begin(); it; ++it) {
        const Coord c = *it;
        if (g.range(0, 99) < 6) {
            obs->tree().setValueOn(c);
            if (g.range(0, 3)) continue;
        }
        const int v = g.range(0, 2) == 0 ? 0 : g.range(0, 400);
        if (v) acc.setValue(c, v);
    }
    const CoordBBox lumpBox(Coord(20, -3, d3 ? -3 : 0), Coord(27, 4, d3 ? 4 : 0));
    for (auto it = lumpBox.begin(); it; ++it)
        acc.setValue(*it, 100);
    acc.setValue(Coord(23, 0, 0), 100 + 20000);
    acc.setValue(Coord(-3, 2, 0), 300000); // a strong source: clay flows far into new leaves
    // A cell over INT32_MAX / 8, walled in by obstacles (it cannot move): every step then runs the
    // read-only overflow check before writing.
    const Coord big(-40, -40, 0);
    acc.setValue(big, 300000000);
    for (int dx = -1; dx <= 1; ++dx)
        for (int dy = -1; dy <= 1; ++dy)
            for (int dz = d3 ? -1 : 0; dz <= (d3 ? 1 : 0); ++dz)
                if (dx || dy || dz) obs->tree().setValueOn(big.offsetBy(dx, dy, dz));
    // An obstacle tile: the whole leaf at (32, 0, 0) (2D: its z = 0 slice is what matters).
    obs->tree().addTile(1, Coord(32, 0, 0), true, true);
    AutomatonOptions o;
    o.dimensions = dims;
    o.rule.rule = rule;
    o.rule.threshold = 100;
    o.rule.alpha = 0.3;
    o.seed = 0xDEADBEEFCAFEF00Dull;
    o.threads = threads;
    Automaton a(mass, o, obs);
    a.setStepCount((uint64_t(1) << 40) + 1); // starts on an odd step
    const int64_t m0 = a.totalMass();
    const StepReport r = a.run(steps);
    EXPECT_EQ(totalMass(*mass), m0);
    return RunResult{contentHash(*mass), r.blocksUpdated, r.blocksGrown, r.residualOverload};
}

TEST(Golden, RunsPerRuleAndDimension)
{
    openvdb::initialize();
    // [rule][dims == 3]: content hash, blocks updated, blocks grown, residual overload after 200 steps.
    const RunResult expected[4][2] = {
        {{0xefb0af024b2aecb3ull, 33417, 21, 300256069}, {0xe8d654e534360a18ull, 227394, 21, 300000385}},
        {{0xb1cbcfbd72b2685bull, 141006, 116, 300001302}, {0xbc4a4fdbbae08593ull, 251286, 21, 299999992}},
        {{0x6eabe94478f3d8bdull, 118991, 100, 300000590}, {0x4f4e7ca61627f0b5ull, 250450, 23, 300000023}},
        {{0xc295de24b516bb34ull, 120821, 119, 300000720}, {0x1a10b4f45414168cull, 228373, 16, 299999974}},
    };
    for (Rule rule : kRules) {
        for (int dims : {2, 3}) {
            for (int threads : {1, 0}) {
                const RunResult r = goldenRun(rule, dims, threads, 200);
                const RunResult& e = expected[int(rule)][dims == 3];
                const std::string what = std::string(ruleName(rule)) + " " + std::to_string(dims) +
                                         "D threads " + std::to_string(threads);
                EXPECT_EQ(r.hash, e.hash) << what;
                EXPECT_EQ(r.updated, e.updated) << what;
                EXPECT_EQ(r.grown, e.grown) << what;
                EXPECT_EQ(r.overload, e.overload) << what;
            }
        }
    }
}

} // namespace
