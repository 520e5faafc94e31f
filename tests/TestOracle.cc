// An oracle that is not the code under test: the four rules written again, plainly and slowly, from
// the paper's formulas and the README's table (vdbclay/Rules.h states the same contract), with their
// own arithmetic (128-bit, sorting with the standard library), and a dense Margolus automaton on a
// plain array written from the README's description of the phases. The library's repartitionBlock()
// is checked against the reference on random blocks, and the library's Automaton against the dense
// automaton on whole runs, cell for cell. Nothing here calls the library's rule code: a wrong rule in
// the library disagrees with this file.
#include <vdbclay/Automaton.h>
#include <vdbclay/Rules.h>

#include <openvdb/openvdb.h>

#include <gtest/gtest.h>

#include <algorithm>
#include <cstdint>
#include <random>
#include <vector>

using namespace vdbclay;

namespace reference {

/// The SplitMix64 finaliser (Steele, Lea, Flood 2014), as Rules.h names it.
uint64_t splitMix64Finaliser(uint64_t z)
{
    z = (z ^ (z >> 30)) * 0xBF58476D1CE4E5B9ull;
    z = (z ^ (z >> 27)) * 0x94D049BB133111EBull;
    return z ^ (z >> 31);
}

/// The block hash over (seed, step, x, (y, z)), each folded in with the finaliser.
uint64_t blockHashOf(int32_t x, int32_t y, int32_t z, uint64_t step, uint64_t seed)
{
    uint64_t h = splitMix64Finaliser(seed + 0x9E3779B97F4A7C15ull);
    h = splitMix64Finaliser(h ^ (step * 0xD1B54A32D192ED03ull));
    h = splitMix64Finaliser(h ^ uint64_t(uint32_t(x)));
    h = splitMix64Finaliser(h ^ ((uint64_t(uint32_t(y)) << 32) | uint64_t(uint32_t(z))));
    return h;
}

struct RuleDef {
    Rule rule;
    int64_t tc;
    uint64_t alphaQ32; ///< alpha as the library quantises it: round(alpha 2^32), an exact fraction
};

/// The block's cells in the order of the rotation that starts at hash mod n.
std::vector<int> rotation(int n, uint64_t hash)
{
    std::vector<int> order;
    for (int k = 0; k < n; ++k)
        order.push_back(int((hash % uint64_t(n) + uint64_t(k)) % uint64_t(n)));
    return order;
}

/// Gives @a units single units to the under cells in rotation order: a pass over the cells still
/// below Tc, then a pass over the others (Rules.h: "cells that still have room first"). Room is
/// judged as each unit is given, so a cell that a unit of the first pass fills to Tc is one of "the
/// others" in the second.
void giveUnits(int64_t units, const std::vector<bool>& isUnder, uint64_t hash, int64_t tc,
               std::vector<int64_t>& out)
{
    const std::vector<int> order = rotation(int(out.size()), hash);
    for (bool roomPass : {true, false}) {
        for (int i : order) {
            if (units == 0) return;
            if (!isUnder[i] || (out[i] < tc) != roomPass) continue;
            out[i] += 1;
            units -= 1;
        }
    }
    ASSERT_EQ(units, 0) << "more remainder than under cells";
}

/// Shares @a amount equally over the under cells; the remainder by giveUnits.
void shareEqually(int64_t amount, const std::vector<bool>& isUnder, uint64_t hash, int64_t tc,
                  std::vector<int64_t>& out)
{
    const int64_t count = std::count(isUnder.begin(), isUnder.end(), true);
    const int64_t each = amount / count;
    for (size_t i = 0; i < out.size(); ++i)
        if (isUnder[i]) out[i] += each;
    giveUnits(amount - each * count, isUnder, hash, tc, out);
}

/// One block, the paper's way (see the file comment).
std::vector<int64_t> repartition(const RuleDef& r, const std::vector<int32_t>& mass,
                                 const std::vector<bool>& valid, uint64_t hash)
{
    const size_t n = mass.size();
    std::vector<int64_t> out(mass.begin(), mass.end());
    std::vector<bool> isOver(n), isUnder(n);
    for (size_t i = 0; i < n; ++i) {
        isOver[i] = valid[i] && mass[i] > r.tc;
        isUnder[i] = valid[i] && mass[i] <= r.tc;
    }
    if (std::count(isOver.begin(), isOver.end(), true) == 0 ||
        std::count(isUnder.begin(), isUnder.end(), true) == 0)
        return out;

    if (r.rule == Rule::Arata) { // dm = max(1, floor(alpha m)) leaves each over cell; shared equally
        int64_t given = 0;
        for (size_t i = 0; i < n; ++i) {
            if (!isOver[i]) continue;
            const int64_t dm = std::max<int64_t>(1, int64_t((__int128(mass[i]) * r.alphaQ32) >> 32));
            out[i] -= dm;
            given += dm;
        }
        shareEqually(given, isUnder, hash, r.tc, out);
        return out;
    }
    int64_t excess = 0, room = 0; // E and A of the paper
    for (size_t i = 0; i < n; ++i) {
        if (isOver[i]) excess += mass[i] - r.tc;
        if (isUnder[i]) room += r.tc - mass[i];
    }
    for (size_t i = 0; i < n; ++i)
        if (isOver[i]) out[i] = r.tc; // every rule but Arata's brings the over cells down to Tc
    if (r.rule == Rule::Bingham) {    // rule 1: dm = m - Tc, shared equally
        shareEqually(excess, isUnder, hash, r.tc, out);
        return out;
    }
    if (excess > room) { // rules 2 and 3, E > A: fill every room, then Tc + (E - A) / n
        for (size_t i = 0; i < n; ++i)
            if (isUnder[i]) out[i] = r.tc;
        shareEqually(excess - room, isUnder, hash, r.tc, out);
        return out;
    }
    if (r.rule == Rule::Sorted) { // rule 2, E <= A: emptiest first, ties in rotation order
        std::vector<int> order;
        for (int i : rotation(int(n), hash))
            if (isUnder[i]) order.push_back(i);
        std::stable_sort(order.begin(), order.end(), [&](int a, int b) { return mass[a] < mass[b]; });
        for (int i : order) {
            const int64_t take = std::min(r.tc - out[i], excess);
            out[i] += take;
            excess -= take;
        }
        return out;
    }
    // rule 3, E <= A: m += floor(E (Tc - m) / A); the rounding loss by giveUnits
    int64_t given = 0;
    for (size_t i = 0; i < n; ++i) {
        if (!isUnder[i]) continue;
        const int64_t share = int64_t(__int128(excess) * (r.tc - mass[i]) / room);
        out[i] += share;
        given += share;
    }
    giveUnits(excess - given, isUnder, hash, r.tc, out);
    return out;
}

/// A dense Margolus automaton on the box [0, size)^dims (z = 0 in 2D); everything outside the box
/// is an obstacle. Step t uses blocks whose minimum corner is even (t even) or odd (t odd) on every
/// axis of the dimension; cell i of a block is at (i & 1, (i >> 1) & 1, i >> 2) from that corner.
struct DenseAutomaton {
    int size, dims;
    RuleDef rule;
    uint64_t seed;
    std::vector<int32_t> mass;
    std::vector<bool> obstacle;
    uint64_t step = 0;

