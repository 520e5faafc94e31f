// The repartition rules on single blocks, against values computed by hand from the paper's formulas.
#include <vdbclay/Rules.h>

#include "automaton/RulesImpl.h"

#include <gtest/gtest.h>

#include <algorithm>
#include <array>
#include <climits>
#include <map>
#include <numeric>
#include <set>
#include <vector>

using namespace vdbclay;

namespace {

CompiledRule make(Rule r, int32_t tc, double alpha = 0.5)
{
    RuleParams p;
    p.rule = r;
    p.threshold = tc;
    p.alpha = alpha;
    return compileRule(p);
}

BlockKey key(uint64_t step, int x = 0, int y = 0, int z = 0)
{
    BlockKey k;
    k.x = x;
    k.y = y;
    k.z = z;
    k.step = step;
    k.seed = 7;
    return k;
}

struct Result {
    std::vector<int64_t> out;
    uint32_t changed;
};

Result apply(const CompiledRule& r, std::vector<int32_t> m, uint32_t valid = 0xFF, uint64_t step = 0)
{
    const int n = int(m.size());
    Result res;
    res.out.assign(n, -1);
    res.changed = repartitionBlock(r, n, m.data(), valid & ((1u << n) - 1), key(step), res.out.data());
    return res;
}

int64_t sum(const std::vector<int64_t>& v)
{
    return std::accumulate(v.begin(), v.end(), int64_t(0));
}
int64_t sum(const std::vector<int32_t>& v)
{
    return std::accumulate(v.begin(), v.end(), int64_t(0));
}

const Rule kAll[] = {Rule::Arata, Rule::Bingham, Rule::Sorted, Rule::Prorata};

} // namespace

TEST(Rules, NamesRoundTripAndBadNamesAreRefused)
{
    for (Rule r : kAll)
        EXPECT_EQ(parseRule(ruleName(r)), r);
    EXPECT_EQ(parseRule("rule3"), Rule::Prorata);
    try {
        parseRule("rule4");
        FAIL() << "expected an error";
    } catch (const Error& e) {
        EXPECT_NE(std::string(e.what()).find("rule4"), std::string::npos);
        EXPECT_NE(std::string(e.what()).find("prorata"), std::string::npos);
    }
}

TEST(Rules, InvalidParametersAreRefused)
{
    RuleParams p;
    p.threshold = 0;
    EXPECT_THROW(compileRule(p), Error);
    p.threshold = -5;
    EXPECT_THROW(compileRule(p), Error);
    p.threshold = 10;
    for (double a : {0.0, 1.0, -0.1, 1.5, std::numeric_limits<double>::quiet_NaN(),
                     std::numeric_limits<double>::infinity()}) {
        p.alpha = a;
        EXPECT_THROW(compileRule(p), Error) << a;
    }
    p.alpha = 1e-12; // tiny but inside (0, 1): quantised to the smallest step, still valid
    EXPECT_NO_THROW(compileRule(p));
}

TEST(Rules, BlockWithoutOverOrWithoutUnderIsUnchanged)
{
    for (Rule r : kAll) {
        const CompiledRule c = make(r, 100);
        // no over cell (a cell exactly at Tc is under)
        Result a = apply(c, {100, 50, 0, 100});
        EXPECT_EQ(a.changed, 0u);
        EXPECT_EQ(a.out, (std::vector<int64_t>{100, 50, 0, 100}));
        // no under cell
        Result b = apply(c, {101, 500, 300, 200, 101, 101, 150, 999});
        EXPECT_EQ(b.changed, 0u);
        EXPECT_EQ(b.out, (std::vector<int64_t>{101, 500, 300, 200, 101, 101, 150, 999}));
        // the only under cells are obstacles
        Result o = apply(c, {500, 0, 0, 0}, /*valid=*/0x1);
        EXPECT_EQ(o.changed, 0u);
        // empty block
        Result e = apply(c, {0, 0, 0, 0});
        EXPECT_EQ(e.changed, 0u);
    }
}

