// The automaton on sparse OpenVDB grids: a dense oracle, conservation, leaf boundaries, threads.
#include <vdbclay/Automaton.h>
#include <vdbclay/Metrics.h>
#include <vdbclay/Rules.h>

#include "automaton/AutomatonInternal.h"
#include "automaton/Candidates.h"

#include <openvdb/openvdb.h>

#include <gtest/gtest.h>

#include <algorithm>
#include <climits>
#include <cstdio>
#include <memory>
#include <string>
#include <vector>

#include <signal.h>
#include <sys/wait.h>
#include <unistd.h>

#include "CandidatesTesting.h"
#include "SanitizerBuild.h"
#include "TestRng.h"

using namespace vdbclay;
using openvdb::Coord;
using openvdb::CoordBBox;

namespace {

const Rule kAll[] = {Rule::Arata, Rule::Bingham, Rule::Sorted, Rule::Prorata};

class AutomatonTest : public ::testing::Test {
protected:
    static void SetUpTestSuite() { openvdb::initialize(); }
};

using vdbclay_test::Rng;

openvdb::Int32Grid::Ptr newMass()
{
    auto g = openvdb::Int32Grid::create(0);
    g->setName("mass");
    return g;
}

AutomatonOptions options(Rule r, int dims = 3, int32_t tc = 100, int threads = 0, uint64_t seed = 1)
{
    AutomatonOptions o;
    o.dimensions = dims;
    o.rule.rule = r;
    o.rule.threshold = tc;
    o.rule.alpha = 0.3;
    o.seed = seed;
    o.threads = threads;
    return o;
}

/// The plain implementation: a dense box, every block of the phase visited every step, same rule
/// functions and the same block hash. Cells outside the box are 0 and must never receive clay.
struct Dense {
    CoordBBox box;
    int dims;
    std::vector<int32_t> m;
    std::vector<uint8_t> obs;
    bool leaked = false;

    Dense(const CoordBBox& b, int d) : box(b), dims(d)
    {
        m.assign(box.volume(), 0);
        obs.assign(box.volume(), 0);
    }
    bool inside(const Coord& c) const { return box.isInside(c); }
    size_t idx(const Coord& c) const
    {
        const Coord d = c - box.min();
        const Coord e = box.extents();
        return (size_t(d.x()) * e.y() + d.y()) * e.z() + d.z();
    }
    int32_t get(const Coord& c) const { return inside(c) ? m[idx(c)] : 0; }
    bool isObs(const Coord& c) const { return inside(c) && obs[idx(c)]; }

    static int floorStart(int lo, int phase)
    {
        // the largest s <= lo with s = phase (mod 2)
        int s = lo - 1;
        if (((s - phase) % 2 + 2) % 2) --s;
        return s;
    }

    void step(const CompiledRule& rule, uint64_t step, uint64_t seed)
    {
        const int p = int(step & 1);
        const int n = dims == 3 ? 8 : 4;
        const int z0 = dims == 3 ? floorStart(box.min().z(), p) : 0;
        const int z1 = dims == 3 ? box.max().z() : 0;
        for (int x = floorStart(box.min().x(), p); x <= box.max().x(); x += 2)
            for (int y = floorStart(box.min().y(), p); y <= box.max().y(); y += 2)
                for (int z = z0; z <= z1; z += 2) {
                    int32_t mm[8];
                    uint32_t valid = 0;
                    Coord cc[8];
                    for (int c = 0; c < n; ++c) {
                        cc[c] = Coord(x + (c & 1), y + ((c >> 1) & 1), z + (c >> 2));
                        mm[c] = get(cc[c]);
                        if (!isObs(cc[c])) valid |= 1u << c;
                    }
                    BlockKey k;
                    k.x = x;
                    k.y = y;
                    k.z = z;
                    k.step = step;
                    k.seed = seed;
                    int64_t out[8];
                    const uint32_t ch = repartitionBlock(rule, n, mm, valid, k, out);
                    for (int c = 0; c < n; ++c) {
                        if (!((ch >> c) & 1u)) continue;
                        if (!inside(cc[c])) {
                            leaked = true;
                            continue;
                        }
                        m[idx(cc[c])] = int32_t(out[c]);
                    }
                }
    }
};

/// Fills @a grid (and the oracle) with random clay in @a region, obstacles with probability pObs.
void randomScene(Rng& rng, const CoordBBox& region, int dims, int maxMass, int pObsPercent,
                 openvdb::Int32Grid& grid, openvdb::MaskGrid* obstacles, Dense* dense)
{
    auto acc = grid.getAccessor();
    for (auto it = region.begin(); it; ++it) {
        const Coord c = *it;
        if (dims == 2 && c.z() != 0) continue;
        if (obstacles && rng.range(0, 99) < pObsPercent) {
            obstacles->tree().setValueOn(c);
            if (dense) dense->obs[dense->idx(c)] = 1;
            if (rng.range(0, 3) == 0) continue; // some obstacles hold frozen clay
        }
        const int v = rng.range(0, 2) == 0 ? 0 : rng.range(0, maxMass);
        if (v) {
            acc.setValue(c, v);
            if (dense) dense->m[dense->idx(c)] = v;
        }
    }
}

::testing::AssertionResult sameAsDense(const openvdb::Int32Grid& grid, const Dense& d)
{
    if (d.leaked) return ::testing::AssertionFailure() << "oracle box too small: clay left it";
    auto acc = grid.getConstAccessor();
    for (auto it = d.box.begin(); it; ++it) {
        const Coord c = *it;
        if (d.dims == 2 && c.z() != 0) continue;
        const int32_t a = acc.getValue(c), b = d.get(c);
        if (a != b) {
            return ::testing::AssertionFailure() << "voxel (" << c.x() << "," << c.y() << "," << c.z()
                                                 << "): sparse " << a << ", dense " << b;
        }
    }
    for (auto it = grid.tree().cbeginValueOn(); it; ++it) {
        if (!d.box.isInside(it.getCoord()))
            return ::testing::AssertionFailure() << "sparse clay outside the oracle's box";
    }
    return ::testing::AssertionSuccess();
}

openvdb::Int32Grid::Ptr lump(const CoordBBox& box, int32_t value)
{
    auto g = newMass();
    g->tree().fill(box, value, true);
    g->tree().voxelizeActiveTiles();
    return g;
}

} // namespace

// ---- the dense oracle ----------------------------------------------------------------------------

class OracleTest : public AutomatonTest, public ::testing::WithParamInterface<std::tuple<Rule, int>> {};

