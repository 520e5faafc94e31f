// The compressing push, the global transport and the swept push.
#include <vdbclay/Automaton.h>
#include <vdbclay/IO.h>
#include <vdbclay/Metrics.h>
#include <vdbclay/Push.h>
#include <vdbclay/Scene.h>
#include <vdbclay/Sculpt.h>
#include <vdbclay/Shapes.h>
#include <vdbclay/Transport.h>

#include "transport/Domain.h"       // the flood, one by one and in batches
#include "transport/Multigrid.h"    // the V-cycle, applied alone
#include "transport/RadixSort.h"    // the routing's order, sorted on any thread count
#include "transport/SolverTuning.h" // the solver's tuning, varied here

#include <openvdb/openvdb.h>

#include <gtest/gtest.h>

#include <tbb/task_arena.h>

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <cstring>
#include <numeric>
#include <random>
#include <string>
#include <unistd.h>

using namespace vdbclay;
using transport_internal::CellCoord;
using transport_internal::SolverTuning;

namespace {

class TransportTest : public ::testing::Test {
protected:
    static void SetUpTestSuite() { openvdb::initialize(); }
};

MassGridPtr block(const Box& b, int32_t m)
{
    MassGridPtr g = openvdb::Int32Grid::create(0);
    g->tree().fill(openvdb::CoordBBox(openvdb::Coord(b.min[0], b.min[1], b.min[2]),
                                      openvdb::Coord(b.max[0], b.max[1], b.max[2])),
                   m, true);
    g->tree().voxelizeActiveTiles();
    return g;
}

Box box(int x0, int y0, int z0, int x1, int y1, int z1)
{
    return Box{{{x0, y0, z0}}, {{x1, y1, z1}}};
}

AutomatonOptions opts(int dims = 3, int threads = 1)
{
    AutomatonOptions o;
    o.dimensions = dims;
    o.rule.rule = Rule::Prorata;
    o.rule.threshold = 1000;
    o.threads = threads;
    return o;
}

int32_t at(const Automaton& a, int x, int y, int z)
{
    return a.mass()->tree().getValue(openvdb::Coord(x, y, z));
}

} // namespace

// ---- the compressing push ------------------------------------------------------------------------

TEST_F(TransportTest, ModesParseAndBadNamesAreRefused)
{
    EXPECT_EQ(parsePushMode("surface"), PushMode::Surface);
    EXPECT_EQ(parsePushMode("compress"), PushMode::Compress);
    EXPECT_THROW(parsePushMode("squash"), Error);
    EXPECT_EQ(parseTransport("local"), Transport::Local);
    EXPECT_EQ(parseTransport("global"), Transport::Global);
    EXPECT_THROW(parseTransport("far"), Error);
    const Scene s = parseScene(R"({"push": "compress", "transport": "global", "sweep": true})", "s.json", "");
    EXPECT_EQ(s.push, PushMode::Compress);
    EXPECT_EQ(s.transport, Transport::Global);
    EXPECT_TRUE(s.sweep);
    const Scene d = parseScene("{}", "s.json", "");
    EXPECT_EQ(d.push, PushMode::Surface);
    EXPECT_EQ(d.transport, Transport::Local);
    EXPECT_FALSE(d.sweep);
    for (const char* bad : {R"({"push": "squash"})", R"({"transport": 3})", R"({"sweep": "yes"})"}) {
        try {
            parseScene(bad, "s.json", "");
            ADD_FAILURE() << bad;
        } catch (const Error& e) {
            const std::string what = e.what();
            EXPECT_NE(what.find("s.json: "), std::string::npos) << what;
            EXPECT_TRUE(what.find("push") != std::string::npos ||
                        what.find("transport") != std::string::npos ||
                        what.find("sweep") != std::string::npos)
                << what;
        }
    }
}

TEST_F(TransportTest, APlateOverAColumnCompressesEveryColumnUniformly)
{
    // An 8 x 8 x 8 column at Tc; a plate wider than it enters the top layer (y = 7): 64 voxels
    // entered, contact size 8, so each top voxel's 1000 is shared over the 7 full voxels below it:
    // 142 each, the remainder 6 to the 6 nearest the plate.
    Automaton a(block(box(0, 0, 0, 7, 7, 7), 1000), opts());
    PushOptions po;
    po.mode = PushMode::Compress;
    const PushReport r = push(a, {makeBox({{-3, 7, -3}}, {{10, 9, 10}})}, po);
    EXPECT_EQ(r.voxelsPushed, 64u);
    EXPECT_EQ(r.voxelsCompressed, 64u);
    EXPECT_DOUBLE_EQ(r.contactSize, 8.0);
    EXPECT_EQ(a.totalMass(), int64_t(512) * 1000);
    EXPECT_EQ(totalMass(*a.mass()), int64_t(512) * 1000);
    for (int x = 0; x < 8; ++x)
        for (int z = 0; z < 8; ++z) {
            EXPECT_EQ(at(a, x, 7, z), 0);
            for (int y = 0; y < 7; ++y)
                EXPECT_EQ(at(a, x, y, z), 1000 + 142 + (6 - y < 6 ? 1 : 0)) << x << y << z;
            // nothing beside the column
            EXPECT_EQ(at(a, -1, 3, z), 0);
            EXPECT_EQ(at(a, 8, 3, z), 0);
        }
}

TEST_F(TransportTest, ASmallToolInABigBlockCompressesOnlyNearItself)
{
    // A sphere of radius 3 enters the top of a 40 x 20 x 40 block: its contact is a few voxels
    // wide, so the clay goes at most that deep, and every far face is untouched.
    const Box b = box(0, 0, 0, 39, 19, 39);
    Automaton a(block(b, 1000), opts());
    PushOptions po;
    po.mode = PushMode::Compress;
    const ShapePtr tool = makeSphere({{20, 21, 20}}, 3.2);
    const PushReport r = push(a, {tool}, po);
    ASSERT_GT(r.voxelsCompressed, 0u);
    const int depth = int(std::lround(r.contactSize));
    EXPECT_LE(depth, 6);
    EXPECT_EQ(a.totalMass(), int64_t(40 * 20 * 40) * 1000);
    for (auto it = a.mass()->tree().cbeginValueOn(); it; ++it) {
        const openvdb::Coord c = it.getCoord();
        if (*it == 1000) continue;
        // changed: inside the tool (emptied) or within depth of it
        EXPECT_LE(std::abs(c.x() - 20), 4 + depth) << c;
        EXPECT_LE(std::abs(c.z() - 20), 4 + depth) << c;
        EXPECT_GE(c.y(), 19 - 3 - depth) << c;
    }
    for (int x = 0; x < 40; ++x)
        for (int z = 0; z < 40; ++z)
            EXPECT_EQ(at(a, x, 0, z), 1000);
}

TEST_F(TransportTest, APlateCoveringATallColumnCompressesItAllTheWayDown)
{
    // A 4 x 40 x 4 column at Tc; a plate wider than it enters the top layer (y = 39): 16 voxels,
    // contact size 4, but the plate covers the clay (nothing beside it), so the whole column below
    // is compressed, past both the contact size and the surface push's search (maxSearch 16):
    // 16 000 over the 16 x 39 cells below, 25 each, the remainder 400 as +1 to the 25 layers
    // nearest the plate (y = 38 ... 14).
    Automaton a(block(box(0, 0, 0, 3, 39, 3), 1000), opts());
    PushOptions po;
    po.mode = PushMode::Compress;
    const PushReport r = push(a, {makeBox({{-3, 39, -3}}, {{6, 41, 6}})}, po);
    EXPECT_EQ(r.voxelsPushed, 16u);
    EXPECT_EQ(r.voxelsCompressed, 16u);
    EXPECT_DOUBLE_EQ(r.contactSize, 4.0);
    EXPECT_EQ(totalMass(*a.mass()), int64_t(16 * 40) * 1000);
    EXPECT_LE(r.region.min[1], 0); // the global layer's seeds cover the whole column
    for (int x = 0; x < 4; ++x)
        for (int z = 0; z < 4; ++z) {
            EXPECT_EQ(at(a, x, 39, z), 0);
            for (int y = 0; y < 39; ++y)
                EXPECT_EQ(at(a, x, y, z), 1025 + (y >= 14 ? 1 : 0)) << x << " " << y << " " << z;
        }
}

TEST_F(TransportTest, ACoveringPlateSharesItsClayEvenlyOverColumnsOfUnequalLength)
{
    // Two blocks under one plate: x 0..3 is 16 tall (y 0..15), x 4..7 only 8 (y 8..15, nothing
    // below). The plate enters y = 15 (64 voxels). Spread per column, the short columns would gain
    // twice as much per cell (1000 / 7 against 1000 / 15) and the clay would leave near the plate;
    // pooled, every cell of the 704 below gains the same: 64 000 = 704 x 90 + 640, the remainder
    // +1 to the cells nearest the plate: the 7 layers of both (448), then 6 layers of the tall one.
    MassGridPtr g = block(box(0, 0, 0, 3, 15, 7), 1000);
    g->tree().fill(openvdb::CoordBBox(openvdb::Coord(4, 8, 0), openvdb::Coord(7, 15, 7)), 1000, true);
    g->tree().voxelizeActiveTiles();
    Automaton a(g, opts());
    PushOptions po;
    po.mode = PushMode::Compress;
    const PushReport r = push(a, {makeBox({{-4, 15, -4}}, {{11, 17, 11}})}, po);
    EXPECT_EQ(r.voxelsCompressed, 64u);
    EXPECT_EQ(totalMass(*a.mass()), int64_t(4 * 16 * 8 + 4 * 8 * 8) * 1000);
    for (int z = 0; z < 8; ++z) {
        for (int x = 0; x < 8; ++x) {
            EXPECT_EQ(at(a, x, 15, z), 0);
            for (int y = 8; y < 15; ++y)
                EXPECT_EQ(at(a, x, y, z), 1091) << x << " " << y << " " << z;
            for (int y = 0; y < 8; ++y)
                EXPECT_EQ(at(a, x, y, z), x < 4 ? 1090 + (y >= 2 ? 1 : 0) : 0) << x << " " << y << " " << z;
        }
    }
}

TEST_F(TransportTest, A2DPlateCoveringATallColumnCompressesItAllTheWayDown)
{
    // 2D: a column 3 wide and 30 tall; a plate wider than it enters the top row (3 voxels, contact
    // size 3): 3000 over the 3 x 29 cells below, 34 each, the remainder 42 as +1 to the 14 rows
    // nearest the plate (y = 28 ... 15).
    Automaton a(block(box(0, 0, 0, 2, 29, 0), 1000), opts(2));
    PushOptions po;
    po.mode = PushMode::Compress;
    const PushReport r = push(a, {makeBox({{-4, 29, -1}}, {{6, 31, 1}})}, po);
    EXPECT_EQ(r.voxelsCompressed, 3u);
    EXPECT_DOUBLE_EQ(r.contactSize, 3.0);
    for (int x = 0; x < 3; ++x) {
        EXPECT_EQ(at(a, x, 29, 0), 0);
        for (int y = 0; y < 29; ++y)
            EXPECT_EQ(at(a, x, y, 0), 1034 + (y >= 15 ? 1 : 0)) << x << " " << y;
    }
    EXPECT_EQ(totalMass(*a.mass()), int64_t(3 * 30) * 1000);
}