TEST(Rules, ArataGivesAlphaOfTheMass)
{
    // alpha = 0.5, Tc = 1000: cell 0 (2000) gives 1000; cells 1..3 (100, 0, 0) are under.
    // D = 1000, n = 3: share 333 each, remainder 1 to one cell with room.
    const CompiledRule c = make(Rule::Arata, 1000, 0.5);
    Result r = apply(c, {2000, 100, 0, 0});
    EXPECT_EQ(r.out[0], 1000);
    EXPECT_EQ(sum(r.out), 2100);
    std::vector<int64_t> gains{r.out[1] - 100, r.out[2], r.out[3]};
    std::sort(gains.begin(), gains.end());
    EXPECT_EQ(gains, (std::vector<int64_t>{333, 333, 334}));
    EXPECT_EQ(r.changed, 0xFu);

    // Two over cells, alpha = 0.25: floor(0.25*1201) = 300, floor(0.25*1999) = 499: D = 799, n = 2.
    const CompiledRule q = make(Rule::Arata, 1000, 0.25);
    Result s = apply(q, {1201, 1999, 10, 20});
    EXPECT_EQ(s.out[0], 901);
    EXPECT_EQ(s.out[1], 1500);
    EXPECT_EQ(sum(s.out), 1201 + 1999 + 10 + 20);
    std::vector<int64_t> g2{s.out[2] - 10, s.out[3] - 20};
    std::sort(g2.begin(), g2.end());
    EXPECT_EQ(g2, (std::vector<int64_t>{399, 400}));
}

TEST(Rules, ArataAlwaysMovesAtLeastOneUnit)
{
    // floor(0.1 * 5) = 0: without the minimum of one unit this over cell would be stuck forever.
    const CompiledRule c = make(Rule::Arata, 4, 0.1);
    Result r = apply(c, {5, 0, 0, 0});
    EXPECT_EQ(r.out[0], 4);
    EXPECT_EQ(sum(r.out), 5);
    EXPECT_NE(r.changed, 0u);
}

TEST(Rules, BinghamGivesTheExcessEqually)
{
    // Rule 1: dm = m - Tc. Tc = 1000; 1500 gives 500 to 3 under cells: 166 each, remainder 2.
    const CompiledRule c = make(Rule::Bingham, 1000);
    Result r = apply(c, {1500, 0, 900, 1000});
    EXPECT_EQ(r.out[0], 1000);
    EXPECT_EQ(sum(r.out), 3400);
    std::vector<int64_t> gains{r.out[1], r.out[2] - 900, r.out[3] - 1000};
    std::sort(gains.begin(), gains.end());
    EXPECT_EQ(gains, (std::vector<int64_t>{166, 167, 167}));
    // After the shares only cell 1 (166) still has room, so it gets the first remainder unit for
    // sure; the second goes to cell 2 or 3, whichever the block's hash rotation reaches first.
    EXPECT_EQ(r.out[1], 167);
    EXPECT_EQ(r.out[2] + r.out[3], 1066 + 1166 + 1);

    // 3D: two over cells (1300, 1200) give 300 + 200 = 500 to 6 under cells: 83 each, remainder 2.
    Result s = apply(c, {1300, 1200, 0, 0, 0, 0, 0, 0});
    EXPECT_EQ(s.out[0], 1000);
    EXPECT_EQ(s.out[1], 1000);
    std::multiset<int64_t> got(s.out.begin() + 2, s.out.end());
    EXPECT_EQ(got, (std::multiset<int64_t>{83, 83, 83, 83, 84, 84}));
}

TEST(Rules, SortedFillsTheEmptiestFirst)
{
    // Rule 2, E <= A. Tc = 1000: E = 300; rooms: 900 -> 100, 500 -> 500, 950 -> 50 (A = 650).
    // Sorted by mass: 500 first, which takes all 300.
    const CompiledRule c = make(Rule::Sorted, 1000);
    Result r = apply(c, {1300, 900, 500, 950});
    EXPECT_EQ(r.out, (std::vector<int64_t>{1000, 900, 800, 950}));
    EXPECT_EQ(r.changed, 0x5u);

    // E = 620 <= A = 650: 500 is filled to Tc (takes 500), then 900 (takes 100), then 950 takes
    // the last 20.
    Result s = apply(c, {1620, 900, 500, 950});
    EXPECT_EQ(s.out, (std::vector<int64_t>{1000, 1000, 1000, 970}));
}

TEST(Rules, SortedOverfillsEquallyWhenExcessExceedsRoom)
{
    // Rule 2, E > A: every under cell becomes Tc + (E - A) / n.
    // Tc = 1000: E = 1000; A = 100 + 200 + 0 = 300; (E - A) / 3 = 233, remainder 1.
    const CompiledRule c = make(Rule::Sorted, 1000);
    Result r = apply(c, {2000, 900, 800, 1000});
    EXPECT_EQ(r.out[0], 1000);
    std::multiset<int64_t> got(r.out.begin() + 1, r.out.end());
    EXPECT_EQ(got, (std::multiset<int64_t>{1233, 1233, 1234}));
    EXPECT_EQ(sum(r.out), 4700);
}