TEST_P(OracleTest, SparseEqualsDenseCellForCellEveryStep)
{
    const Rule rule = std::get<0>(GetParam());
    const int dims = std::get<1>(GetParam());
    for (int trial = 0; trial < 3; ++trial) {
        Rng rng(100 * trial + int(rule) + 10 * dims);
        // Clay spans negative coordinates and leaf boundaries at -8, 0 and 8.
        const CoordBBox region(Coord(-9, -7, dims == 3 ? -10 : 0), Coord(9, 10, dims == 3 ? 8 : 0));
        const CoordBBox box(Coord(-40, -40, dims == 3 ? -40 : 0), Coord(40, 40, dims == 3 ? 40 : 0));
        Dense dense(box, dims);
        auto mass = newMass();
        auto obs = openvdb::MaskGrid::create(false);
        randomScene(rng, region, dims, 300, 8, *mass, obs.get(), &dense);
        const AutomatonOptions opt = options(rule, dims, 100, 0, 42 + trial);
        Automaton a(mass, opt, obs);
        const CompiledRule cr = compileRule(opt.rule);
        const int64_t m0 = a.totalMass();
        for (uint64_t s = 0; s < 80; ++s) {
            a.step();
            dense.step(cr, s, opt.seed);
            ASSERT_TRUE(sameAsDense(*mass, dense))
                << ruleName(rule) << " " << dims << "D trial " << trial << " after step " << s;
            ASSERT_EQ(totalMass(*mass), m0);
        }
        ASSERT_EQ(a.residualOverload(), residualOverload(*mass, 100, obs.get()));
    }
}

INSTANTIATE_TEST_SUITE_P(AllRules, OracleTest,
                         ::testing::Combine(::testing::ValuesIn(kAll), ::testing::Values(2, 3)),
                         [](const auto& info) {
                             return std::string(ruleName(std::get<0>(info.param))) + "_" +
                                    std::to_string(std::get<1>(info.param)) + "D";
                         });

TEST_F(AutomatonTest, BlocksStraddlingLeavesAndNegativeCoordinates)
{
    // A single overloaded cell at or next to every kind of leaf boundary, each rule, against the
    // oracle, for enough steps that the clay crosses into the neighbouring leaves.
    const Coord spots[] = {Coord(7, 7, 7),    Coord(8, 8, 8),  Coord(0, 0, 0),   Coord(-1, -1, -1),
                           Coord(-8, -8, -8), Coord(-9, 7, 8), Coord(15, -9, 7), Coord(7, 0, -1)};
    for (Rule rule : kAll) {
        for (const Coord& spot : spots) {
            for (int dims : {2, 3}) {
                const Coord s(spot.x(), spot.y(), dims == 3 ? spot.z() : 0);
                const CoordBBox box(s.offsetBy(-14), s.offsetBy(14));
                const CoordBBox b2 = dims == 3 ? box
                                               : CoordBBox(Coord(box.min().x(), box.min().y(), 0),
                                                           Coord(box.max().x(), box.max().y(), 0));
                Dense dense(b2, dims);
                auto mass = newMass();
                mass->tree().setValue(s, 2500);
                dense.m[dense.idx(s)] = 2500;
                const AutomatonOptions opt = options(rule, dims, 100);
                Automaton a(mass, opt);
                const CompiledRule cr = compileRule(opt.rule);
                for (uint64_t st = 0; st < 24; ++st) {
                    a.step();
                    dense.step(cr, st, opt.seed);
                    ASSERT_TRUE(sameAsDense(*mass, dense))
                        << ruleName(rule) << " spot " << s << " " << dims << "D step " << st;
                }
                // clay did reach the neighbouring leaves
                EXPECT_GT(mass->tree().leafCount(), 1u) << ruleName(rule) << " " << s;
                EXPECT_EQ(totalMass(*mass), 2500);
            }
        }
    }
}

// ---- conservation --------------------------------------------------------------------------------

TEST_F(AutomatonTest, MassIsExactOverHundredThousandStepsWithObstacles)
{
    // Random clay in a box of obstacles that straddles leaf boundaries. Every 10 steps a random
    // "tool" gathers clay from a few cells into one through edit(), so the automaton never goes quiet.
    const uint64_t kSteps = 100000;
    for (Rule rule : kAll) {
        Rng rng(777 + int(rule));
        auto mass = newMass();
        auto obs = openvdb::MaskGrid::create(false);
        const CoordBBox inner(Coord(-5, -5, -5), Coord(4, 4, 4));
        const CoordBBox wall(inner.min().offsetBy(-1), inner.max().offsetBy(1));
        for (auto it = wall.begin(); it; ++it)
            if (!inner.isInside(*it)) obs->tree().setValueOn(*it);
        randomScene(rng, inner, 3, 190, 5, *mass, obs.get(), nullptr);
        Automaton a(mass, options(rule, 3, 100, 0, 9), obs);
        const int64_t m0 = totalMass(*mass);
        ASSERT_GT(m0, 0);
        ASSERT_EQ(a.totalMass(), m0);
        uint64_t activeSteps = 0;
        for (uint64_t done = 0; done < kSteps; done += 10) {
            for (int i = 0; i < 10; ++i) {
                const StepReport r = a.step();
                activeSteps += r.blocksUpdated ? 1 : 0;
            }
            if (done % 1000 == 0) {
                ASSERT_EQ(totalMass(*mass), m0) << ruleName(rule) << " after " << done + 10 << " steps";
            }
            // gather the clay of 8 random cells into one random cell, inside the box
            const Coord to(rng.range(-5, 4), rng.range(-5, 4), rng.range(-5, 4));
            a.edit(Box{{{-5, -5, -5}}, {{4, 4, 4}}}, [&](MassGrid& g) {
                auto acc = g.getAccessor();
                for (int k = 0; k < 8; ++k) {
                    const Coord from(rng.range(-5, 4), rng.range(-5, 4), rng.range(-5, 4));
                    const int32_t v = acc.getValue(from);
                    acc.setValue(from, 0);
                    acc.setValue(to, acc.getValue(to) + v);
                }
            });
            ASSERT_EQ(a.totalMass(), m0);
        }
        ASSERT_EQ(totalMass(*mass), m0);
        EXPECT_EQ(a.stepCount(), kSteps);
        EXPECT_GT(activeSteps, kSteps / 4) << ruleName(rule) << ": the scene should stay active";
        EXPECT_EQ(a.residualOverload(), residualOverload(*mass, 100, obs.get()));
    }
}

// ---- determinism ---------------------------------------------------------------------------------