TEST_F(TransportTest, APooledShareThatWouldOverflowAVoxelIsRefusedAndChangesNothing)
{
    // Two columns under one plate: x = 0 has 2e9 on top of 8 cells at Tc, x = 1 has Tc on top of
    // 8 cells at 2.1e9. Each column alone fits; pooled, every cell gets about 1.25e8, which the
    // cells at 2.1e9 cannot take (INT32_MAX 2 147 483 647): refused, nothing written.
    MassGridPtr g = block(box(0, 0, 0, 0, 7, 0), 1000);
    g->tree().fill(openvdb::CoordBBox(openvdb::Coord(1, 0, 0), openvdb::Coord(1, 7, 0)), 2100000000, true);
    g->tree().voxelizeActiveTiles();
    g->tree().setValue(openvdb::Coord(0, 8, 0), 2000000000);
    g->tree().setValue(openvdb::Coord(1, 8, 0), 1000);
    Automaton a(g, opts());
    const uint64_t h = contentHash(*g);
    PushOptions po;
    po.mode = PushMode::Compress;
    try {
        push(a, {makeBox({{-3, 8, -3}}, {{4, 10, 3}})}, po);
        ADD_FAILURE() << "no error";
    } catch (const Error& e) {
        EXPECT_NE(std::string(e.what()).find("INT32_MAX"), std::string::npos) << e.what();
    }
    EXPECT_EQ(contentHash(*a.mass()), h);
}

TEST_F(TransportTest, APlateNarrowerThanTheClayCompressesOnlyAsDeepAsItIsWide)
{
    // A 4 x 4 plate entering the top of a 24 x 40 x 24 block does not cover it (clay beside it):
    // the clay goes at most the contact size (4) deep, the rest of the block is untouched, however
    // far the floor. The inner 2 x 2 sources push straight down: 250 to each of the 4 below.
    Automaton a(block(box(0, 0, 0, 23, 39, 23), 1000), opts());
    PushOptions po;
    po.mode = PushMode::Compress;
    const PushReport r = push(a, {makeBox({{10, 39, 10}}, {{13, 41, 13}})}, po);
    EXPECT_EQ(r.voxelsCompressed, 16u);
    EXPECT_DOUBLE_EQ(r.contactSize, 4.0);
    for (auto it = a.mass()->tree().cbeginValueOn(); it; ++it) {
        const openvdb::Coord c = it.getCoord();
        if (*it == 1000) continue;
        EXPECT_GE(c.y(), 35) << c;
        EXPECT_LE(std::abs(2 * c.x() - 23), 3 + 2 * 4) << c;
        EXPECT_LE(std::abs(2 * c.z() - 23), 3 + 2 * 4) << c;
    }
    for (int x = 11; x <= 12; ++x)
        for (int z = 11; z <= 12; ++z)
            for (int y = 35; y <= 39; ++y)
                EXPECT_EQ(at(a, x, y, z), y == 39 ? 0 : 1250) << x << " " << y << " " << z;
    EXPECT_EQ(totalMass(*a.mass()), int64_t(24 * 40 * 24) * 1000);
}

TEST_F(TransportTest, CompressPushIsDeterministicAndExactAndFallsBackToTheSurfacePush)
{
    // A thin film (below 0.3 Tc): nothing to compress, so the compress push is the surface push,
    // voxel for voxel.
    for (int32_t m : {200, 1000}) {
        uint64_t h[2] = {0, 0};
        for (int mode = 0; mode < 2; ++mode) {
            Automaton a(block(box(0, 0, 0, 11, 11, 11), m), opts());
            PushOptions po;
            po.mode = mode ? PushMode::Compress : PushMode::Surface;
            const std::vector<ShapePtr> tools = {makeSphere({{6, 12, 6}}, 4),
                                                 makeBox({{-1, -1, -1}}, {{2, 4, 2}})};
            push(a, tools, po);
            EXPECT_EQ(a.totalMass(), int64_t(12 * 12 * 12) * m);
            EXPECT_EQ(totalMass(*a.mass()), int64_t(12 * 12 * 12) * m);
            h[mode] = contentHash(*a.mass());
            Automaton again(block(box(0, 0, 0, 11, 11, 11), m), opts());
            push(again, tools, po);
            EXPECT_EQ(contentHash(*again.mass()), h[mode]);
        }
        if (m < 900)
            EXPECT_EQ(h[0], h[1]);
        else
            EXPECT_NE(h[0], h[1]);
    }
}

// ---- the global transport ------------------------------------------------------------------------

TEST_F(TransportTest, BadGlobalTransportOptionsAndTuningAreRefusedNamingTheFieldAndChangeNothing)
{
    MassGridPtr g = block(box(0, 0, 0, 3, 3, 3), 1000);
    g->tree().setValue(openvdb::Coord(1, 1, 1), 1500);
    Automaton a(g, opts());
    const uint64_t h = contentHash(*g);
    GlobalTransportOptions badReach;
    badReach.reach = -1;
    SolverTuning bad[4];
    bad[1].maxRounds = 0;
    bad[2].tolerance = 0;
    bad[3].roundTolerance = 1.5;
    const char* names[4] = {"reach", "maxRounds", "tolerance", "roundTolerance"};
    for (int i = 0; i < 4; ++i) {
        try {
            if (i == 0)
                transportGlobally(a, badReach);
            else
                transport_internal::transportGlobally(a, {}, bad[i]);
            ADD_FAILURE() << names[i];
        } catch (const Error& e) {
            EXPECT_NE(std::string(e.what()).find(names[i]), std::string::npos) << e.what();
        }
        EXPECT_EQ(contentHash(*g), h) << names[i];
    }
}

TEST_F(TransportTest, GlobalLayerMovesTheOverloadToRoomExactly)
{
    // A 10^3 block at Tc with 5000 extra in one centre cell: every solved cell ends at Tc, the
    // extra lands in cells with room outside the block, mass exact, no automaton step needed.
    MassGridPtr g = block(box(0, 0, 0, 9, 9, 9), 1000);
    g->tree().setValue(openvdb::Coord(5, 5, 5), 6000);
    Automaton a(g, opts());
    const GlobalTransportReport r = transportGlobally(a);
    EXPECT_EQ(r.overloadBefore, 5000);
    EXPECT_EQ(r.overloadAfter, 0);
    EXPECT_FALSE(r.noRoom);
    EXPECT_GE(r.solves, 1u);
    EXPECT_EQ(a.totalMass(), int64_t(1000) * 1000 + 5000);
    EXPECT_EQ(totalMass(*g), a.totalMass());
    for (int x = 0; x < 10; ++x)
        for (int y = 0; y < 10; ++y)
            for (int z = 0; z < 10; ++z)
                EXPECT_EQ(at(a, x, y, z), 1000);
    int64_t outside = 0;
    for (auto it = g->tree().cbeginValueOn(); it; ++it) {
        EXPECT_LE(*it, 1000);
        const openvdb::Coord c = it.getCoord();
        if (c.x() < 0 || c.x() > 9 || c.y() < 0 || c.y() > 9 || c.z() < 0 || c.z() > 9) outside += *it;
    }
    EXPECT_EQ(outside, 5000);
}

TEST_F(TransportTest, TheDenseCellIndexAndTheTreeBeyondItGiveOneResult)
{
    // The cell index is a dense array over the seeds' bounds grown by the reach + 2, a tree beyond
    // it. Clay at 0.99 Tc with 20 Tc extra in one cell: the cell is the whole flood (no full
    // cell beside it) with reach 1 as with reach 0 (no dense index at all), and the active set joins
    // cells with room (10 each) shell by shell, far past the dense box: both give one result, on any
    // thread count, exact.
    uint64_t ref = 0;
    for (int64_t reach : {0, 1})
        for (int threads : {1, 3}) {
            MassGridPtr g = block(box(0, 0, 0, 23, 23, 23), 990);
            g->tree().setValue(openvdb::Coord(12, 12, 12), 990 + 20000);
            Automaton a(g, opts(3, threads));
            GlobalTransportOptions o;
            o.reach = reach;
            o.threads = threads;
            const GlobalTransportReport r = transportGlobally(a, o);
            EXPECT_EQ(r.overloadBefore, 20000 - 10);
            EXPECT_FALSE(r.noRoom);
            EXPECT_GT(r.unknowns, 343u) << "the set should grow past the dense box (7^3 cells)";
            EXPECT_EQ(totalMass(*g), int64_t(24 * 24 * 24) * 990 + 20000);
            const uint64_t h = contentHash(*g);
            if (ref == 0) ref = h;
            EXPECT_EQ(h, ref) << "reach " << reach << ", " << threads << " threads";
        }
}

TEST_F(TransportTest, SetMassesIsAnEditOfItsRegionThatReadsOnlyTheCells)
{
    // The routing writes its changed cells through Automaton::setMasses (no rescan of their
    // bounds). Against edit() over the same region: one cell over Tc, one emptied, a whole leaf
    // emptied (pruned), a new leaf beyond the clay; the same grid, leaves, totals, and the same
    // steps after (the same blocks woken). Bad lists are refused and change nothing.
    auto make = [] { return block(box(0, 0, 0, 15, 15, 15), 1000); };
    std::vector<Automaton::CellMass> cells = {{{{3, 3, 3}}, 1500}, {{{4, 3, 3}}, 0}, {{{20, 3, 3}}, 7}};
    for (int x = 8; x < 16; ++x)
        for (int y = 8; y < 16; ++y)
            for (int z = 8; z < 16; ++z)
                cells.push_back({{{x, y, z}}, 0});
    const Box region = box(3, 3, 3, 20, 15, 15);
    MassGridPtr ga = make(), gb = make();
    Automaton a(ga, opts()), b(gb, opts());
    a.edit(region, [&](MassGrid& g) {
        for (const Automaton::CellMass& c : cells)
            g.tree().setValue(openvdb::Coord(c.at[0], c.at[1], c.at[2]), c.mass);
    });
    b.setMasses(region, cells);
    EXPECT_EQ(contentHash(*gb), contentHash(*ga));
    EXPECT_EQ(gb->tree().leafCount(), ga->tree().leafCount());
    EXPECT_EQ(gb->tree().activeVoxelCount(), ga->tree().activeVoxelCount());
    EXPECT_EQ(b.totalMass(), a.totalMass());
    EXPECT_EQ(b.totalMass(), totalMass(*gb));
    EXPECT_EQ(b.residualOverload(), 500);
    EXPECT_EQ(b.residualOverload(), a.residualOverload());
    EXPECT_FALSE(gb->tree().probeConstLeaf(openvdb::Coord(8, 8, 8))); // emptied: pruned
    SettleOptions so;
    so.maxSteps = 40;
    a.settle(so);
    b.settle(so);
    EXPECT_EQ(b.stepCount(), a.stepCount());
    EXPECT_EQ(contentHash(*gb), contentHash(*ga));

    const uint64_t before = contentHash(*gb);
    const int64_t mass = b.totalMass();
    EXPECT_THROW(b.setMasses(region, {{{{5, 5, 5}}, 10}, {{{6, 5, 5}}, -1}}), Error);
    EXPECT_THROW(b.setMasses(box(0, 0, 0, 4, 4, 4), {{{{5, 5, 5}}, 10}}), Error);
    MassGridPtr g2 = block(box(0, 0, 0, 7, 7, 0), 1000);
    Automaton a2(g2, opts(2));
    EXPECT_THROW(a2.setMasses(box(0, 0, 0, 7, 7, 1), {{{{1, 1, 1}}, 10}}), Error);
    EXPECT_EQ(contentHash(*gb), before);
    EXPECT_EQ(b.totalMass(), mass);
}