TEST(Rules, SortedBreaksTiesByTheBlockHashNotByPosition)
{
    // Two equally empty cells; only one can be filled. Over many steps both must be chosen.
    const CompiledRule c = make(Rule::Sorted, 10);
    std::set<int> winners;
    for (uint64_t step = 0; step < 64; ++step) {
        Result r = apply(c, {15, 0, 0, 10}, 0xF, step);
        EXPECT_EQ(r.out[0], 10);
        EXPECT_EQ(sum(r.out), 25);
        ASSERT_TRUE((r.out[1] == 5 && r.out[2] == 0) || (r.out[1] == 0 && r.out[2] == 5));
        winners.insert(r.out[1] == 5 ? 1 : 2);
    }
    EXPECT_EQ(winners, (std::set<int>{1, 2}));
}

TEST(Rules, ProrataSharesInProportionToRoom)
{
    // Rule 3, E <= A. Tc = 1000, E = 300, rooms 100, 500, 50 (A = 650):
    // floor(300*100/650) = 46, floor(300*500/650) = 230, floor(300*50/650) = 23: 299, one unit left.
    const CompiledRule c = make(Rule::Prorata, 1000);
    Result r = apply(c, {1300, 900, 500, 950});
    EXPECT_EQ(r.out[0], 1000);
    EXPECT_EQ(sum(r.out), 3650);
    const int64_t g1 = r.out[1] - 900, g2 = r.out[2] - 500, g3 = r.out[3] - 950;
    EXPECT_TRUE((g1 == 47 && g2 == 230 && g3 == 23) || (g1 == 46 && g2 == 231 && g3 == 23) ||
                (g1 == 46 && g2 == 230 && g3 == 24))
        << g1 << " " << g2 << " " << g3;

    // Exact division: E = 325, rooms 100, 500, 50 -> 50, 250, 25 with nothing left over.
    Result s = apply(c, {1325, 900, 500, 950});
    EXPECT_EQ(s.out, (std::vector<int64_t>{1000, 950, 750, 975}));
}

TEST(Rules, ProrataWithExcessEqualToRoomFillsEveryCell)
{
    const CompiledRule c = make(Rule::Prorata, 1000);
    Result r = apply(c, {1650, 900, 500, 950});
    EXPECT_EQ(r.out, (std::vector<int64_t>{1000, 1000, 1000, 1000}));
}

TEST(Rules, ProrataWithNoRoomSplitsTheSurplusWithoutDividingByZero)
{
    // A = 0: every under cell is exactly at Tc. E = 500 split over 3 cells: 166, 167, 167.
    const CompiledRule c = make(Rule::Prorata, 1000);
    Result r = apply(c, {1500, 1000, 1000, 1000});
    EXPECT_EQ(r.out[0], 1000);
    std::multiset<int64_t> got(r.out.begin() + 1, r.out.end());
    EXPECT_EQ(got, (std::multiset<int64_t>{1166, 1167, 1167}));
}

TEST(Rules, ProrataWithExcessAboveRoomFillsThenSplits)
{
    // E = 1000 > A = 300: fill rooms to Tc, then (E - A) = 700 over 3 cells: 233, 233, 234.
    const CompiledRule c = make(Rule::Prorata, 1000);
    Result r = apply(c, {2000, 900, 800, 1000});
    std::multiset<int64_t> got(r.out.begin() + 1, r.out.end());
    EXPECT_EQ(got, (std::multiset<int64_t>{1233, 1233, 1234}));
    EXPECT_EQ(r.out[0], 1000);
}

TEST(Rules, ObstacleCellsNeitherGiveNorReceive)
{
    for (Rule rule : kAll) {
        const CompiledRule c = make(rule, 100);
        // cell 1 is an obstacle holding clay over Tc; cell 2 an empty obstacle.
        Result r = apply(c, {400, 700, 0, 0, 0, 0, 0, 0}, /*valid=*/0xFF & ~0x6u);
        EXPECT_EQ(r.out[1], 700) << ruleName(rule);
        EXPECT_EQ(r.out[2], 0) << ruleName(rule);
        EXPECT_EQ(sum(r.out), 1100) << ruleName(rule);
        EXPECT_FALSE(r.changed & 0x6u) << ruleName(rule);
    }
}