TEST_F(AutomatonTest, SameHashOnOneTwoThreeAndEightThreads)
{
    for (Rule rule : kAll) {
        std::vector<uint64_t> hashes;
        std::vector<uint64_t> updated;
        for (int threads : {1, 2, 3, 8}) {
            Rng rng(5);
            auto mass = newMass();
            auto obs = openvdb::MaskGrid::create(false);
            randomScene(rng, CoordBBox(Coord(-20, -12, -20), Coord(20, 12, 20)), 3, 260, 3, *mass, obs.get(),
                        nullptr);
            Automaton a(mass, options(rule, 3, 100, threads, 3), obs);
            const int64_t m0 = a.totalMass();
            const StepReport r = a.run(60);
            ASSERT_EQ(totalMass(*mass), m0);
            hashes.push_back(contentHash(*mass));
            updated.push_back(r.blocksUpdated);
        }
        for (size_t i = 1; i < hashes.size(); ++i) {
            EXPECT_EQ(hashes[i], hashes[0]) << ruleName(rule) << " thread config " << i;
            EXPECT_EQ(updated[i], updated[0]) << ruleName(rule);
        }
        EXPECT_GT(updated[0], 1000u);
    }
}

TEST_F(AutomatonTest, ThePassGivesTheSameStepsOnAnyThreadCount)
{
    // The pass on several threads (PassEngine.h): chunks cut by the measured speed, run on the crew,
    // chunk 0 predraining. Every item exactly once: the same hash, and the same blocks examined,
    // over Tc and updated (a lost or doubled item changes the counts), as one thread (no chunks).
    for (Rule rule : {Rule::Prorata, Rule::Arata}) {
        for (int dims : {2, 3}) {
            auto runOnce = [&](int threads) {
                Rng rng(11);
                auto mass = newMass();
                auto obs = openvdb::MaskGrid::create(false);
                const int z = dims == 3 ? 20 : 0;
                randomScene(rng, CoordBBox(Coord(-20, -12, -z), Coord(20, 12, z)), dims, 260, 3, *mass,
                            obs.get(), nullptr);
                Automaton a(mass, options(rule, dims, 100, threads, 3), obs);
                const StepReport r = a.run(80);
                return std::vector<uint64_t>{contentHash(*mass), r.blocksVisited, r.blocksUpdated,
                                             r.blocksOverTc};
            };
            const std::vector<uint64_t> expected = runOnce(1);
            EXPECT_GT(expected[2], 1000u);
            for (int threads : {2, 3, 8})
                EXPECT_EQ(runOnce(threads), expected)
                    << ruleName(rule) << " " << dims << "D, " << threads << " threads";
        }
    }
}

TEST_F(AutomatonTest, AForkedChildGoesOnWithThreadsOfItsOwnAndTheSameResult)
{
#if defined(VDBCLAY_TSAN) || defined(VDBCLAY_ASAN)
    GTEST_SKIP() << "a sanitizer runtime is not fork-safe with threads running";
#else
    // Python's multiprocessing forks a process that holds automata. The child has the automaton's
    // pass crew but not its helper threads (PassCrew.h, "fork()"): it must make its own, settle to
    // the same clay as the parent, and destroy the automaton without waiting for the parent's helpers.
    Rng rng(23);
    auto mass = newMass();
    auto obs = openvdb::MaskGrid::create(false);
    randomScene(rng, CoordBBox(Coord(-20, -12, -20), Coord(20, 12, 20)), 3, 260, 3, *mass, obs.get(),
                nullptr);
    auto a = std::make_unique<Automaton>(mass, options(Rule::Prorata, 3, 100, 2, 3), obs);
    const int64_t m0 = a->totalMass();
    EXPECT_GT(a->run(4).blocksUpdated, 100u);
    int fds[2];
    ASSERT_EQ(pipe(fds), 0);
    const pid_t child = fork();
    ASSERT_GE(child, 0);
    if (child == 0) {
        alarm(120); // a hang ends the child (SIGALRM), which the parent reports
        close(fds[0]);
        const StepReport r = a->run(60);
        const uint64_t got[3] = {contentHash(*mass), r.blocksUpdated, uint64_t(totalMass(*mass) == m0)};
        a.reset(); // the automaton's crew, made in the parent, destroyed in the child
        const bool sent = write(fds[1], got, sizeof got) == ssize_t(sizeof got);
        _exit(sent ? 0 : 1);
    }
    close(fds[1]);
    const StepReport r = a->run(60);
    uint64_t got[3] = {0, 0, 0};
    const ssize_t n = read(fds[0], got, sizeof got);
    close(fds[0]);
    int status = 0;
    ASSERT_EQ(waitpid(child, &status, 0), child);
    ASSERT_TRUE(WIFEXITED(status)) << "the child died of signal "
                                   << (WIFSIGNALED(status) ? WTERMSIG(status) : 0);
    EXPECT_EQ(WEXITSTATUS(status), 0);
    ASSERT_EQ(n, ssize_t(sizeof got));
    EXPECT_EQ(got[0], contentHash(*mass));
    EXPECT_EQ(got[1], r.blocksUpdated);
    EXPECT_GT(r.blocksUpdated, 100u); // the child had work to do
    EXPECT_EQ(got[2], 1u);            // the child's mass was exact
    EXPECT_EQ(totalMass(*mass), m0);
#endif
}

TEST_F(AutomatonTest, PassIdleCountsTheThreadSecondsThePassesLeftUnused)
{
    // StageSeconds::passBusy (the thread-seconds the passes' chunks ran) and passIdle (threads x the
    // passes' time, minus passBusy). They are times, so only their bounds are exact: busy more than 0
    // once a pass ran; idle 0 on one thread (no pass is shared); both within the threads' capacity
    // over the repartition (the passes lie inside it); and on several threads idle more than 0 (every
    // lane waits at least while the caller cuts the work list, before the chunks start).
    auto runOnce = [&](int threads, StepReport& first, StepReport& second) {
        Rng rng(11);
        auto mass = newMass();
        randomScene(rng, CoordBBox(Coord(-20, -12, -20), Coord(20, 12, 20)), 3, 260, 3, *mass, nullptr,
                    nullptr);
        Automaton a(mass, options(Rule::Prorata, 3, 100, threads, 3));
        first = a.run(40);
        second = a.run(40);
    };
    for (int threads : {1, 2, 3}) {
        StepReport first, second;
        runOnce(threads, first, second);
        ASSERT_GT(first.blocksUpdated, 1000u);
        StepReport sum = first;
        sum += second;
        EXPECT_EQ(sum.seconds.passIdle, first.seconds.passIdle + second.seconds.passIdle);
        EXPECT_EQ(sum.seconds.passBusy, first.seconds.passBusy + second.seconds.passBusy);
        const double idle = sum.seconds.passIdle, busy = sum.seconds.passBusy;
        const double capacity = threads * sum.seconds.repartition;
        EXPECT_GT(busy, 0.0) << threads << " threads";
        EXPECT_LE(idle + busy, capacity * (1 + 1e-9)) << threads << " threads";
        if (threads == 1) {
            EXPECT_EQ(idle, 0.0);
        } else {
            EXPECT_GT(idle, 0.0) << threads << " threads";
        }
    }
}