TEST_F(TransportTest, GlobalLayerSkipsOverloadThatFitsWhereItIs)
{
    // Compressible clay (m0 = Tc / 2) with 3000 extra in one cell: its 24 cells within two steps
    // have 12000 room, so no solve; with 13000 extra (more than that room) it solves; in clay at
    // Tc (no room near) it solves. The automaton settles the skipped overload, mass exact.
    for (int extra : {3000, 13000}) {
        MassGridPtr g = block(box(0, 0, 0, 9, 9, 9), 500);
        g->tree().setValue(openvdb::Coord(5, 5, 5), 500 + extra);
        Automaton a(g, opts());
        const int64_t m0 = a.totalMass();
        const GlobalTransportReport r = transportGlobally(a);
        EXPECT_EQ(r.skipped, extra == 3000) << extra;
        EXPECT_EQ(r.solves == 0, extra == 3000) << extra;
        a.settle(100000);
        EXPECT_EQ(a.residualOverload(), 0);
        EXPECT_EQ(a.totalMass(), m0);
    }
    MassGridPtr g = block(box(0, 0, 0, 9, 9, 9), 1000);
    g->tree().setValue(openvdb::Coord(5, 5, 5), 1100);
    Automaton a(g, opts());
    const GlobalTransportReport r = transportGlobally(a);
    EXPECT_FALSE(r.skipped);
    EXPECT_GE(r.solves, 1u);
    EXPECT_EQ(r.overloadAfter, 0);
}

TEST_F(TransportTest, GlobalLayerIsIdenticalOnAnyThreadCount2DAnd3D)
{
    for (int dims : {2, 3}) {
        uint64_t first = 0;
        for (int threads : {1, 2, 3, 8}) {
            // > 4096 unknowns, so the solver's chunks really run in parallel.
            MassGridPtr g =
                dims == 3 ? block(box(0, 0, 0, 23, 23, 23), 1000) : block(box(0, 0, 0, 95, 95, 0), 1000);
            const int top = dims == 3 ? 23 : 95;
            for (int x = 0; x <= top; x += 3)
                g->tree().setValue(openvdb::Coord(x, top / 2, dims == 3 ? x / 2 : 0), 1700 + x);
            const int64_t m0 = totalMass(*g);
            Automaton a(g, opts(dims, threads));
            GlobalTransportOptions go;
            go.threads = threads;
            const GlobalTransportReport r = transportGlobally(a, go);
            EXPECT_GT(r.unknowns, 4096u);
            EXPECT_EQ(a.totalMass(), m0);
            EXPECT_EQ(totalMass(*g), m0);
            EXPECT_EQ(r.overloadAfter, 0) << dims << "D, " << threads << " threads";
            const uint64_t h = contentHash(*g);
            if (threads == 1) first = h;
            EXPECT_EQ(h, first) << dims << "D, " << threads << " threads";
        }
    }
}

TEST_F(TransportTest, MultigridSolvesAreExactIdenticalOnAnyThreadCountAndNeedFewerIterations)
{
    // The same overloaded block solved with the multigrid preconditioner (multigridMin 0) and with
    // MIC(0) (multigridMin beyond every solve): both exact, every solved cell at Tc; the multigrid result is
    // the same on 1, 2, 3 and 8 threads, 2D and 3D, and needs fewer CG iterations than MIC(0) at this size.
    for (int dims : {2, 3}) {
        uint64_t first = 0, micIterations = 0, mgIterations = 0;
        for (int threads : {1, 2, 3, 8, 0}) {
            const int top = dims == 3 ? 31 : 127;
            MassGridPtr g =
                dims == 3 ? block(box(0, 0, 0, top, top, top), 1000) : block(box(0, 0, 0, top, top, 0), 1000);
            for (int x = 1; x < top; x += 2)
                g->tree().setValue(openvdb::Coord(x, top / 2 + x % 5, dims == 3 ? top - x : 0), 1900 + 7 * x);
            const int64_t m0 = totalMass(*g);
            Automaton a(g, opts(dims, threads == 0 ? 1 : threads));
            GlobalTransportOptions go;
            go.threads = threads == 0 ? 1 : threads;
            SolverTuning tuning;
            tuning.multigridMin = threads == 0 ? UINT64_MAX : 0; // threads 0 here: MIC(0), one thread
            const GlobalTransportReport r = transport_internal::transportGlobally(a, go, tuning);
            EXPECT_EQ(r.multigridSolves, threads == 0 ? 0u : r.solves);
            EXPECT_EQ(totalMass(*g), m0);
            EXPECT_EQ(a.totalMass(), m0);
            EXPECT_EQ(r.overloadAfter, 0) << dims << "D, " << threads << " threads";
            for (auto it = g->tree().cbeginValueOn(); it; ++it)
                EXPECT_LE(*it, 1000);
            if (threads == 0) {
                micIterations = r.iterations;
                continue;
            }
            mgIterations = r.iterations;
            const uint64_t h = contentHash(*g);
            if (threads == 1) first = h;
            EXPECT_EQ(h, first) << dims << "D, " << threads << " threads";
        }
        EXPECT_LT(mgIterations, micIterations) << dims << "D";
    }
}

namespace {
/// Rows for the multigrid alone: a graph Laplacian (off-diagonals -1) with 6 neighbour rows a row (-1:
/// none), its diagonal as face counts and each row's cell.
struct MultigridRows {
    size_t n = 0;
    std::vector<int32_t> nb;
    std::vector<uint8_t> faces;
    std::vector<CellCoord> coord;
};

/// The cells of an nx x ny x nz box in x-fastest order; every row has 6 faces on the diagonal (the
/// box's own faces are Dirichlet faces: no neighbour row).
MultigridRows boxRows(int nx, int ny, int nz)
{
    MultigridRows m;
    m.n = size_t(nx) * size_t(ny) * size_t(nz);
    const auto row = [&](int x, int y, int z) {
        if (x < 0 || y < 0 || z < 0 || x >= nx || y >= ny || z >= nz) return int32_t(-1);
        return int32_t((z * ny + y) * nx + x);
    };
    for (int z = 0; z < nz; ++z)
        for (int y = 0; y < ny; ++y)
            for (int x = 0; x < nx; ++x) {
                for (int32_t j : {row(x - 1, y, z), row(x + 1, y, z), row(x, y - 1, z), row(x, y + 1, z),
                                  row(x, y, z - 1), row(x, y, z + 1)})
                    m.nb.push_back(j);
                m.faces.push_back(6);
                m.coord.push_back(CellCoord{x, y, z});
            }
    return m;
}

/// A x for @a m's matrix.
std::vector<double> timesMatrix(const MultigridRows& m, const std::vector<double>& x)
{
    std::vector<double> ax(m.n);
    for (size_t k = 0; k < m.n; ++k) {
        ax[k] = double(m.faces[k]) * x[k];
        for (int d = 0; d < 6; ++d)
            if (m.nb[k * 6 + size_t(d)] >= 0) ax[k] -= x[size_t(m.nb[k * 6 + size_t(d)])];
    }
    return ax;
}

double dot(const std::vector<double>& a, const std::vector<double>& b)
{
    return std::inner_product(a.begin(), a.end(), b.begin(), 0.0);
}

/// One V-cycle of @a m's hierarchy applied to @a in, built and applied on @a threads (0: serially).
std::vector<double> vCycle(const MultigridRows& m, const std::vector<double>& in, int threads)
{
    transport_internal::Multigrid mg;
    std::vector<double> out;
    const auto run = [&]() {
        mg.build(m.n, m.nb, m.faces, m.coord, threads == 0);
        mg.apply(in, out);
    };
    if (threads == 0)
        run();
    else
        tbb::task_arena(threads).execute(run);
    return out;
}

std::vector<double> randomVector(size_t n, unsigned seed)
{
    std::mt19937 rng(seed);
    std::uniform_real_distribution<double> u(-1.0, 1.0);
    std::vector<double> v(n);
    for (double& x : v)
        x = u(rng);
    return v;
}
} // namespace

TEST_F(TransportTest, TheMultigridsVCycleIsSymmetricPositiveAndTheSameOnAnyThreadCount)
{
    // Over several levels (the finest by colour, the coarser by row): M is symmetric and positive, as
    // conjugate gradients need, and applying it gives the same bits serially and on 1, 2, 3, 8 threads.
    const MultigridRows m = boxRows(40, 36, 24);
    const std::vector<double> u = randomVector(m.n, 1), v = randomVector(m.n, 2);
    const std::vector<double> mu = vCycle(m, u, 0), mv = vCycle(m, v, 0);
    transport_internal::Multigrid mg;
    mg.build(m.n, m.nb, m.faces, m.coord, true);
    EXPECT_GE(mg.levels(), 3u);
    EXPECT_NEAR(dot(u, mv), dot(v, mu), 1e-12 * std::abs(dot(u, mv)));
    EXPECT_GT(dot(u, mu), 0.0);
    EXPECT_GT(dot(v, mv), 0.0);
    // A V-cycle is a preconditioner: M A u is nearer u than A u is.
    const std::vector<double> au = timesMatrix(m, u), mau = vCycle(m, au, 0);
    double err = 0, norm = 0;
    for (size_t k = 0; k < m.n; ++k) {
        err += (mau[k] - u[k]) * (mau[k] - u[k]);
        norm += u[k] * u[k];
    }
    EXPECT_LT(err, 0.5 * norm);
    for (int threads : {1, 2, 3, 8}) {
        const std::vector<double> t = vCycle(m, u, threads);
        ASSERT_EQ(t.size(), mu.size());
        EXPECT_EQ(0, std::memcmp(t.data(), mu.data(), mu.size() * sizeof(double))) << threads << " threads";
    }
}