TEST(Rules, RemainderChangesFromStepToStepAndPrefersRoom)
{
    // Bingham, Tc = 10: 11 gives 1 unit to 3 empty cells: the share is 0, the remainder 1.
    const CompiledRule c = make(Rule::Bingham, 10);
    std::map<int, int> receiver;
    for (uint64_t step = 0; step < 300; ++step) {
        Result r = apply(c, {11, 0, 0, 0}, 0xF, step);
        int who = -1;
        for (int i = 1; i < 4; ++i)
            if (r.out[i] == 1) who = i;
        ASSERT_NE(who, -1);
        ++receiver[who];
    }
    // All three cells receive the unit, none systematically.
    ASSERT_EQ(receiver.size(), 3u);
    for (auto& kv : receiver)
        EXPECT_GT(kv.second, 50) << "cell " << kv.first;

    // Prefer room: cells 1, 2 at Tc (no room), cell 3 empty: 13 -> D = 3, share 1 each, remainder 0.
    // With 14: D = 4, share 1, remainder 1 must go to cell 3 (the only one with room after shares).
    for (uint64_t step = 0; step < 50; ++step) {
        Result r = apply(c, {14, 10, 10, 0}, 0xF, step);
        EXPECT_EQ(r.out, (std::vector<int64_t>{10, 11, 11, 2}));
    }
}

TEST(Rules, EveryRuleConservesMassOnRandomBlocks)
{
    uint64_t s = 12345;
    auto rnd = [&]() {
        s ^= s << 13;
        s ^= s >> 7;
        s ^= s << 17;
        return s;
    };
    for (Rule rule : kAll) {
        for (int tc : {1, 7, 1000, 1 << 20}) {
            const CompiledRule c = make(rule, tc, 0.37);
            for (int trial = 0; trial < 20000; ++trial) {
                const int n = (trial & 1) ? 8 : 4;
                std::vector<int32_t> m(n);
                for (int i = 0; i < n; ++i)
                    m[i] = int32_t(rnd() % uint64_t(3 * tc + 2));
                const uint32_t valid = uint32_t(rnd()) | uint32_t(rnd()); // mostly valid
                std::vector<int64_t> out(n);
                const uint32_t ch =
                    repartitionBlock(c, n, m.data(), valid & ((1u << n) - 1), key(trial), out.data());
                ASSERT_EQ(sum(out), sum(m));
                for (int i = 0; i < n; ++i) {
                    ASSERT_GE(out[i], 0);
                    if (!((valid >> i) & 1u)) {
                        ASSERT_EQ(out[i], m[i]);
                    }
                    ASSERT_EQ(((ch >> i) & 1u) != 0, out[i] != m[i]);
                    // Over cells never end below Tc except under arata; under cells never lose.
                    if (m[i] <= tc) {
                        ASSERT_GE(out[i], m[i]);
                    }
                    if (ch && rule != Rule::Arata && m[i] > tc && ((valid >> i) & 1u)) {
                        ASSERT_EQ(out[i], tc);
                    }
                }
            }
        }
    }
}

TEST(Rules, ExtremeMassesAreExactIn64Bits)
{
    // Near the worst case of E * room for prorata (see Rules.cc): Tc = 5/8 2^31, 5 over cells at
    // INT32_MAX, 3 empty under cells, E = 5 (2^31 - 1 - Tc) <= A = 3 Tc.
    const int32_t tc = int32_t((5ll << 31) / 8);
    const CompiledRule c = make(Rule::Prorata, tc);
    std::vector<int32_t> m{INT32_MAX, INT32_MAX, INT32_MAX, INT32_MAX, INT32_MAX, 0, 0, 0};
    std::vector<int64_t> out(8);
    repartitionBlock(c, 8, m.data(), 0xFF, key(3), out.data());
    const int64_t e = 5 * (int64_t(INT32_MAX) - tc);
    EXPECT_EQ(sum(out), sum(m));
    for (int i = 5; i < 8; ++i) {
        EXPECT_GE(out[i], e / 3);
        EXPECT_LE(out[i], e / 3 + 1);
    }

    // Bingham with one under cell: 7 (INT32_MAX - 1) lands in one cell, far above INT32_MAX.
    // The rule returns it exactly in 64 bits; the automaton is the one to refuse it.
    const CompiledRule b = make(Rule::Bingham, 1);
    std::vector<int32_t> big(8, INT32_MAX);
    big[7] = 0;
    repartitionBlock(b, 8, big.data(), 0xFF, key(0), out.data());
    EXPECT_EQ(out[7], 7 * (int64_t(INT32_MAX) - 1));
    EXPECT_GT(out[7], INT32_MAX);
}