    DenseAutomaton(int s, int d, const RuleDef& r, uint64_t sd)
        : size(s), dims(d), rule(r), seed(sd), mass(cells(), 0), obstacle(cells(), false)
    {
    }
    size_t cells() const { return size_t(size) * size * (dims == 3 ? size : 1); }
    bool inside(int x, int y, int z) const
    {
        return x >= 0 && y >= 0 && z >= 0 && x < size && y < size && z < (dims == 3 ? size : 1);
    }
    size_t index(int x, int y, int z) const { return (size_t(z) * size + y) * size + x; }

    void advance()
    {
        const int parity = int(step & 1);
        const int n = dims == 3 ? 8 : 4;
        const int zMax = dims == 3 ? size : 1;
        for (int bz = (dims == 3 ? parity - 2 : 0); bz < zMax; bz += (dims == 3 ? 2 : 1))
            for (int by = parity - 2; by < size; by += 2)
                for (int bx = parity - 2; bx < size; bx += 2) {
                    std::vector<int32_t> m(n, 0);
                    std::vector<bool> valid(n, false);
                    for (int i = 0; i < n; ++i) {
                        const int x = bx + (i & 1), y = by + ((i >> 1) & 1), z = bz + (i >> 2);
                        if (!inside(x, y, z)) continue;
                        m[i] = mass[index(x, y, z)];
                        valid[i] = !obstacle[index(x, y, z)];
                    }
                    const std::vector<int64_t> out =
                        repartition(rule, m, valid, blockHashOf(bx, by, bz, step, seed));
                    for (int i = 0; i < n; ++i) {
                        const int x = bx + (i & 1), y = by + ((i >> 1) & 1), z = bz + (i >> 2);
                        if (inside(x, y, z)) mass[index(x, y, z)] = int32_t(out[i]);
                    }
                }
        ++step;
    }
};

} // namespace reference