TEST_F(TransportTest, TheMultigridOfOneLevelSolvesByCholeskyOrJacobiSweeps)
{
    // At most kDense rows: no coarser level; the V-cycle is the dense Cholesky solve, exact.
    {
        const MultigridRows m = boxRows(8, 8, 8);
        const std::vector<double> b = randomVector(m.n, 3);
        const std::vector<double> x = vCycle(m, b, 0);
        const std::vector<double> ax = timesMatrix(m, x);
        double err = 0;
        for (size_t k = 0; k < m.n; ++k)
            err = std::max(err, std::abs(ax[k] - b[k]));
        EXPECT_LT(err, 1e-12);
        EXPECT_EQ(0, std::memcmp(vCycle(m, b, 2).data(), x.data(), x.size() * sizeof(double)));
    }
    // Rows that no 2x2x2 block joins (a chain whose cells lie two apart): coarsening stalls at once and
    // the V-cycle is kCoarseSweeps damped Jacobi sweeps from omega D^-1 b, exactly these operations.
    MultigridRows m;
    m.n = 2000;
    for (size_t k = 0; k < m.n; ++k) {
        for (int32_t j : {k ? int32_t(k) - 1 : -1, k + 1 < m.n ? int32_t(k) + 1 : -1, -1, -1, -1, -1})
            m.nb.push_back(j);
        m.faces.push_back(2);
        m.coord.push_back(CellCoord{int32_t(2 * k), 0, 0});
    }
    const std::vector<double> b = randomVector(m.n, 4);
    const double omega = transport_internal::Multigrid::kOmega;
    std::vector<double> x(m.n), t(m.n);
    for (size_t k = 0; k < m.n; ++k)
        x[k] = omega * (1.0 / 2.0) * b[k];
    for (int s = 1; s < transport_internal::Multigrid::kCoarseSweeps; ++s) {
        for (size_t k = 0; k < m.n; ++k) {
            double r = b[k] - 2.0 * x[k];
            for (int d = 0; d < 6; ++d)
                if (m.nb[k * 6 + size_t(d)] >= 0) r += x[size_t(m.nb[k * 6 + size_t(d)])];
            t[k] = x[k] + omega * (1.0 / 2.0) * r;
        }
        x.swap(t);
    }
    for (int threads : {0, 2}) {
        const std::vector<double> got = vCycle(m, b, threads);
        ASSERT_EQ(got.size(), x.size());
        EXPECT_EQ(0, std::memcmp(got.data(), x.data(), x.size() * sizeof(double))) << threads << " threads";
    }
}

namespace {
/// A block at Tc (0..top on each axis; top 0: 23 in 3D, 95 in 2D) with a row of cells loaded far beyond
/// the room of its first shell of air: the active set grows over several rounds, the later ones
/// rebinding the first round's multigrid hierarchy.
MassGridPtr rebindingActiveSetScene(int dims, int top = 0)
{
    if (top == 0) top = dims == 3 ? 23 : 95;
    MassGridPtr g =
        dims == 3 ? block(box(0, 0, 0, top, top, top), 1000) : block(box(0, 0, 0, top, top, 0), 1000);
    for (int x = 4; x < top - 4; x += 2)
        g->tree().setValue(openvdb::Coord(x, top / 2, dims == 3 ? top / 2 : 0), dims == 3 ? 400000 : 60000);
    return g;
}

/// One global transport of @a a's clay on @a threads, every solve by the multigrid.
GlobalTransportReport transportByMultigrid(Automaton& a, int threads)
{
    GlobalTransportOptions go;
    go.threads = threads;
    SolverTuning tuning;
    tuning.multigridMin = 0;
    return transport_internal::transportGlobally(a, go, tuning);
}
} // namespace

TEST_F(TransportTest, ActiveSetRoundsReuseTheMultigridHierarchyExactlyOnAnyThreadCount)
{
    // An overload far larger than the room of the block's first shell of air: the active set grows
    // over several rounds, the later ones rebind the first round's multigrid hierarchy. Mass is
    // exact, the overload is gone (to the solver's tolerance), and the result is the same on 1, 2, 3 and 8
    // threads (the parallel matrix set-up and the routing's parallel sort included), 2D and 3D.
    for (int dims : {2, 3}) {
        uint64_t first = 0, solves = 0;
        for (int threads : {1, 2, 3, 8}) {
            MassGridPtr g = rebindingActiveSetScene(dims);
            const int64_t m0 = totalMass(*g);
            Automaton a(g, opts(dims, threads));
            const GlobalTransportReport r = transportByMultigrid(a, threads);
            EXPECT_GE(r.solves, 3u) << dims << "D";
            EXPECT_EQ(r.multigridSolves, r.solves);
            EXPECT_GE(r.multigridReused, 2u) << dims << "D, " << r.solves << " solves";
            EXPECT_EQ(totalMass(*g), m0);
            EXPECT_EQ(a.totalMass(), m0);
            // The active set ends within the solver's tolerance: a few units of Tc may be left
            // over Tc at the rim (14 of 4.3e6 in 3D, also without the reuse), for the automaton.
            EXPECT_LT(r.overloadAfter * 10000, r.overloadBefore) << dims << "D, " << threads << " threads";
            const uint64_t h = contentHash(*g);
            if (threads == 1) first = h, solves = r.solves;
            EXPECT_EQ(h, first) << dims << "D, " << threads << " threads";
            EXPECT_EQ(r.solves, solves) << dims << "D, " << threads << " threads";
        }
    }
}

TEST_F(TransportTest, TheMultigridActiveSetGivesItsPinnedHashAndIterations)
{
    // The active-set scene above (the first solve builds the hierarchy, later rounds rebind it; 2D
    // and 3D, 1 and 3 threads): its content hash and CG iterations, pinned. The V-cycle's finest-level
    // residual and CG's A p read 6 neighbour rows per row (a missing face points at a -0 / +0
    // sentinel): the same additions in the same order as a loop over the present faces (CSR rows),
    // which computes these values too.
    const uint64_t pinnedHash[2] = {0xc9607a28cfb7c329ull, 0xac3ff2ff670d6ecfull};
    const uint64_t pinnedIterations[2] = {24, 12};
    for (int dims : {2, 3})
        for (int threads : {1, 3}) {
            MassGridPtr g = rebindingActiveSetScene(dims);
            Automaton a(g, opts(dims, threads));
            const GlobalTransportReport r = transportByMultigrid(a, threads);
            EXPECT_GE(r.multigridReused, 2u) << dims << "D";
            EXPECT_EQ(contentHash(*g), pinnedHash[dims - 2]) << dims << "D, " << threads << " threads";
            EXPECT_EQ(r.iterations, pinnedIterations[dims - 2]) << dims << "D, " << threads << " threads";
        }
}

TEST_F(TransportTest, AWorkspaceKeptAcrossCallsChangesNoResult)
{
    // One workspace serves calls of different sizes, dimensions, preconditioners and thread counts
    // in turn (large 3D multigrid, small 2D MIC(0), a smaller 3D multigrid, the large one again):
    // each result and report is that of a call with no workspace (its arrays are never read stale).
    struct Case {
        int dims, top, threads;
        uint64_t multigridMin;
    };
    const Case cases[] = {{3, 23, 2, 0}, {2, 40, 1, 20000}, {3, 15, 3, 0}, {3, 23, 1, 0}, {2, 95, 2, 0}};
    auto make = [](const Case& c) { return rebindingActiveSetScene(c.dims, c.top); };
    GlobalTransportWorkspace ws;
    for (const Case& c : cases) {
        GlobalTransportOptions go;
        go.threads = c.threads;
        SolverTuning tuning;
        tuning.multigridMin = c.multigridMin;
        MassGridPtr fresh = make(c), reused = make(c);
        const int64_t m0 = totalMass(*fresh);
        Automaton a(fresh, opts(c.dims, c.threads)), b(reused, opts(c.dims, c.threads));
        const GlobalTransportReport ra = transport_internal::transportGlobally(a, go, tuning);
        const GlobalTransportReport rb = transport_internal::transportGlobally(b, go, tuning, &ws);
        EXPECT_GT(ra.massMoved, 0) << c.dims << "D " << c.top;
        EXPECT_EQ(contentHash(*reused), contentHash(*fresh)) << c.dims << "D " << c.top;
        EXPECT_EQ(rb.solves, ra.solves);
        EXPECT_EQ(rb.iterations, ra.iterations);
        EXPECT_EQ(rb.multigridReused, ra.multigridReused);
        EXPECT_EQ(rb.massMoved, ra.massMoved);
        EXPECT_EQ(totalMass(*reused), m0);
    }
    ws.release();
    MassGridPtr g = make(cases[0]);
    Automaton a(g, opts(3, 1));
    EXPECT_GT(transportGlobally(a, {}, &ws).massMoved, 0); // usable again after release()
}

TEST_F(TransportTest, ALargeSolveRoutesInBlocksIdenticallyOnAnyThreadCount)
{
    // Over 65,536 unknowns: the routing gathers its lower neighbours a block of 65,536 cells at a
    // time, the inflow and the set-up run on many chunks. Same result on 1, 2, 3 and 8 threads,
    // mass exact, the overload gone.
    uint64_t first = 0;
    for (int threads : {1, 2, 3, 8}) {
        MassGridPtr g = block(box(0, 0, 0, 43, 43, 43), 1000);
        for (int x = 2; x < 42; x += 3)
            g->tree().setValue(openvdb::Coord(x, 21, 21), 300000);
        const int64_t m0 = totalMass(*g);
        Automaton a(g, opts(3, threads));
        GlobalTransportOptions go;
        go.threads = threads;
        const GlobalTransportReport r = transportGlobally(a, go);
        EXPECT_GT(r.unknowns, 65536u);
        EXPECT_EQ(totalMass(*g), m0);
        EXPECT_LT(r.overloadAfter * 10000, r.overloadBefore);
        const uint64_t h = contentHash(*g);
        if (threads == 1) first = h;
        EXPECT_EQ(h, first) << threads << " threads";
    }
}