TEST(Rules, HashDependsOnEveryField)
{
    BlockKey a = key(5, 1, 2, 3);
    const uint64_t h = blockHash(a);
    BlockKey b = a;
    b.x = 2;
    EXPECT_NE(blockHash(b), h);
    b = a;
    b.y = -2;
    EXPECT_NE(blockHash(b), h);
    b = a;
    b.z = 4;
    EXPECT_NE(blockHash(b), h);
    b = a;
    b.step = 6;
    EXPECT_NE(blockHash(b), h);
    b = a;
    b.seed = 8;
    EXPECT_NE(blockHash(b), h);
    EXPECT_EQ(blockHash(a), h);
}

TEST(Rules, BlockSizeMustBeFourOrEight)
{
    const CompiledRule c = make(Rule::Prorata, 10);
    int32_t m[8] = {};
    int64_t out[8];
    EXPECT_THROW(repartitionBlock(c, 6, m, 0xFF, key(0), out), Error);
}

// ---- the kernel's arithmetic shortcuts (lib/src/RulesImpl.h) ------------------------------------

TEST(Rules, DivisionBySmallCountsIsExact)
{
    // a * ceil(2^35 / d) >> 35 for a < 2^28, a division above: compare with '/' on every a below
    // 2^16, around every multiple of d near the switch, and at the extremes.
    for (int d = 1; d <= 8; ++d) {
        for (int64_t a = 0; a < (1 << 16); ++a)
            ASSERT_EQ(rules_internal::divideBySmall(a, d), a / d) << a << "/" << d;
        for (int64_t base : {int64_t(1) << 20, (int64_t(1) << 28) - 64, int64_t(1) << 28, int64_t(1) << 31,
                             (int64_t(1) << 32) - 64, int64_t(1) << 40}) {
            for (int64_t a = base - 64; a < base + 64; ++a) {
                ASSERT_EQ(rules_internal::divideBySmall(a, d), a / d) << a << "/" << d;
            }
        }
        uint64_t s = 99 + uint64_t(d);
        for (int i = 0; i < 200000; ++i) {
            s ^= s << 13;
            s ^= s >> 7;
            s ^= s << 17;
            const int64_t a = int64_t(s >> (1 + (s & 31)));
            ASSERT_EQ(rules_internal::divideBySmall(a, d), a / d) << a << "/" << d;
        }
    }
}

TEST(Rules, HashFromTheStepPrefixEqualsTheBlockHash)
{
    BlockKey k{-5, 7, 1 << 30, (uint64_t(1) << 50) + 9, 0xFEEDull};
    EXPECT_EQ(rules_internal::finishHash(rules_internal::stepPrefix(k.step, k.seed), k.x, k.y, k.z),
              blockHash(k));
}

TEST(Rules, ProrataReciprocalSharesAreExactFloors)
{
    // The common prorata case (E * Tc < 2^32) takes shares from one reciprocal of A: check against
    // the plain division on blocks built to hit exact multiples (E * room divisible by A).
    RuleParams p;
    p.rule = Rule::Prorata;
    p.threshold = 1000;
    const CompiledRule cr = compileRule(p);
    for (int over = 1001; over <= 1064; ++over) {
        for (int u = 0; u <= 1000; u += 7) {
            const int32_t m[8] = {over, u, 1000 - u / 2, 0, 1000, 999, 500, 250};
            int64_t out[8];
            const BlockKey k{1, 2, 3, 4, 5};
            repartitionBlock(cr, 8, m, 0xFFu, k, out);
            const int64_t e = over - 1000;
            int64_t a = 0;
            for (int i = 1; i < 8; ++i)
                a += 1000 - m[i];
            int64_t before = m[0], after = out[0];
            for (int i = 1; i < 8; ++i) {
                const int64_t share = e * (1000 - m[i]) / a;
                EXPECT_GE(out[i] - m[i], share) << over << " " << u << " cell " << i;
                EXPECT_LE(out[i] - m[i], share + 1); // plus at most one unit of the remainder
                before += m[i];
                after += out[i];
            }
            EXPECT_EQ(after, before);
            EXPECT_EQ(out[0], 1000);
        }
    }
}