TEST_F(AutomatonTest, PredrainLeavesEveryGatherUnchanged)
{
    // Candidates::predrain, as the pass engine calls it: the items below a cut recorded (random
    // lanes), then the next step's slot drained below the reach of the items after the cut, then
    // those recorded. Against a twin without predrain: the same work lists, step after step, with
    // edits, quiet steps, detach/attach and missed sinks (predrain undone) among them. A predrain
    // that drained an entry a later item still writes, or lost or repeated one, changes a list.
    using namespace automaton_internal;
    uint64_t predrainedAll = 0;
    uint64_t undone = 0; // steps whose predrain was undone or dropped (the next gather not dense)
    for (int is3D = 0; is3D < 2; ++is3D) {
        for (uint64_t seed = 1; seed <= 8; ++seed) {
            Rng g(seed * 17 + uint64_t(is3D));
            const int side = is3D ? 9 : 20;
            const vdbclay_test::RandomAnchorIndex table(g, side, is3D != 0, 3);
            const std::vector<Origin>& keys = table.keys;
            const AnchorIndex& index = table.index;
            auto less = vdbclay_test::RandomAnchorIndex::less;
            std::vector<Origin> hot;
            for (int i = 0; i < 40; ++i)
                hot.push_back(keys[size_t(g.range(0, int(keys.size()) - 1))]);
            std::sort(hot.begin(), hot.end(), less);
            hot.erase(std::unique(hot.begin(), hot.end()), hot.end());
            Candidates ref, pre;
            ref.reset(hot);
            pre.reset(hot);
            ref.attach(index, 0, is3D);
            pre.attach(index, 0, is3D);
            uint64_t predrained = 0;
            for (int t = 0; t < 80; ++t) {
                const int phase = t & 1;
                const int event = g.range(0, 19);
                if (event == 0) {
                    const Box b{{g.range(0, 8 * side), g.range(0, 8 * side), is3D ? g.range(0, 8 * side) : 0},
                                {0, 0, 0}};
                    const Box e{b.min, {b.min[0] + 9, b.min[1] + 9, is3D ? b.min[2] + 9 : 0}};
                    ref.addRegion(e);
                    pre.addRegion(e);
                    undone += pre.predrained() > 0;
                } else if (event == 1) {
                    undone += pre.predrained() > 0;
                    ref.detach();
                    pre.detach();
                    ref.attach(index, phase, is3D);
                    pre.attach(index, phase, is3D);
                }
                std::vector<WorkItem> wr, wp;
                ref.gather(phase, is3D, wr);
                pre.gather(phase, is3D, wp);
                ASSERT_EQ(wp.size(), wr.size()) << "seed " << seed << " step " << t;
                for (size_t i = 0; i < wr.size(); ++i) {
                    ASSERT_EQ(wp[i].anchor, wr[i].anchor)
                        << "seed " << seed << " step " << t << " item " << i;
                    ASSERT_EQ(wp[i].mask, wr[i].mask) << "seed " << seed << " step " << t << " item " << i;
                    ASSERT_EQ(wp[i].entry, wr[i].entry) << "seed " << seed << " step " << t << " item " << i;
                }
                if (event == 2) { // no over cell
                    undone += pre.predrained() > 0;
                    ref.clearChanges();
                    pre.clearChanges();
                    ref.endStep();
                    pre.endStep();
                    continue;
                }
                for (size_t i = 0; i < wr.size(); ++i)
                    wr[i].changed = wp[i].changed = wr[i].mask & g.next() & (g.next() | g.next());
                auto sinkOne = [&](const DenseSink& s, const WorkItem& w) {
                    if (!w.changed || w.entry == kNoEntry) return;
                    vdbclay_test::sinkChangesAt(phase, is3D != 0, s, w.entry, w.changed);
                };
                const DenseSink* sr = ref.lanes(2);
                const DenseSink* sp = pre.lanes(2);
                ASSERT_TRUE(sr && sp);
                for (const WorkItem& w : wr)
                    sinkOne(sr[g.range(0, 1)], w);
                const size_t cut = size_t(g.range(0, int(wp.size())));
                for (size_t i = 0; i < cut; ++i)
                    sinkOne(sp[g.range(0, 1)], wp[i]);
                if (cut < wp.size()) pre.predrain(phase, wp[cut].entry);
                predrained += pre.predrained() > 0;
                for (size_t i = cut; i < wp.size(); ++i)
                    sinkOne(sp[g.range(0, 1)], wp[i]);
                if (event == 3) { // a range ran outside the lanes: record() records every item
                    undone += pre.predrained() > 0;
                    ref.sinkMissed();
                    pre.sinkMissed();
                }
                ref.record(wr);
                pre.record(wp);
                ref.endStep();
                pre.endStep();
            }
            EXPECT_GT(predrained, 0u) << "seed " << seed;
            predrainedAll += predrained;
        }
    }
    std::printf("steps predrained %llu, undone %llu\n", (unsigned long long)predrainedAll,
                (unsigned long long)undone);
    EXPECT_GT(predrainedAll, 100u);
    EXPECT_GT(undone, 10u);
}