TEST_F(TransportTest, TheRoutingsOrderIsOneSequenceOnAnyThreadCount)
{
    // Over 2 x kSortBlock cells the threaded radix sort runs by blocks in parallel: the order is a
    // comparison sort's on 1, 2, 3 and 8 threads, ties of p (a few values, -0 and +0 among them)
    // by coordinate.
    using namespace transport_internal;
    const size_t n = 3 * kSortBlock + 1234;
    std::vector<double> p(n);
    std::vector<CellCoord> at(n);
    std::mt19937 rng(7);
    const double values[] = {-0.0, 0.0, 1.5, -2.25, 1e-300};
    for (size_t i = 0; i < n; ++i) {
        p[i] = i % 3 == 0 ? values[rng() % 5] : std::ldexp(double(rng()) - 2147483648.0, -20);
        at[i] = CellCoord{int32_t(i % 97) - 40, int32_t(i / 97 % 89), int32_t(i / (97 * 89))};
    }
    const HigherPotential higher{p, at};
    std::vector<int32_t> expected(n);
    std::iota(expected.begin(), expected.end(), 0);
    std::sort(expected.begin(), expected.end(), higher);
    for (int threads : {1, 2, 3, 8}) {
        std::vector<int32_t> order(n);
        std::iota(order.begin(), order.end(), 0);
        RadixScratch scratch;
        tbb::task_arena arena(threads);
        arena.execute([&] { sortByPotential(order, higher, scratch, threads == 1); });
        EXPECT_EQ(order, expected) << threads << " threads";
    }
}

namespace {

/// Chamber A (x 0..3) full at Tc with 2,000 extra at (1, 1, 1), in @a g; chamber B (x 5..8) empty;
/// the obstacles @a obs: a wall at x = 4 and a closed shell around both.
void walledInChambers(MassGridPtr& g, openvdb::MaskGrid::Ptr& obs)
{
    g = block(box(0, 0, 0, 3, 3, 3), 1000);
    g->tree().setValue(openvdb::Coord(1, 1, 1), 3000);
    obs = openvdb::MaskGrid::create(false);
    obs->tree().fill(openvdb::CoordBBox(openvdb::Coord(-1, -1, -1), openvdb::Coord(9, 4, 4)), true, true);
    obs->tree().fill(openvdb::CoordBBox(openvdb::Coord(0, 0, 0), openvdb::Coord(3, 3, 3)), false, true);
    obs->tree().fill(openvdb::CoordBBox(openvdb::Coord(5, 0, 0), openvdb::Coord(8, 3, 3)), false, true);
    obs->tree().voxelizeActiveTiles();
}

} // namespace

TEST_F(TransportTest, WalledInClayIsReportedAsNoRoomAndLeftAsItIs)
{
    // A's clay cannot reach B (walledInChambers): NoRoom, nothing moves.
    MassGridPtr g;
    openvdb::MaskGrid::Ptr obs;
    walledInChambers(g, obs);
    Automaton a(g, opts(), obs);
    const uint64_t h = contentHash(*g);
    const GlobalTransportReport r = transportGlobally(a);
    EXPECT_TRUE(r.noRoom);
    EXPECT_EQ(r.massNoRoom, 2000);
    EXPECT_EQ(contentHash(*g), h);
    EXPECT_EQ(r.overloadAfter, 2000);

    // Open the wall at one cell: now the overload crosses there, and only there, into B.
    obs->tree().setValueOff(openvdb::Coord(4, 3, 3));
    Automaton b(g, opts(), obs);
    const GlobalTransportReport r2 = transportGlobally(b);
    EXPECT_FALSE(r2.noRoom);
    EXPECT_EQ(r2.overloadAfter, 0);
    EXPECT_EQ(totalMass(*g), 64 * 1000 + 2000);
    for (auto it = obs->tree().cbeginValueOn(); it; ++it)
        EXPECT_EQ(g->tree().getValue(it.getCoord()), 0);
    EXPECT_GT(g->tree().getValue(openvdb::Coord(4, 3, 3)), 0);
}

namespace {

uint64_t runScene(const std::string& json, int threads, int64_t* drift = nullptr, uint64_t* steps = nullptr)
{
    Sculptor sc(parseScene(json, "t.json", ""), threads);
    const int64_t m0 = sc.automaton().totalMass();
    uint64_t n = 0;
    while (!sc.done()) {
        const FrameReport r = sc.runFrame();
        n += r.settle.steps;
        EXPECT_EQ(totalMass(*sc.mass()), m0) << "frame " << r.frame;
        EXPECT_NE(r.settle.reason, StopReason::StepBudget) << "frame " << r.frame;
    }
    if (drift) *drift = totalMass(*sc.mass()) - m0;
    if (steps) *steps = n;
    return contentHash(*sc.mass());
}

std::string pressScene(const char* rule, const char* push, const char* transport, int dims = 3)
{
    const std::string d = std::to_string(dims);
    if (dims == 2) {
        return std::string(R"({"dimensions": 2, "threshold": 1000, "rule": ")") + rule + R"(", "push": ")" +
               push + R"(", "transport": ")" + transport + R"(", "alpha": 0.4,
            "clay": [{"shape": "box", "min": [0,0], "max": [23,23], "mass": 1000}],
            "tools": [{"shape": "box", "min": [-20,24], "max": [43,27], "path": [{"translate": [0,-1], "frames": 8}]}],
            "obstacles": [{"shape": "box", "min": [-60,-3], "max": [80,-1]}],
            "settle": {"max_steps": 400000}})";
    }
    return std::string(R"({"threshold": 1000, "rule": ")") + rule + R"(", "push": ")" + push +
           R"(", "transport": ")" + transport + R"(", "alpha": 0.4,
        "clay": [{"shape": "box", "min": [0,0,0], "max": [11,11,11], "mass": 1000}],
        "tools": [{"shape": "box", "min": [-10,12,-10], "max": [21,14,21], "path": [{"translate": [0,-1,0], "frames": 4}]}],
        "obstacles": [{"shape": "box", "min": [-30,-3,-30], "max": [40,-1,40]}],
        "settle": {"max_steps": 400000}})";
}

/// @a json (a 3D pressScene) with clay walled in a closed chamber beside the cube, more than Tc per cell
/// in part of it (950 on 4^3 cells, 1500 more on 2^3): overload that never finds room.
std::string withWalledOverloadBesideTheCube(std::string json)
{
    json.replace(json.find(R"("clay": [)"), 9,
                 R"("clay": [{"shape": "box", "min": [31,1,31], "max": [34,4,34], "mass": 950},
        {"shape": "box", "min": [31,1,31], "max": [32,2,32], "mass": 1500}, )");
    json.replace(json.find(R"("obstacles": [)"), 14, R"("obstacles": [
        {"shape": "box", "min": [30,0,30], "max": [35,0,35]}, {"shape": "box", "min": [30,5,30], "max": [35,5,35]},
        {"shape": "box", "min": [30,1,30], "max": [30,4,35]}, {"shape": "box", "min": [35,1,30], "max": [35,4,35]},
        {"shape": "box", "min": [31,1,30], "max": [34,4,30]}, {"shape": "box", "min": [31,1,35], "max": [34,4,35]}, )");
    return json;
}

} // namespace

TEST_F(TransportTest, GlobalPressKeepsMassOverEveryFrameWithEveryRuleIn2DAnd3D)
{
    for (int dims : {2, 3})
        for (const char* rule : {"prorata", "sorted", "bingham", "arata"})
            for (const char* push : {"surface", "compress"}) {
                int64_t drift = 1;
                runScene(pressScene(rule, push, "global", dims), 2, &drift);
                EXPECT_EQ(drift, 0) << dims << "D " << rule << " " << push;
            }
}

TEST_F(TransportTest, GlobalPressIsIdenticalOnOneTwoThreeAndEightThreads)
{
    // Surface: the later frames run the automaton's try before the layer.
    for (const char* push : {"compress", "surface"})
        for (int dims : {2, 3}) {
            const std::string s = pressScene("prorata", push, "global", dims);
            const uint64_t h1 = runScene(s, 1);
            for (int threads : {2, 3, 8})
                EXPECT_EQ(runScene(s, threads), h1) << push << " " << dims << "D, " << threads << " threads";
        }
}

TEST_F(TransportTest, GlobalTransportNeedsFarFewerStepsThanLocal)
{
    uint64_t local = 0, global = 0;
    runScene(pressScene("prorata", "compress", "local"), 2, nullptr, &local);
    runScene(pressScene("prorata", "compress", "global"), 2, nullptr, &global);
    EXPECT_LT(global * 4, local) << "global " << global << " steps, local " << local;
}

TEST_F(TransportTest, ASqueezedTallCylinderKeepsStraightSides)
{
    // A cylinder R0 6, H0 36 at Tc squeezed to H 24 between slip plates (global + compress): it
    // should stay a cylinder (radius 6 sqrt(1.5) = 7.3, about 170 cells per layer). The column
    // under the plate is longer than both the contact size (~11) and the surface push's search, so
    // a push cut at either leaves the bottom uncompressed and the clay flows out under the plate.
    const std::string json = R"({"threshold": 1000, "rule": "prorata", "seed": 1, "push": "compress",
        "transport": "global",
        "clay": [{"shape": "cylinder", "center": [0, 17.5, 0], "radius": 6, "height": 36, "mass": 1000}],
        "tools": [{"shape": "box", "min": [-24, 36, -24], "max": [24, 39, 24], "path": [{"translate": [0, -1, 0], "frames": 12}]}],
        "obstacles": [{"shape": "box", "min": [-36, -3, -36], "max": [36, -1, 36]}],
        "settle": {"max_steps": 400000}})";
    int64_t drift = 1;
    Sculptor sc(parseScene(json, "t.json", ""), 2);
    const int64_t m0 = sc.automaton().totalMass();
    sc.run();
    drift = totalMass(*sc.mass()) - m0;
    EXPECT_EQ(drift, 0);
    std::vector<int64_t> layer(24, 0);
    int64_t above = 0;
    for (auto it = sc.mass()->tree().cbeginValueOn(); it; ++it) {
        if (*it * 2 < 1000) continue;
        const int y = it.getCoord().y();
        if (y >= 0 && y < 24)
            ++layer[size_t(y)];
        else
            ++above;
    }
    EXPECT_EQ(above, 0);
    const int64_t lo = *std::min_element(layer.begin(), layer.end());
    const int64_t hi = *std::max_element(layer.begin(), layer.end());
    std::string counts;
    for (int64_t n : layer)
        counts += " " + std::to_string(n);
    // Cells per layer within 10 % of each other (radius within 5 %; one ring of cells is ~5 %), floor
    // to plate. Measured: 157 ... 169; a push cut at the search region would give 109 ... 293, a cone.
    EXPECT_LE(hi * 100, lo * 110) << "cells per layer, floor to plate:" << counts;
    EXPECT_GE(lo, 150) << counts;
}