namespace {

const Rule kAll[] = {Rule::Arata, Rule::Bingham, Rule::Sorted, Rule::Prorata};

reference::RuleDef defOf(const CompiledRule& c)
{
    return {c.rule, c.threshold, c.alphaQ32};
}

CompiledRule compiled(Rule rule, int32_t tc, double alpha)
{
    RuleParams p;
    p.rule = rule;
    p.threshold = tc;
    p.alpha = alpha;
    return compileRule(p);
}

class Oracle : public ::testing::Test {
protected:
    static void SetUpTestSuite() { openvdb::initialize(); }
};

} // namespace

TEST_F(Oracle, TheBlockHashIsTheDocumentedOne)
{
    std::mt19937_64 rng(11);
    for (int k = 0; k < 10000; ++k) {
        BlockKey key;
        key.x = int32_t(rng());
        key.y = int32_t(rng());
        key.z = int32_t(rng());
        key.step = rng() >> (rng() % 64);
        key.seed = rng();
        ASSERT_EQ(blockHash(key), reference::blockHashOf(key.x, key.y, key.z, key.step, key.seed));
    }
}

TEST_F(Oracle, RandomBlocksMatchThePaperFormulas)
{
    // Masses drawn around Tc (the common case), near 0, and up to the int32 limit; obstacles at
    // random; every rule, 2D and 3D blocks, several Tc and alpha values.
    std::mt19937_64 rng(2003);
    uint64_t blocksThatMoved = 0;
    for (Rule rule : kAll)
        for (int32_t tc : {1, 7, 1000, 1 << 20, INT32_MAX / 3})
            for (double alpha : {0.5, 0.3, 0.97}) {
                if (rule != Rule::Arata && alpha != 0.5) continue;
                const CompiledRule c = compiled(rule, tc, alpha);
                for (int trial = 0; trial < 4000; ++trial) {
                    const int n = trial % 2 ? 8 : 4;
                    std::vector<int32_t> m(n);
                    std::vector<bool> valid(n);
                    uint32_t validBits = 0;
                    const int64_t top = std::min<int64_t>(INT32_MAX / 2, int64_t(tc) * 3);
                    for (int i = 0; i < n; ++i) {
                        switch (rng() % 4) {
                        case 0: m[i] = int32_t(rng() % (uint64_t(tc) + 1)); break;                    // under
                        case 1: m[i] = int32_t(tc + int64_t(rng() % uint64_t(top - tc + 1))); break;  // over
                        case 2: m[i] = int32_t(std::max<int64_t>(0, tc - int64_t(rng() % 3))); break; // at Tc
                        default: m[i] = int32_t(rng() % 3); break; // nearly empty
                        }
                        valid[i] = rng() % 8 != 0;
                        if (valid[i]) validBits |= 1u << i;
                    }
                    BlockKey key;
                    key.x = int32_t(rng() % 2000) - 1000;
                    key.y = int32_t(rng() % 2000) - 1000;
                    key.z = n == 8 ? int32_t(rng() % 2000) - 1000 : 0;
                    key.step = rng() % 100000;
                    key.seed = rng() % 5;
                    std::vector<int64_t> got(n, -1);
                    const uint32_t changed = repartitionBlock(c, n, m.data(), validBits, key, got.data());
                    const std::vector<int64_t> want = reference::repartition(
                        defOf(c), m, valid, reference::blockHashOf(key.x, key.y, key.z, key.step, key.seed));
                    ASSERT_EQ(got, want)
                        << ruleName(rule) << " Tc " << tc << " alpha " << alpha << " trial " << trial;
                    uint32_t differs = 0;
                    for (int i = 0; i < n; ++i)
                        if (want[i] != m[i]) differs |= 1u << i;
                    ASSERT_EQ(changed, differs);
                    if (changed) ++blocksThatMoved;
                }
            }
    EXPECT_GT(blocksThatMoved, 20000u); // the draws exercise the rules, not only unchanged blocks
}