TEST_F(AutomatonTest, PrunedCandidatesChangeOnlyTheBlocksVisited)
{
    // The pass wakes a block of the other phase only through cells that were or went over Tc, and
    // its own blocks two steps on only while they hold an over and a not-over cell (sinkActive).
    // Against the full bookkeeping (automaton_internal::setPruneCandidates off), step by step: the same
    // grid, the same blocks updated and the same overload, with fewer blocks visited. A third
    // automaton switches pruning on and off every few steps and is edited midway (the two
    // bookkeepings must mix). Every rule, 2D and 3D, obstacles, 1 and 3 threads.
    for (Rule rule : kAll) {
        for (int dims : {2, 3}) {
            for (int threads : {1, 3}) {
                const int z = dims == 3 ? 10 : 0;
                const CoordBBox body(Coord(-14, -10, -z), Coord(14, 10, z));
                const CoordBBox hot(Coord(-4, 4, -std::min(z, 4)), Coord(4, 10, std::min(z, 4)));
                std::vector<openvdb::Int32Grid::Ptr> grids;
                std::vector<std::unique_ptr<Automaton>> autos;
                for (int k = 0; k < 3; ++k) {
                    Rng rng(17 + uint64_t(dims));
                    auto mass = newMass();
                    auto obs = openvdb::MaskGrid::create(false);
                    mass->tree().fill(body, 80, true); // clay at 0.8 Tc
                    mass->tree().voxelizeActiveTiles();
                    randomScene(rng, hot, dims, 400, 3, *mass, obs.get(), nullptr);
                    if (dims == 2) { // the fill covered z != 0 too: 2D clay lives in z = 0 only
                        auto acc = mass->getAccessor();
                        for (auto it = body.begin(); it; ++it)
                            if ((*it).z() != 0) acc.setValueOff(*it, 0);
                        mass->tree().prune();
                    }
                    grids.push_back(mass);
                    autos.push_back(
                        std::make_unique<Automaton>(mass, options(rule, dims, 100, threads, 5), obs));
                }
                Automaton& pruned = *autos[0];
                Automaton& full = *autos[1];
                Automaton& mixed = *autos[2];
                EXPECT_TRUE(automaton_internal::pruneCandidates(pruned));
                automaton_internal::setPruneCandidates(full, false);
                uint64_t visitedPruned = 0, visitedFull = 0, updated = 0;
                const std::string what = std::string(ruleName(rule)) + " " + std::to_string(dims) + "D " +
                                         std::to_string(threads) + " threads";
                for (int t = 0; t < 400; ++t) {
                    if (t == 150) { // an edit: more clay dropped on top, in all three
                        const Box region{{-2, 8, 0}, {2, 10, dims == 3 ? 2 : 0}};
                        for (Automaton* a : {&pruned, &full, &mixed})
                            a->edit(region, [&](openvdb::Int32Grid& g) {
                                auto acc = g.getAccessor();
                                for (int x = -2; x <= 2; ++x)
                                    for (int y = 8; y <= 10; ++y)
                                        for (int zz = 0; zz <= (dims == 3 ? 2 : 0); ++zz)
                                            acc.setValue(Coord(x, y, zz),
                                                         acc.getValue(Coord(x, y, zz)) + 300);
                            });
                    }
                    automaton_internal::setPruneCandidates(mixed, (t / 7) % 2 == 0);
                    const StepReport a = pruned.step(), b = full.step(), c = mixed.step();
                    ASSERT_EQ(a.blocksUpdated, b.blocksUpdated) << what << " step " << t;
                    ASSERT_EQ(c.blocksUpdated, b.blocksUpdated) << what << " step " << t;
                    ASSERT_EQ(a.residualOverload, b.residualOverload) << what << " step " << t;
                    ASSERT_LE(a.blocksVisited, b.blocksVisited) << what << " step " << t;
                    if (t % 25 == 0 || t == 399) {
                        ASSERT_EQ(contentHash(*grids[0]), contentHash(*grids[1])) << what << " step " << t;
                        ASSERT_EQ(contentHash(*grids[2]), contentHash(*grids[1])) << what << " step " << t;
                    }
                    visitedPruned += a.blocksVisited;
                    visitedFull += b.blocksVisited;
                    updated += a.blocksUpdated;
                }
                EXPECT_GT(updated, dims == 3 ? 2000u : 500u) << what;
                EXPECT_LT(visitedPruned, visitedFull) << what; // the pruning did prune
            }
        }
    }
}

TEST_F(AutomatonTest, SeedChangesTheResultButNotTheMass)
{
    auto run = [](uint64_t seed) {
        auto mass = lump(CoordBBox(Coord(0, 0, 0), Coord(5, 5, 5)), 100);
        mass->tree().setValue(Coord(2, 2, 2), 5000);
        Automaton a(mass, options(Rule::Bingham, 3, 100, 0, seed));
        a.run(40);
        EXPECT_EQ(totalMass(*mass), 216 * 100 - 100 + 5000);
        return contentHash(*mass);
    };
    EXPECT_EQ(run(1), run(1));
    EXPECT_NE(run(1), run(2));
}

// ---- settling ------------------------------------------------------------------------------------

TEST_F(AutomatonTest, CompactLumpWithOneOverloadedCellSettles)
{
    // Every cell exactly at Tc (nearly incompressible clay), one cell overloaded by 40 Tc. The
    // excess must travel through the lump to its free surface and the automaton must settle.
    const int32_t tc = 100;
    const CoordBBox cube(Coord(-4, -4, -4), Coord(3, 3, 3)); // straddles leaves on every axis
    for (Rule rule : kAll) {
        for (int dims : {2, 3}) {
            const CoordBBox c = dims == 3 ? cube : CoordBBox(Coord(-4, -4, 0), Coord(3, 3, 0));
            auto mass = lump(c, tc);
            const int64_t excess = 40 * tc;
            mass->tree().setValue(Coord(0, 0, 0), int32_t(tc + excess));
            Automaton a(mass, options(rule, dims, tc));
            const int64_t m0 = a.totalMass();
            const StepReport r = a.settle(200000);
            ASSERT_TRUE(r.settled) << ruleName(rule) << " " << dims << "D";
            EXPECT_EQ(r.reason, StopReason::Settled);
            EXPECT_EQ(r.residualOverload, 0);
            EXPECT_EQ(totalMass(*mass), m0);
            EXPECT_EQ(residualOverload(*mass, tc, nullptr), 0);
            int64_t outside = 0;
            for (auto it = mass->tree().cbeginValueOn(); it; ++it) {
                EXPECT_LE(*it, tc);
                if (!c.isInside(it.getCoord())) outside += *it;
            }
            if (rule == Rule::Arata) {
                EXPECT_GT(outside, 0);
            } else {
                // Over cells drop to exactly Tc and under cells only gain, so the lump stays full
                // and the whole excess sits outside it.
                EXPECT_EQ(outside, excess) << ruleName(rule) << " " << dims << "D";
                for (auto it = c.begin(); it; ++it)
                    EXPECT_EQ(mass->tree().getValue(*it), tc);
            }
            // Settled means settled: further steps examine nothing and change nothing.
            const uint64_t h = contentHash(*mass);
            const StepReport more = a.run(10);
            EXPECT_EQ(more.blocksVisited, 0u);
            EXPECT_EQ(contentHash(*mass), h);
        }
    }
}