TEST_F(TransportTest, OnCompressibleClayGlobalWithTheSurfacePushSettlesAsLocalDoes)
{
    // A 24^3 press at 0.8 Tc: after each surface push the automaton's try settles the frame (a
    // few hundred cheap steps), so the global layer never runs and the result is local's, bit for bit.
    const auto scene = [](const char* transport) {
        return std::string(R"({"threshold": 1000, "rule": "prorata", "push": "surface", "transport": ")") +
               transport + R"(",
            "clay": [{"shape": "box", "min": [0,0,0], "max": [23,23,23], "mass": 800}],
            "tools": [{"shape": "box", "min": [-12,24,-12], "max": [35,27,35], "path": [{"translate": [0,-1,0], "frames": 4}]}],
            "obstacles": [{"shape": "box", "min": [-30,-3,-30], "max": [50,-1,50]}],
            "settle": {"max_steps": 400000}})";
    };
    const std::string local = scene("local"), global = scene("global");
    uint64_t localSteps = 0, globalSteps = 0;
    const uint64_t h = runScene(local, 2, nullptr, &localSteps);
    EXPECT_EQ(runScene(global, 2, nullptr, &globalSteps), h);
    EXPECT_EQ(globalSteps, localSteps);
    for (int threads : {1, 8})
        EXPECT_EQ(runScene(global, threads), h) << threads << " threads";
    Sculptor sc(parseScene(global, "t.json", ""), 3);
    sc.run(0, [](const FrameReport& r) {
        EXPECT_GT(r.trySteps, 0u) << "frame " << r.frame;
        EXPECT_EQ(r.trySteps, r.settle.steps) << "frame " << r.frame;
        EXPECT_EQ(r.transport.solves, 0u) << "frame " << r.frame;
    });
    EXPECT_EQ(contentHash(*sc.mass()), h);
}

TEST_F(TransportTest, TheTryIsJudgedByTheClayNearTheToolNotByTheWholeBody)
{
    // A sphere of clay at Tc (32 wide) stroked by a small sphere, beside a large loose lump (0.5 Tc)
    // the tool never touches: the body's mean density is ~0.55, under the try's 0.96, but the
    // stroked clay is saturated. Judged near the tool (the push's region grown by the layer's
    // reach), every frame goes straight to the layer, as the stroke at Tc on its own does; judged by
    // the whole body, the automaton's try would run first (250-380 steps a frame here, up to its cap
    // of 4096 on larger clay) after a scan of the whole body every frame. A sphere pressed into the
    // loose lump is still settled by the try alone.
    const auto scene = [](const std::string& tool) {
        return R"({"threshold": 1000, "rule": "prorata", "push": "surface", "transport": "global",
            "clay": [{"shape": "sphere", "center": [16,16,16], "radius": 16, "mass": 1000},
                     {"shape": "box", "min": [80,0,0], "max": [143,63,63], "mass": 500}],
            "tools": [)" +
               tool + R"(],
            "obstacles": [{"shape": "box", "min": [-30,-3,-30], "max": [170,-1,100]}],
            "settle": {"max_steps": 400000}})";
    };
    const std::string plate =
        R"({"shape": "sphere", "center": [10, 34, 16], "radius": 4, "path": [{"translate": [2,0,0], "frames": 4}]})";
    const std::string sphere =
        R"({"shape": "sphere", "center": [112, 67, 32], "radius": 4, "path": [{"translate": [0,-1,0], "frames": 3}]})";
    uint64_t solves = 0, tries = 0;
    Sculptor pressed(parseScene(scene(plate), "t.json", ""), 2);
    const int64_t m0 = pressed.automaton().totalMass();
    pressed.run(0, [&](const FrameReport& r) {
        tries += r.trySteps;
        solves += r.transport.solves;
    });
    EXPECT_EQ(tries, 0u);
    EXPECT_GT(solves, 0u);
    EXPECT_EQ(totalMass(*pressed.mass()), m0);
    solves = tries = 0;
    Sculptor poked(parseScene(scene(sphere), "t.json", ""), 2);
    poked.run(0, [&](const FrameReport& r) {
        tries += r.trySteps;
        solves += r.transport.solves;
    });
    EXPECT_GT(tries, 0u);
    EXPECT_EQ(solves, 0u);
}

TEST_F(TransportTest, AGlobalRunStoppedAndResumedIsIdenticalToAnUnbrokenRun)
{
    // The press, plus clay walled in a closed chamber with more than Tc per cell on average: the
    // global layer reports it and leaves it, the automaton shuffles it until the frame's step budget,
    // so frames have steps to be stopped between. Compress push: the layer runs right after the push.
    // Surface push: the first frame (the cube at Tc, saturated) goes to the layer at once; in the later
    // frames (clay spread thin around the cube) the automaton's try runs first, gives up at its work
    // cap, then the layer runs. A stop asked inside the try is honoured after the layer (a frame saved
    // open is past its layer): the resumed run never repeats or skips it.
    for (const char* push : {"compress", "surface"}) {
        std::string json = withWalledOverloadBesideTheCube(pressScene("prorata", push, "global"));
        const bool surface = std::string(push) == "surface";
        json.replace(json.find(R"("max_steps": 400000)"), 19,
                     surface ? R"("max_steps": 400)" : R"("max_steps": 40)");
        const Scene s = parseScene(json, "t.json", "");
        Sculptor whole(s, 2);
        uint64_t tried = 0, layers = 0;
        whole.run(0, [&](const FrameReport& r) {
            tried += r.trySteps > 0 ? 1 : 0;
            layers += r.transport.overloadBefore > 0 ? 1 : 0;
        });
        EXPECT_EQ(layers, 4u) << push; // every frame reaches the layer
        EXPECT_EQ(tried, surface ? 3u : 0u) << push;
        const uint64_t h = contentHash(*whole.mass());
        const uint64_t steps = whole.automaton().stepCount();
        const std::string ckpt = "/tmp/vdbclay-transport-ckpt-" + std::to_string(::getpid()) + ".vdb";
        for (uint64_t every : surface ? std::vector<uint64_t>{37, 91} : std::vector<uint64_t>{7, 13}) {
            Scene cur = s;
            int checkpoints = 0, midFrame = 0, insideTry = 0;
            for (;;) {
                Sculptor sc(cur, checkpoints % 2 ? 1 : 3);
                const uint64_t stopAt = sc.automaton().stepCount() + every;
                sc.setStopRequest([&sc, stopAt] { return sc.automaton().stepCount() >= stopAt; });
                // A frame reopened from a mid-frame checkpoint neither pushes, tries nor transports again.
                bool reopened = sc.frameOpen();
                sc.run(0, [&](const FrameReport& r) {
                    const uint64_t start = sc.automaton().stepCount() - r.settle.steps;
                    if (reopened) {
                        EXPECT_EQ(r.push.voxelsPushed, 0u);
                        EXPECT_EQ(r.trySteps, 0u);
                        EXPECT_EQ(r.transport.solves, 0u);
                    } else {
                        EXPECT_GT(r.transport.overloadBefore, 0);
                        // A stop asked inside the try: the frame went on through the layer.
                        if (r.trySteps > 0 && start + r.trySteps >= stopAt) {
                            ++insideTry;
                            EXPECT_GT(sc.automaton().stepCount(), start + r.trySteps);
                        }
                    }
                    reopened = false;
                });
                if (!sc.stopped()) {
                    EXPECT_EQ(contentHash(*sc.mass()), h) << push << " every " << every;
                    EXPECT_EQ(sc.automaton().stepCount(), steps) << push << " every " << every;
                    break;
                }
                const ClayMeta m = sc.checkpointMeta();
                if (m.frameSteps) ++midFrame;
                writeClayFile(ckpt, *sc.mass(), m);
                cur.start = ckpt;
                ASSERT_LT(++checkpoints, 10000);
            }
            EXPECT_GT(midFrame, 0) << push << " every " << every;
            if (surface) {
                EXPECT_GT(insideTry, 0) << "every " << every;
            }
        }
        std::remove(ckpt.c_str());
    }
}

TEST_F(TransportTest, MemoryEstimateCountsTheGlobalLayer)
{
    const std::string base = R"("clay": [{"shape": "box", "min": [0,0,0], "max": [31,31,31], "mass": 1000}])";
    const MemoryEstimate local = estimateSceneMemory(parseScene("{" + base + "}", "s.json", ""));
    const MemoryEstimate global =
        estimateSceneMemory(parseScene(R"({"transport": "global", )" + base + "}", "s.json", ""));
    EXPECT_EQ(local.transportBytes, 0u);
    EXPECT_GE(global.transportBytes, global.clayLeavesGrown * 512 * 200);
    // The layer's arrays and the output grids are not held at once: the larger counts.
    EXPECT_EQ(global.total(),
              local.total() - local.outputBytes + std::max(global.transportBytes, global.outputBytes));
}

// ---- the swept push ------------------------------------------------------------------------------

TEST_F(TransportTest, AThinPlateFlattensClayInsteadOfHoppingOverIt)
{
    // An 8^3 cube on a floor, a plate one voxel thick coming down from y = 9 to y = 1 in 8 frames.
    const std::string scene = R"({"threshold": 1000, "sweep": SWEEP,
        "clay": [{"shape": "box", "min": [0,0,0], "max": [7,7,7], "mass": 1000}],
        "tools": [{"shape": "box", "min": [-12,9,-12], "max": [19,9,19], "path": [{"translate": [0,-1,0], "frames": 8}]}],
        "obstacles": [{"shape": "box", "min": [-40,-3,-40], "max": [47,-1,47]}],
        "settle": {"max_steps": 200000}})";
    for (const char* sweep : {"false", "true"}) {
        std::string json = scene;
        json.replace(json.find("SWEEP"), 5, sweep);
        Sculptor sc(parseScene(json, "t.json", ""), 2);
        sc.run();
        int64_t above = 0;
        for (auto it = sc.mass()->tree().cbeginValueOn(); it; ++it)
            if (it.getCoord().y() > 1) above += *it;
        EXPECT_EQ(totalMass(*sc.mass()), 512 * 1000);
        if (std::string(sweep) == "true")
            EXPECT_EQ(above, 0) << "clay above the plate";
        else
            EXPECT_GT(above, 0) << "the unswept push no longer lets clay hop over (update this test)";
    }
}

TEST_F(TransportTest, TheReachCountsFromTheContactNotFromEveryCellOfACompressChain)
{
    // A 21^3 block at Tc; a compress chain from the top face straight down: (10, 20 ... 17, 10), 25
    // extra each. Reach 4. From the contact (the chain's top cell, the only one with a face on room)
    // the unknowns are the cells within 4 face steps of it: a half octahedron, 85 cells. From every
    // over cell (reachFromContact false): the union of the four chain cells' octahedra, 208 cells. Both
    // exact: every cell of the block ends at Tc, the 100 extra above it.
    for (const bool fromContact : {true, false}) {
        MassGridPtr g = block(box(0, 0, 0, 20, 20, 20), 1000);
        for (int y = 17; y <= 20; ++y)
            g->tree().setValue(openvdb::Coord(10, y, 10), 1025);
        Automaton a(g, opts());
        GlobalTransportOptions go;
        go.reach = 4;
        SolverTuning tuning;
        tuning.reachFromContact = fromContact;
        const GlobalTransportReport r = transport_internal::transportGlobally(a, go, tuning);
        EXPECT_EQ(r.overloadBefore, 100);
        EXPECT_EQ(r.overloadAfter, 0) << fromContact;
        EXPECT_EQ(r.reach, 4);
        EXPECT_EQ(r.unknowns, fromContact ? 85u : 208u);
        EXPECT_EQ(a.totalMass(), int64_t(21 * 21 * 21) * 1000 + 100);
        EXPECT_EQ(totalMass(*g), a.totalMass());
        int64_t inside = 0;
        for (int x = 0; x <= 20; ++x)
            for (int y = 0; y <= 20; ++y)
                for (int z = 0; z <= 20; ++z)
                    inside += at(a, x, y, z) == 1000 ? 1 : 0;
        EXPECT_EQ(inside, 21 * 21 * 21) << fromContact;
    }
}