TEST_F(Oracle, WholeRunsMatchADenseAutomatonCellForCell)
{
    // Random clay around Tc with overloads and obstacles inside a closed box (the box's faces are
    // obstacles for the library too), every rule, 2D and 3D, 300 steps, the library on 3 threads.
    for (int dims : {2, 3})
        for (Rule rule : kAll) {
            const int size = dims == 3 ? 14 : 40;
            const int32_t tc = 100;
            const uint64_t seed = 5 + uint64_t(rule);
            const CompiledRule c = compiled(rule, tc, 0.3);
            reference::DenseAutomaton dense(size, dims, defOf(c), seed);
            auto grid = openvdb::Int32Grid::create(0);
            auto walls = openvdb::MaskGrid::create(false);
            std::mt19937_64 rng(31 * dims + int(rule));
            const int zMax = dims == 3 ? size : 1;
            for (int z = -1; z <= zMax; ++z)
                for (int y = -1; y <= size; ++y)
                    for (int x = -1; x <= size; ++x) {
                        if (dims == 2 && z != 0) continue;
                        const openvdb::Coord ijk(x, y, z);
                        if (!dense.inside(x, y, z)) {
                            walls->tree().setValueOn(ijk);
                            continue;
                        }
                        const size_t i = dense.index(x, y, z);
                        if (rng() % 16 == 0) {
                            dense.obstacle[i] = true;
                            walls->tree().setValueOn(ijk);
                            continue;
                        }
                        const uint64_t draw = rng() % 10;
                        const int32_t m = draw < 6 ? int32_t(rng() % (tc + 1))
                                                   : (draw < 9 ? int32_t(tc + rng() % (3 * tc)) : 0);
                        dense.mass[i] = m;
                        if (m) grid->tree().setValue(ijk, m);
                    }
            AutomatonOptions o;
            o.dimensions = dims;
            o.rule.rule = rule;
            o.rule.threshold = tc;
            o.rule.alpha = 0.3;
            o.seed = seed;
            o.threads = 3;
            Automaton a(grid, o, walls);
            for (int step = 0; step < 300; ++step) {
                a.step();
                dense.advance();
            }
            int64_t cellsChecked = 0, clayCells = 0;
            for (int z = 0; z < zMax; ++z)
                for (int y = 0; y < size; ++y)
                    for (int x = 0; x < size; ++x) {
                        const int32_t want = dense.mass[dense.index(x, y, z)];
                        ASSERT_EQ(grid->tree().getValue(openvdb::Coord(x, y, z)), want)
                            << ruleName(rule) << " " << dims << "D at " << x << "," << y << "," << z;
                        ++cellsChecked;
                        if (want) ++clayCells;
                    }
            // Nothing outside the box: every active voxel was among the cells checked.
            EXPECT_EQ(int64_t(grid->tree().activeVoxelCount()), clayCells)
                << ruleName(rule) << " " << dims << "D";
            EXPECT_EQ(a.stepCount(), dense.step);
            EXPECT_GT(cellsChecked, 1000);
        }
}