TEST_F(AutomatonTest, SettleStopsOnBudgetOrTolerance)
{
    auto mass = lump(CoordBBox(Coord(0, 0, 0), Coord(7, 7, 7)), 100);
    mass->tree().setValue(Coord(3, 3, 3), 100 + 10000);
    Automaton a(mass, options(Rule::Prorata, 3, 100));
    StepReport r = a.settle(5);
    EXPECT_EQ(r.steps, 5u);
    EXPECT_EQ(r.reason, StopReason::StepBudget);
    EXPECT_FALSE(r.settled);
    r = a.settle(100000, /*tolerance=*/5000);
    EXPECT_EQ(r.reason, StopReason::Tolerance);
    EXPECT_LE(r.residualOverload, 5000);
    EXPECT_GT(r.residualOverload, 0);
    r = a.settle(100000);
    EXPECT_EQ(r.reason, StopReason::Settled);
    EXPECT_EQ(a.totalMass(), totalMass(*mass));
    EXPECT_EQ(a.stepCount(), 5u + 0u + r.steps + (a.stepCount() - 5u - r.steps));
}

// ---- sparsity --------------------------------------------------------------------------------------

TEST_F(AutomatonTest, CostFollowsTheMovingClayNotTheVolume)
{
    // A wide settled slab (64 x 8 x 64 at Tc) and one small overload on its top. After the two
    // full-scan steps, each step examines only blocks near the moving clay. blocksVisited counts
    // every candidate block before any filter (no over cell, missing leaf), so a regression to a
    // full scan of the slab's leaves shows here even though such blocks would change nothing.
    auto mass = lump(CoordBBox(Coord(0, 0, 0), Coord(63, 7, 63)), 100);
    mass->tree().setValue(Coord(30, 7, 30), 100 + 300);
    Automaton a(mass, options(Rule::Prorata, 3, 100));
    const uint64_t slabBlocks = 64 * 8 * 64 / 8;
    a.run(2);
    uint64_t maxVisited = 0;
    StepReport total;
    for (int i = 0; i < 5000 && !a.settled(); ++i) {
        const StepReport r = a.step();
        maxVisited = std::max(maxVisited, r.blocksVisited);
        EXPECT_GE(r.blocksVisited, r.blocksOverTc);
        EXPECT_GE(r.blocksOverTc, r.blocksUpdated);
        total += r;
    }
    EXPECT_TRUE(a.settled());
    EXPECT_GT(total.blocksUpdated, 0u);
    // A dense sweep visits every block of the slab every step; here no step comes near that.
    EXPECT_LT(maxVisited * 10, slabBlocks) << maxVisited << " of " << slabBlocks << " blocks";
    EXPECT_LT(total.blocksVisited, total.steps * slabBlocks / 20);
    EXPECT_GT(total.blocksVisited, total.blocksOverTc); // the filter did reject candidates
    // The tree grew only where clay flowed: no leaf is without clay.
    for (auto it = mass->tree().cbeginLeaf(); it; ++it)
        EXPECT_FALSE(it->isEmpty()) << it->origin();
}

TEST_F(AutomatonTest, SettledRegionCostsNothing)
{
    auto mass = lump(CoordBBox(Coord(0, 0, 0), Coord(31, 31, 31)), 100);
    Automaton a(mass, options(Rule::Sorted, 3, 100));
    EXPECT_TRUE(a.settled()); // nothing is over Tc
    const StepReport r = a.run(1000);
    EXPECT_EQ(r.blocksVisited, 0u);
    EXPECT_EQ(a.stepCount(), 1000u);
}

TEST_F(AutomatonTest, SettledRegionWithOverloadLeftCostsNothing)
{
    // A settled lump at Tc and, inside it, one over cell walled in by obstacles on every side: the
    // overload stays (so steps are not skipped for want of overload), but once two steps change
    // nothing no candidate is left. Counted before any filter: a full scan would show here.
    for (int dims : {2, 3}) {
        const bool d3 = dims == 3;
        auto mass = lump(CoordBBox(Coord(0, 0, 0), Coord(31, 31, d3 ? 31 : 0)), 100);
        auto obs = openvdb::MaskGrid::create(false);
        const Coord c(12, 13, d3 ? 14 : 0);
        mass->tree().setValue(c, 900);
        for (int dx = -1; dx <= 1; ++dx)
            for (int dy = -1; dy <= 1; ++dy)
                for (int dz = d3 ? -1 : 0; dz <= (d3 ? 1 : 0); ++dz)
                    if (dx || dy || dz) obs->tree().setValueOn(c.offsetBy(dx, dy, dz));
        Automaton a(mass, options(Rule::Sorted, dims, 100), obs);
        EXPECT_EQ(a.residualOverload(), 800);
        const StepReport first = a.run(2);
        EXPECT_GT(first.blocksVisited, 0u) << "the first two steps examine the leaf holding the over cell";
        EXPECT_EQ(first.blocksUpdated, 0u);
        EXPECT_TRUE(a.settled());
        const StepReport r = a.run(1000);
        EXPECT_EQ(r.blocksVisited, 0u) << dims << "D";
        EXPECT_EQ(r.blocksOverTc, 0u);
        EXPECT_EQ(r.residualOverload, 800);
    }
}

// ---- settle with a stop hook ----------------------------------------------------------------------

TEST_F(AutomatonTest, SettleStopHookStopsAfterAStepAndResumesExactly)
{
    auto build = [] {
        auto mass = lump(CoordBBox(Coord(0, 0, 0), Coord(7, 7, 7)), 100);
        mass->tree().setValue(Coord(3, 3, 3), 100 + 6000);
        return mass;
    };
    // Unbroken.
    auto m1 = build();
    Automaton a1(m1, options(Rule::Prorata, 3, 100));
    const StepReport whole = a1.settle(100000);
    ASSERT_EQ(whole.reason, StopReason::Settled);
    ASSERT_GT(whole.steps, 20u);

    // The hook is polled after every step: stop after 11, then go on with the steps done.
    auto m2 = build();
    Automaton a2(m2, options(Rule::Prorata, 3, 100));
    uint64_t polls = 0;
    SettleOptions so;
    so.maxSteps = 100000;
    so.stop = [&](const Automaton& a) {
        ++polls;
        EXPECT_EQ(a.stepCount(), polls);
        return a.stepCount() == 11;
    };
    const StepReport part = a2.settle(so);
    EXPECT_EQ(part.reason, StopReason::Stopped);
    EXPECT_STREQ(stopReasonName(part.reason), "stopped");
    EXPECT_EQ(part.steps, 11u);
    EXPECT_EQ(polls, 11u);
    EXPECT_FALSE(part.settled);
    so.stepsDone = part.steps;
    so.stop = nullptr;
    const StepReport rest = a2.settle(so);
    EXPECT_EQ(rest.reason, StopReason::Settled);
    EXPECT_EQ(part.steps + rest.steps, whole.steps);
    EXPECT_EQ(contentHash(*m2), contentHash(*m1));

    // The budget counts the steps already done.
    auto m3 = build();
    Automaton a3(m3, options(Rule::Prorata, 3, 100));
    SettleOptions budget;
    budget.maxSteps = 15;
    budget.stepsDone = 10;
    const StepReport r3 = a3.settle(budget);
    EXPECT_EQ(r3.steps, 5u);
    EXPECT_EQ(r3.reason, StopReason::StepBudget);
    // A hook that never stops changes nothing.
    auto m4 = build();
    Automaton a4(m4, options(Rule::Prorata, 3, 100));
    SettleOptions never;
    never.maxSteps = 100000;
    never.stop = [](const Automaton&) { return false; };
    EXPECT_EQ(a4.settle(never).steps, whole.steps);
    EXPECT_EQ(contentHash(*m4), contentHash(*m1));
}