namespace {

/// A 21^3 block at Tc (1000) with a chain (10, 9 ... 20, 10) of 12 cells, 40 extra each, and a lone
/// over cell deep inside at (4, 4, 4), 300 extra.
MassGridPtr chainAndLoneCell()
{
    MassGridPtr g = block(box(0, 0, 0, 20, 20, 20), 1000);
    for (int y = 9; y <= 20; ++y)
        g->tree().setValue(openvdb::Coord(10, y, 10), 1040);
    g->tree().setValue(openvdb::Coord(4, 4, 4), 1300);
    return g;
}

/// The cells of that block holding exactly Tc.
int64_t cellsOfTheBlockAtTc(const Automaton& a)
{
    int64_t n = 0;
    for (int x = 0; x <= 20; ++x)
        for (int y = 0; y <= 20; ++y)
            for (int z = 0; z <= 20; ++z)
                n += at(a, x, y, z) == 1000 ? 1 : 0;
    return n;
}

} // namespace

TEST_F(TransportTest, OverCellsBeyondTheContactsReachStartTheirOwnFloodIdenticallyOnAnyThreadCount)
{
    // A chain deeper than the reach: (10, 20 ... 9, 10), 12 cells, 40 extra each, reach 3, and a lone
    // over cell deep inside (4, 4, 4). The cells the contact's flood misses start floods of their own:
    // every over cell is solved, all of the block ends at Tc, mass exact, the same on 1, 2, 3, 8 threads.
    uint64_t first = 0;
    for (int threads : {1, 2, 3, 8}) {
        MassGridPtr g = chainAndLoneCell();
        Automaton a(g, opts(3, threads));
        GlobalTransportOptions go;
        go.reach = 3;
        go.threads = threads;
        const GlobalTransportReport r = transportGlobally(a, go);
        EXPECT_EQ(r.overloadBefore, 12 * 40 + 300);
        EXPECT_EQ(r.overloadAfter, 0) << threads;
        EXPECT_FALSE(r.noRoom);
        // The lone cell is 5 steps from room: its margin (2) doubles with the reach, once, to 4, so
        // its flood links the face cell beside room (one rebuild, not one per doubling up to the body).
        EXPECT_EQ(r.reach, 6);
        EXPECT_EQ(totalMass(*g), int64_t(21 * 21 * 21) * 1000 + 780);
        EXPECT_EQ(cellsOfTheBlockAtTc(a), 21 * 21 * 21) << threads;
        const uint64_t h = contentHash(*g);
        if (threads == 1) first = h;
        EXPECT_EQ(h, first) << threads;
    }
}

TEST_F(TransportTest, ADoublingOfTheReachStopsFirstAtTheCallersBoundOnRoom)
{
    // The block of the test above: reach 3 finds no room for the lone cell, so it doubles, to 6. With
    // roomWithin 4 or 5 (room lies within it) the doubling stops there, and that reach finds room: the
    // memory estimate's bound of the domain (max(reach, roomWithin), not twice). 7 lies past the
    // doubling: 6. Each exact: every cell at Tc, the 780 extra above the block.
    for (const int64_t within : {int64_t(0), int64_t(4), int64_t(5), int64_t(7)}) {
        MassGridPtr g = chainAndLoneCell();
        Automaton a(g, opts(3, 2));
        GlobalTransportOptions go;
        go.reach = 3;
        go.roomWithin = within;
        const GlobalTransportReport r = transportGlobally(a, go);
        EXPECT_EQ(r.reach, within == 4 || within == 5 ? within : 6) << within;
        EXPECT_EQ(r.overloadAfter, 0) << within;
        EXPECT_FALSE(r.noRoom);
        EXPECT_EQ(totalMass(*g), int64_t(21 * 21 * 21) * 1000 + 780);
        EXPECT_EQ(cellsOfTheBlockAtTc(a), 21 * 21 * 21) << within;
    }
    MassGridPtr g = block(box(0, 0, 0, 3, 3, 3), 1000);
    Automaton a(g, opts());
    GlobalTransportOptions go;
    go.roomWithin = -1;
    EXPECT_THROW(transportGlobally(a, go), Error);
}

TEST_F(TransportTest, OverloadTheTryCarriedBeyondTheReachIsLeftToTheCleanupNotToTheLayer)
{
    // After the automaton's try, the global layer looks for its seeds in the push's region only, not
    // as far as the try's steps can have carried the overload (up to 4096 steps: the memory estimate
    // would have to count the whole body). A 2D channel of clay at Tc 2400 long between two walls, a
    // plunger entering it 1 voxel a frame, room (loose clay) only at its far end, and loose clay
    // behind the upper wall near the plunger, so the clay near the tool is unsaturated on average and
    // the try runs. In the full channel the automaton carries the overload as a front, one voxel a
    // step: the try gives up at its work cap (~1,500 steps) with all of it far beyond the reach
    // (contact 6: reach 8). The layer finds no seed (seeded there, every frame would solve the
    // channel up to the front: 11,136 unknowns in the first frame, its reach doubled until it met the
    // room), and the cleanup automaton carries the front on to the room.
    const std::string json =
        R"({"dimensions": 2, "threshold": 1000, "rule": "prorata", "seed": 1, "transport": "global", "push": "surface",
        "clay": [{"shape": "box", "min": [0,0], "max": [2399,5], "mass": 1000},
                 {"shape": "box", "min": [2400,-20], "max": [2429,25], "mass": 300},
                 {"shape": "box", "min": [0,25], "max": [7,29], "mass": 300}],
        "obstacles": [{"shape": "box", "min": [-10,-3], "max": [2399,-1]}, {"shape": "box", "min": [-10,6], "max": [2399,24]}],
        "tools": [{"shape": "box", "min": [-4,0], "max": [-1,5], "path": [{"translate": [1,0,0], "frames": 4}]}],
        "settle": {"max_steps": 100000}})";
    uint64_t first = 0;
    for (int threads : {1, 2, 3, 8}) {
        Sculptor sc(parseScene(json, "t.json", ""), threads);
        const int64_t m0 = sc.automaton().totalMass();
        while (!sc.done()) {
            const FrameReport r = sc.runFrame();
            const std::string at = std::to_string(threads) + " threads, frame " + std::to_string(r.frame);
            EXPECT_EQ(r.push.contactSize, 6.0) << at;
            // The try gave up (the layer ran after it) having run further than the push's region (the
            // plunger's box grown by 18) and the reach (8) together.
            EXPECT_GT(r.trySteps, 4u + 18u + 8u) << at;
            EXPECT_LT(r.trySteps, r.settle.steps) << at;
            // The overload lay beyond the region and the reach: no seed, no domain; it was all still there.
            EXPECT_EQ(r.transport.overloadBefore, 0) << at;
            EXPECT_EQ(r.transport.unknowns, 0u) << at;
            EXPECT_EQ(r.transport.overloadAfter, 6000) << at;
            // The frame still settles, mass exact.
            EXPECT_TRUE(r.settle.settled) << at;
            EXPECT_EQ(r.settle.residualOverload, 0) << at;
            EXPECT_EQ(totalMass(*sc.mass()), m0) << at;
        }
        const uint64_t h = contentHash(*sc.mass());
        if (threads == 1) first = h;
        EXPECT_EQ(h, first) << threads << " threads";
    }
}

TEST_F(TransportTest, AFrameWhoseToolsTouchNoClayAfterAnUnsettledFrameLeavesTheOverloadToTheAutomaton)
{
    // A frame whose tools touch no clay runs the layer (over every over cell, no reach) only as the
    // scene's first frame (clay that starts over Tc), not after a frame that ended unsettled (over
    // every over cell however far, which the memory estimate does not count). A plate
    // presses a cube at Tc once, then lifts away; beside it, clay walled in a closed chamber with more
    // than Tc per cell: every frame ends with that overload left (no room). The first frame's layer
    // seeds it (it lies in the push's region); the later frames touch no clay and run no layer.
    std::string json = withWalledOverloadBesideTheCube(pressScene("prorata", "compress", "global"));
    const std::string path = R"([{"translate": [0,-1,0], "frames": 4}])";
    json.replace(json.find(path), path.size(),
                 R"([{"translate": [0,-1,0], "frames": 1}, {"translate": [0,10,0], "frames": 3}])");
    json.replace(json.find(R"("max_steps": 400000)"), 19, R"("max_steps": 40)");
    uint64_t first = 0;
    for (int threads : {1, 2, 3, 8}) {
        Sculptor sc(parseScene(json, "t.json", ""), threads);
        const int64_t m0 = sc.automaton().totalMass();
        int frames = 0;
        while (!sc.done()) {
            const FrameReport r = sc.runFrame();
            const std::string at = std::to_string(threads) + " threads, frame " + std::to_string(r.frame);
            ++frames;
            EXPECT_GT(r.settle.residualOverload, 0) << at; // the chamber's, every frame
            if (r.frame == 1) {
                EXPECT_GT(r.push.contactSize, 0.0) << at;
                EXPECT_GT(r.transport.overloadBefore, 0) << at;
                EXPECT_TRUE(r.transport.noRoom) << at;
            } else {
                EXPECT_EQ(r.push.contactSize, 0.0) << at;
                EXPECT_EQ(r.transport.overloadBefore, 0) << at; // no layer
                EXPECT_EQ(r.transport.solves, 0u) << at;
                EXPECT_EQ(r.trySteps, 0u) << at;
            }
            EXPECT_EQ(totalMass(*sc.mass()), m0) << at;
        }
        EXPECT_EQ(frames, 4);
        const uint64_t h = contentHash(*sc.mass());
        if (threads == 1) first = h;
        EXPECT_EQ(h, first) << threads << " threads";
    }
    // Resumed after the first frame (its file records a cell over Tc), the run does what the unbroken
    // one did: the rule goes by the scene's frame number.
    const std::string ckpt = "/tmp/vdbclay-transport-touchnone-" + std::to_string(::getpid()) + ".vdb";
    Scene s = parseScene(json, "t.json", "");
    {
        Sculptor sc(s, 2);
        sc.runFrame();
        writeClayFile(ckpt, *sc.mass(), sc.checkpointMeta());
    }
    s.start = ckpt;
    Sculptor resumed(s, 3);
    resumed.run(
        0, [](const FrameReport& r) { EXPECT_EQ(r.transport.overloadBefore, 0) << "frame " << r.frame; });
    EXPECT_EQ(resumed.frame(), 4u);
    EXPECT_EQ(contentHash(*resumed.mass()), first);
    std::remove(ckpt.c_str());
}

TEST_F(TransportTest, TheLayersWorkFollowsTheToolNotTheBody)
{
    // The stroke of transport_study (a sphere r 6 dipped 9 voxels, slid 2 a frame) into the
    // flat top of a slab at Tc, 96 wide and 256 wide, the tool at the same place. The layer's domain
    // is the clay within the reach of the contact: every frame solves the same unknowns with the same
    // solves and iterations and routes the same clay, and the small slab's clay is the large one's
    // voxel for voxel. (Anything the layer did over the whole body, or its bounds, would differ.)
    auto slab = [](int lo, int hi) {
        return R"({"threshold": 1000, "rule": "prorata", "seed": 1, "transport": "global", "push": "surface",
        "clay": [{"shape": "box", "min": [)" +
               std::to_string(lo) + ",0," + std::to_string(lo) + "], \"max\": [" + std::to_string(hi) +
               ",63," + std::to_string(hi) + R"(], "mass": 1000}],
        "tools": [{"shape": "sphere", "center": [36,61,48], "radius": 6, "path": [{"translate": [2,0,0], "frames": 6}]}],
        "settle": {"max_steps": 100000}})";
    };
    Sculptor small(parseScene(slab(0, 95), "s.json", ""), 2),
        large(parseScene(slab(-80, 175), "l.json", ""), 2);
    uint64_t solved = 0;
    while (!small.done()) {
        const FrameReport a = small.runFrame(), b = large.runFrame();
        const std::string at = "frame " + std::to_string(a.frame);
        EXPECT_EQ(a.push.voxelsPushed, b.push.voxelsPushed) << at;
        EXPECT_EQ(a.transport.unknowns, b.transport.unknowns) << at;
        EXPECT_EQ(a.transport.solves, b.transport.solves) << at;
        EXPECT_EQ(a.transport.iterations, b.transport.iterations) << at;
        EXPECT_EQ(a.transport.massMoved, b.transport.massMoved) << at;
        EXPECT_EQ(a.settle.steps, b.settle.steps) << at;
        solved += a.transport.unknowns;
    }
    EXPECT_TRUE(large.done());
    EXPECT_GT(solved, 6u * 8000u); // the layer ran every frame, on ~9 k cells
    // The small slab's clay (all of it within its box and up to 8 voxels above) is the large one's there.
    auto sa = small.mass()->getConstAccessor();
    auto la = large.mass()->getConstAccessor();
    uint64_t differ = 0;
    for (int x = -1; x <= 96; ++x)
        for (int y = 0; y <= 71; ++y)
            for (int z = -1; z <= 96; ++z) {
                const openvdb::Coord c(x, y, z);
                const int32_t expect = (x < 0 || x > 95 || z < 0 || z > 95) ? 0 : la.getValue(c);
                differ += sa.getValue(c) != expect ? 1 : 0;
            }
    EXPECT_EQ(differ, 0u);
    EXPECT_EQ(totalMass(*small.mass()), int64_t(96) * 64 * 96 * 1000);
}

// ---- the flood in batches ------------------------------------------------------------------------

namespace {

/// The domain's arrays as one comparable record (Domain.h: the cells, their links, distances and the
/// faces the flood found).
struct BuiltDomain {
    bool allRoom = false, cut = false;
    std::vector<int32_t> at; // x, y, z per cell
    std::vector<int64_t> m0, dist;
    std::vector<uint8_t> kind, hasNb, face;
    std::vector<int32_t> nb;
};

BuiltDomain buildDomain(const Automaton& a, int64_t reach, uint64_t batchMin, bool serial)
{
    using namespace transport_internal;
    BuiltDomain b;
    DomainArrays arrays;
    Domain domain(a, arrays, true, batchMin, serial);
    std::vector<CellCoord> seeds;
    domain.seeds(Box(), seeds);
    b.allRoom = domain.build(seeds, reach, kInnerMargin, b.cut);
    for (const CellCoord& c : arrays.cells.at)
        b.at.insert(b.at.end(), {c.x, c.y, c.z});
    b.m0 = arrays.cells.m0;
    b.dist = arrays.dist;
    b.kind = arrays.cells.kind;
    b.hasNb = arrays.cells.hasNb;
    b.face = arrays.face;
    b.nb = arrays.cells.nb;
    return b;
}

/// The first index where @a a and @a b differ (the shorter one's size if one is a prefix), or -1.
template <typename T> int64_t firstDifference(const std::vector<T>& a, const std::vector<T>& b)
{
    const auto d = std::mismatch(a.begin(), a.end(), b.begin(), b.end());
    return d.first == a.end() && d.second == b.end() ? -1 : int64_t(d.first - a.begin());
}

} // namespace

TEST_F(TransportTest, TheFloodInBatchesBuildsTheOneByOneFloodsDomainOnAnyThreadCount)
{
    // The flood takes a whole layer at a time once it holds floodBatchMin cells, probing its faces in
    // parallel and adding what they found in the one-by-one flood's order (Domain.h). Its domain must
    // be that flood's exactly: the same cells in the same order, links, distances, faces found, the
    // same answer on room and cut. Batches of every layer (1), of layers of 7 or more, and of none
    // (8192, larger than every layer here), on 1, 2, 3 and 8 threads, over: a plate on a block (layers
    // of 6,144 cells, two chunks), a chain and a lone cell beyond the reach (floods of their own), one
    // over cell inside, a row of them, a 2D slab, random over cells in a block (parts that meet),
    // chambers walled in (no room); each with no reach (the index's tree alone) and with short ones
    // (its dense box, faces cut).
    struct Case {
        const char* name;
        MassGridPtr g;
        openvdb::MaskGrid::Ptr obs;
        int dims;
    };
    std::vector<Case> cases;
    {
        MassGridPtr g = block(box(0, 0, 0, 95, 5, 63), 1000);
        for (int x = 0; x < 96; ++x)
            for (int z = 0; z < 64; ++z)
                g->tree().setValue(openvdb::Coord(x, 5, z), 1000 + (x * 7 + z * 3) % 50);
        openvdb::MaskGrid::Ptr plate = openvdb::MaskGrid::create(false);
        plate->tree().fill(openvdb::CoordBBox(openvdb::Coord(-1, 6, -1), openvdb::Coord(96, 7, 64)), true,
                           true);
        cases.push_back({"plate on a block", g, plate, 3});
    }
    cases.push_back({"chain and lone cell", chainAndLoneCell(), nullptr, 3});
    {
        // One over cell inside: its own flood's layers (1, 6, 18, ... cells) start below 7 and
        // pass it part way through a layer, where a batch must wait for the layer's end.
        MassGridPtr g = block(box(0, 0, 0, 14, 14, 14), 1000);
        g->tree().setValue(openvdb::Coord(7, 7, 7), 1500);
        cases.push_back({"one cell inside", g, nullptr, 3});
    }
    {
        // A row of five over cells inside: its first layers, 5 and then 20 cells, meet along the row,
        // and a batch that took two layers at once would find the second's neighbours too late.
        MassGridPtr g = block(box(0, 0, 0, 14, 14, 14), 1000);
        for (int x = 5; x <= 9; ++x)
            g->tree().setValue(openvdb::Coord(x, 7, 7), 1200);
        cases.push_back({"a row inside", g, nullptr, 3});
    }
    {
        MassGridPtr g = block(box(0, 0, 0, 127, 31, 0), 1000);
        for (int x = 0; x < 128; ++x)
            g->tree().setValue(openvdb::Coord(x, 31, 0), 1000 + x % 13);
        openvdb::MaskGrid::Ptr line = openvdb::MaskGrid::create(false);
        line->tree().fill(openvdb::CoordBBox(openvdb::Coord(-1, 32, 0), openvdb::Coord(128, 32, 0)), true,
                          true);
        cases.push_back({"2D slab", g, line, 2});
    }
    {
        MassGridPtr g = block(box(0, 0, 0, 31, 31, 31), 1000);
        std::mt19937 rng(7);
        for (int k = 0; k < 300; ++k)
            g->tree().setValue(openvdb::Coord(int(rng() % 32), int(rng() % 32), int(rng() % 32)),
                               1000 + 1 + int(rng() % 90));
        cases.push_back({"random over cells", g, nullptr, 3});
    }
    {
        MassGridPtr g;
        openvdb::MaskGrid::Ptr obs;
        walledInChambers(g, obs);
        cases.push_back({"walled in", g, obs, 3});
    }
    for (const Case& c : cases) {
        Automaton a(c.g, opts(c.dims, 1), c.obs);
        for (int64_t reach : {int64_t(0), int64_t(1), int64_t(2)}) {
            const BuiltDomain ref = buildDomain(a, reach, 1, true);
            ASSERT_FALSE(ref.at.empty()) << c.name;
            if (std::string(c.name) == "walled in") {
                EXPECT_FALSE(ref.allRoom);
            }
            if (std::string(c.name) == "plate on a block" && reach == 0) {
                EXPECT_GT(ref.dist.size(), size_t(5 * 6144)); // six layers of 6,144 cells
            }
            for (uint64_t batchMin : {uint64_t(1), uint64_t(7), uint64_t(8192)})
                for (int threads : {1, 2, 3, 8}) {
                    BuiltDomain got;
                    tbb::task_arena arena(threads);
                    arena.execute([&] { got = buildDomain(a, reach, batchMin, false); });
                    const std::string what = std::string(c.name) + ", reach " + std::to_string(reach) +
                                             ", batches of " + std::to_string(batchMin) + ", " +
                                             std::to_string(threads) + " threads";
                    EXPECT_EQ(got.allRoom, ref.allRoom) << what;
                    EXPECT_EQ(got.cut, ref.cut) << what;
                    EXPECT_EQ(firstDifference(got.at, ref.at), -1) << "at, " << what;
                    EXPECT_EQ(firstDifference(got.m0, ref.m0), -1) << "m0, " << what;
                    EXPECT_EQ(firstDifference(got.dist, ref.dist), -1) << "dist, " << what;
                    EXPECT_EQ(firstDifference(got.kind, ref.kind), -1) << "kind, " << what;
                    EXPECT_EQ(firstDifference(got.hasNb, ref.hasNb), -1) << "hasNb, " << what;
                    EXPECT_EQ(firstDifference(got.face, ref.face), -1) << "face, " << what;
                    EXPECT_EQ(firstDifference(got.nb, ref.nb), -1) << "nb, " << what;
                }
        }
    }
}