// ---- edits ------------------------------------------------------------------------------------------

TEST_F(AutomatonTest, EditWakesTheRegionAndTracksMass)
{
    auto mass = lump(CoordBBox(Coord(0, 0, 0), Coord(15, 15, 15)), 100);
    Automaton a(mass, options(Rule::Prorata, 3, 100));
    a.settle(10);
    ASSERT_TRUE(a.settled());
    const int64_t m0 = a.totalMass();
    // A tool adds 5000 units at one voxel (not mass-neutral: the automaton must follow).
    a.edit(Box{{{8, 15, 8}}, {{8, 15, 8}}}, [](MassGrid& g) { g.tree().setValue(Coord(8, 15, 8), 5100); });
    EXPECT_EQ(a.totalMass(), m0 + 5000);
    EXPECT_EQ(a.residualOverload(), 5000);
    EXPECT_FALSE(a.settled());
    const StepReport r = a.settle(100000);
    EXPECT_TRUE(r.settled);
    EXPECT_EQ(totalMass(*mass), m0 + 5000);
    EXPECT_EQ(r.residualOverload, 0);
    // An edit that empties a whole leaf prunes it.
    const auto leaves = mass->tree().leafCount();
    a.edit(Box{{{0, 0, 0}}, {{7, 7, 7}}},
           [](MassGrid& g) { g.tree().fill(CoordBBox(Coord(0, 0, 0), Coord(7, 7, 7)), 0, false); });
    EXPECT_EQ(mass->tree().leafCount(), leaves - 1);
    EXPECT_EQ(a.totalMass(), totalMass(*mass));
}

TEST_F(AutomatonTest, EditVoxelizesTheActiveTilesItMakesInItsRegion)
{
    // The edit voxelizes the tiles of the nodes meeting its region only (it costs the region, not the
    // model): a leaf-sized tile and a 128^3 tile (a lower node's) written by the edit are voxelized
    // and counted exactly; clay far away is not touched.
    auto mass = lump(CoordBBox(Coord(1000, 0, 0), Coord(1003, 3, 3)), 100);
    Automaton a(mass, options(Rule::Prorata, 3, 100));
    const int64_t m0 = a.totalMass();
    a.edit(Box{{{0, 0, 0}}, {{7, 7, 7}}},
           [](MassGrid& g) { g.tree().fill(CoordBBox(Coord(0, 0, 0), Coord(7, 7, 7)), 3, true); });
    EXPECT_EQ(a.totalMass(), m0 + 3 * 512);
    EXPECT_EQ(mass->tree().activeTileCount(), 0u);
    a.edit(Box{{{-128, 0, 0}}, {{-1, 127, 127}}},
           [](MassGrid& g) { g.tree().fill(CoordBBox(Coord(-128, 0, 0), Coord(-1, 127, 127)), 1, true); });
    EXPECT_EQ(a.totalMass(), m0 + 3 * 512 + 128 * 128 * 128);
    EXPECT_EQ(a.totalMass(), totalMass(*mass));
    EXPECT_EQ(mass->tree().activeTileCount(), 0u);
    EXPECT_EQ(mass->tree().activeVoxelCount(), uint64_t(64 + 512 + 128 * 128 * 128));
}

TEST_F(AutomatonTest, QuietStepsCountStepsThatChangeNothingAndEditsRestartThem)
{
    // A 4^3 lump, every cell over Tc, walled in by obstacles: no block has an under cell, so no
    // step changes anything although the overload stays.
    auto mass = lump(CoordBBox(Coord(0, 0, 0), Coord(3, 3, 3)), 150);
    auto obs = openvdb::MaskGrid::create(false);
    obs->tree().fill(CoordBBox(Coord(-2, -2, -2), Coord(5, 5, 5)), true);
    obs->tree().fill(CoordBBox(Coord(0, 0, 0), Coord(3, 3, 3)), false);
    Automaton a(mass, options(Rule::Prorata, 3, 100), obs);
    EXPECT_EQ(a.quietSteps(), 0);
    EXPECT_EQ(a.residualOverload(), 64 * 50);
    a.step();
    EXPECT_EQ(a.quietSteps(), 1);
    EXPECT_FALSE(a.settled());
    a.step();
    EXPECT_EQ(a.quietSteps(), 2);
    EXPECT_TRUE(a.settled());
    // Emptying one corner cell gives the lump room: the edit restarts the count, and the next step
    // (step 2, even) has the block [0,1]^3: that cell and seven over cells, which changes.
    a.edit(Box{{{0, 0, 0}}, {{0, 0, 0}}}, [](MassGrid& g) { g.tree().setValue(Coord(0, 0, 0), 0); });
    EXPECT_EQ(a.quietSteps(), 0);
    EXPECT_FALSE(a.settled());
    const StepReport r = a.step();
    EXPECT_GT(r.blocksUpdated, 0u);
    EXPECT_EQ(a.quietSteps(), 0);
    // 63 x 150 cannot fit in 64 x 100, and the rule sets over cells to Tc and gives the surplus to
    // the others: the surplus keeps hopping between cells, with a quiet step now and then (a phase
    // whose every block is all over Tc). The count follows the step reports exactly.
    int expect = 0, quietSeen = 0;
    for (int i = 0; i < 200; ++i) {
        const StepReport ri = a.step();
        expect = ri.blocksUpdated ? 0 : expect + 1;
        quietSeen += ri.blocksUpdated ? 0 : 1;
        ASSERT_EQ(a.quietSteps(), expect) << "step " << a.stepCount();
        if (a.settled()) break;
    }
    EXPECT_GT(quietSeen, 0);
    EXPECT_EQ(a.totalMass(), 63 * 150);
    EXPECT_TRUE(a.overloadHasNoRoom());
    a.resync();
    EXPECT_EQ(a.quietSteps(), 0);
}

// ---- refusals ---------------------------------------------------------------------------------------

TEST_F(AutomatonTest, OverflowIsRefusedBeforeAnythingIsWritten)
{
    // Seven cells of 2^30 and one empty cell, walled in by obstacles. Bingham with Tc = 1 would put
    // 7 (2^30 - 1) into the empty cell: more than INT32_MAX. The step must throw, grid untouched.
    auto mass = newMass();
    auto obs = openvdb::MaskGrid::create(false);
    const CoordBBox cell(Coord(0, 0, 0), Coord(1, 1, 1));
    const CoordBBox wall(Coord(-1, -1, -1), Coord(2, 2, 2));
    for (auto it = wall.begin(); it; ++it)
        if (!cell.isInside(*it)) obs->tree().setValueOn(*it);
    for (auto it = cell.begin(); it; ++it)
        mass->tree().setValue(*it, 1 << 30);
    mass->tree().setValue(Coord(1, 1, 1), 0);
    // A second, harmless overload far away, in a block processed in the same pass.
    mass->tree().setValue(Coord(100, 100, 100), 50);
    Automaton a(mass, options(Rule::Bingham, 3, 1), obs);
    const uint64_t h = contentHash(*mass);
    try {
        a.step();
        FAIL() << "expected an overflow error";
    } catch (const Error& e) {
        const std::string msg = e.what();
        EXPECT_NE(msg.find("INT32_MAX"), std::string::npos) << msg;
        EXPECT_NE(msg.find("(0, 0, 0)"), std::string::npos) << msg;
    }
    EXPECT_EQ(contentHash(*mass), h);
    EXPECT_EQ(a.stepCount(), 0u);
}

TEST_F(AutomatonTest, LargeButSafeMassesAreExact)
{
    // One cell of 2^30 in empty space with Tc = 2^20: spreads without any overflow.
    auto mass = newMass();
    mass->tree().setValue(Coord(-3, 5, 9), 1 << 30);
    for (Rule rule : kAll) {
        auto m = mass->deepCopy();
        Automaton a(m, options(rule, 3, 1 << 20));
        a.run(30);
        EXPECT_EQ(totalMass(*m), int64_t(1) << 30) << ruleName(rule);
        EXPECT_GT(m->tree().activeVoxelCount(), 27u) << ruleName(rule);
    }
}

TEST_F(AutomatonTest, BadStatesAreRefusedWithClearErrors)
{
    auto expectError = [](auto&& f, const std::string& needle) {
        try {
            f();
            ADD_FAILURE() << "expected an error containing \"" << needle << "\"";
        } catch (const Error& e) {
            EXPECT_NE(std::string(e.what()).find(needle), std::string::npos) << e.what();
        }
    };
    expectError([] { Automaton a(nullptr); }, "null");
    expectError(
        [] {
            auto m = newMass();
            m->tree().setValue(Coord(1, -2, 3), -7);
            Automaton a(m);
        },
        "(1, -2, 3)");
    expectError(
        [] {
            auto m = newMass();
            m->tree().setValue(Coord(0, 0, 4), 7);
            Automaton a(m, options(Rule::Prorata, 2));
        },
        "z = 0");
    expectError(
        [] {
            auto m = openvdb::Int32Grid::create(5);
            Automaton a(m);
        },
        "background");
    expectError([] { Automaton a(newMass(), options(Rule::Prorata, 4)); }, "dimensions");
    expectError(
        [] {
            AutomatonOptions o;
            o.rule.threshold = 0;
            Automaton a(newMass(), o);
        },
        "threshold");
    expectError(
        [] {
            AutomatonOptions o;
            o.rule.alpha = 1.0;
            Automaton a(newMass(), o);
        },
        "alpha");
    expectError(
        [] {
            auto m = newMass();
            m->tree().addTile(1, Coord(0, 0, 0), 9, /*active=*/false);
            Automaton a(m);
        },
        "tile");
}

TEST_F(AutomatonTest, ActiveTilesAreVoxelizedAndSettle)
{
    auto m = newMass();
    m->tree().addTile(2, Coord(0, 0, 0), 100, /*active=*/true); // a 128^3 tile at Tc
    m->tree().setValue(Coord(64, 127, 64), 900);
    Automaton a(m, options(Rule::Prorata, 3, 100));
    EXPECT_EQ(a.totalMass(), int64_t(128) * 128 * 128 * 100 + 800);
    const StepReport r = a.settle(10000);
    EXPECT_TRUE(r.settled);
    EXPECT_EQ(totalMass(*m), a.totalMass());
}

// The leaf scan (construction, resync, edits) runs in parallel over leaves: the totals, the
// overload and the error reported (the first bad voxel in leaf order) must be a serial scan's.
TEST(AutomatonScan, ParallelScanReportsTheSameTotalsAndTheFirstErrorInLeafOrder)
{
    openvdb::initialize();
    auto make = [] {
        auto g = openvdb::Int32Grid::create(0);
        for (int i = 0; i < 200; ++i) // 200 leaves, a few over Tc
            g->tree().setValue(Coord(8 * (i % 10), 8 * (i / 10 % 5), 8 * (i / 50)), 500 + 7 * i);
        return g;
    };
    std::string firstError;
    for (int threads : {1, 2, 3, 8}) {
        AutomatonOptions o;
        o.threads = threads;
        auto g = make();
        Automaton a(g, o);
        EXPECT_EQ(a.totalMass(), 200 * 500 + 7 * 199 * 200 / 2) << threads;
        int64_t over = 0;
        for (int i = 0; i < 200; ++i)
            over += std::max(0, 500 + 7 * i - 1000);
        EXPECT_EQ(a.residualOverload(), over) << threads;
        // Two bad voxels: the one in the lower leaf (x, then y, then z) is reported.
        auto bad = make();
        bad->tree().setValue(Coord(72, 33, 17), -5);
        bad->tree().setValue(Coord(8, 2, 9), -3);
        try {
            Automaton b(bad, o);
            ADD_FAILURE() << "accepted negative mass, " << threads << " threads";
        } catch (const Error& e) {
            const std::string msg = e.what();
            EXPECT_NE(msg.find("(8, 2, 9)"), std::string::npos) << msg;
            if (firstError.empty()) firstError = msg;
            EXPECT_EQ(msg, firstError) << threads;
        }
    }
}
