// Surface tension (vdbclay/Smooth.h, the "smooth" action): a bumpy sphere (coverage-weighted clay,
// or bumps of full cells), a pressed cube's terraced top and the study scenes smooth-bumps.json and
// smooth-terraces.json lose at least half of the roughness their bumps or terraces add
// (surfaceEnergy over a smooth reference's), keep their mass exactly and their volume within 1 %,
// and a second pass moves less than the first; a flat face does not move;
// nothing changes outside the tool; no clay crosses an obstacle; the same clay on any thread count.
#include <vdbclay/Automaton.h>
#include <vdbclay/Deposit.h>
#include <vdbclay/Metrics.h>
#include <vdbclay/Scene.h>
#include <vdbclay/Sculpt.h>
#include <vdbclay/Shapes.h>
#include <vdbclay/Smooth.h>

#include <openvdb/openvdb.h>

#include "Builders.h"

#include <gtest/gtest.h>

#include <cmath>
#include <cstdint>
#include <string>
#include <vector>

using namespace vdbclay;
using openvdb::Coord;
using vdbclay_test::clayBox;
using vdbclay_test::expectError;

namespace {

class SmoothTest : public ::testing::Test {
protected:
    static void SetUpTestSuite() { openvdb::initialize(); }
};

AutomatonOptions options(int dims = 3)
{
    return vdbclay_test::automatonOptions(Rule::Prorata, 1000, dims, 1);
}

/// Voxels holding at least half of Tc: the clay's volume as its surface encloses it.
uint64_t volume(const MassGrid& g)
{
    uint64_t n = 0;
    for (auto it = g.tree().cbeginValueOn(); it; ++it)
        n += *it >= 500;
    return n;
}

/// A sphere of radius @a radius at the origin (coverage-weighted) with @a bumps balls of radius 1.6
/// on its surface (3D: a Fibonacci lattice of directions; 2D: evenly round the disc), all at Tc 1000.
std::unique_ptr<Automaton> bumpySphere(int bumps, int dims = 3, double radius = 10)
{
    auto a = std::make_unique<Automaton>(openvdb::Int32Grid::create(0), options(dims));
    deposit(*a, *makeSphere({{0, 0, 0}}, radius), 1000);
    const double golden = M_PI * (3.0 - std::sqrt(5.0));
    for (int i = 0; i < bumps; ++i) {
        Vec3 d;
        if (dims == 3) {
            const double y = 1.0 - 2.0 * (i + 0.5) / bumps, r = std::sqrt(1.0 - y * y);
            d = {{r * std::cos(golden * i), y, r * std::sin(golden * i)}};
        } else {
            const double t = 2.0 * M_PI * i / bumps;
            d = {{std::cos(t), std::sin(t), 0}};
        }
        const double r = radius + 0.4;
        deposit(*a, *makeSphere({{r * d[0], r * d[1], r * d[2]}}, 1.6), 1000);
    }
    return a;
}

const Box kAround{{{-16, -16, -16}}, {{16, 16, 16}}};

/// Full cells: Tc 1000 in every voxel whose centre lies inside one of @a balls (centre, radius); a
/// voxel inside two holds Tc once.
std::unique_ptr<Automaton> fullCells(const std::vector<std::pair<Vec3, double>>& balls, int threads)
{
    auto g = openvdb::Int32Grid::create(0);
    auto acc = g->getAccessor();
    for (const auto& [c, r] : balls)
        for (int x = int(std::floor(c[0] - r)); x <= int(std::ceil(c[0] + r)); ++x)
            for (int y = int(std::floor(c[1] - r)); y <= int(std::ceil(c[1] + r)); ++y)
                for (int z = int(std::floor(c[2] - r)); z <= int(std::ceil(c[2] + r)); ++z) {
                    const double dx = x - c[0], dy = y - c[1], dz = z - c[2];
                    if (dx * dx + dy * dy + dz * dz < r * r) acc.setValue(Coord(x, y, z), 1000);
                }
    return std::make_unique<Automaton>(g, vdbclay_test::automatonOptions(Rule::Prorata, 1000, 3, threads));
}

/// A ball of full cells, radius 10, with @a bumps full-cell balls of radius 2.2 centred 10.4 from its
/// centre (a Fibonacci lattice of directions): bumps several voxels wide, as in smooth-bumps.json.
std::unique_ptr<Automaton> fullCellBumpyBall(int bumps, int threads = 1)
{
    std::vector<std::pair<Vec3, double>> balls{{Vec3{{0, 0, 0}}, 10.0}};
    const double golden = M_PI * (3.0 - std::sqrt(5.0));
    for (int i = 0; i < bumps; ++i) {
        const double y = 1.0 - 2.0 * (i + 0.5) / bumps, r = std::sqrt(1.0 - y * y);
        balls.push_back(
            {Vec3{{10.4 * r * std::cos(golden * i), 10.4 * y, 10.4 * r * std::sin(golden * i)}}, 2.2});
    }
    return fullCells(balls, threads);
}

/// The top of a pressed cube: a 32 x 16 x 32 block of full cells whose top (y = 15) a plate has
/// dented 2 deep over [10, 21]^2, the clay it pushed out standing round the dent as terraces (a ring
/// one voxel high over [6, 25]^2, a second over [8, 23]^2). @a terraced false: the plain block.
std::unique_ptr<Automaton> terracedTop(bool terraced, int threads = 1)
{
    auto g = vdbclay_test::clayBox(Coord(0, 0, 0), Coord(31, 15, 31), 1000);
    if (terraced) {
        g->tree().fill(openvdb::CoordBBox(Coord(6, 16, 6), Coord(25, 16, 25)), 1000, true);
        g->tree().fill(openvdb::CoordBBox(Coord(8, 17, 8), Coord(23, 17, 23)), 1000, true);
        g->tree().fill(openvdb::CoordBBox(Coord(10, 14, 10), Coord(21, 17, 21)), 0, false);
        g->tree().voxelizeActiveTiles();
    }
    return std::make_unique<Automaton>(g, vdbclay_test::automatonOptions(Rule::Prorata, 1000, 3, threads));
}

/// Runs @a passes smooth() calls of @a strength with @a tool on @a a and checks what smoothing
/// guarantees: the roughness over @a around (surfaceEnergy) loses at least half of its excess over
/// @a reference's, the mass is exact, the volume within 1 %, no voxel over Tc, the second pass moves
/// less than the first. Returns the clay's contentHash.
uint64_t expectSmoothed(const char* what, Automaton& a, const Automaton& reference, const Shape& tool,
                        const Box& around, int passes, double strength)
{
    const int64_t e0 = surfaceEnergy(*reference.mass(), around, 1000);
    const int64_t e1 = surfaceEnergy(*a.mass(), around, 1000);
    const int64_t mass = a.totalMass();
    const uint64_t vol = volume(*a.mass());
    EXPECT_GT(e1, e0) << what;
    std::vector<int64_t> moved;
    for (int pass = 0; pass < passes; ++pass)
        moved.push_back(smooth(a, tool, strength).massMoved);
    const int64_t e2 = surfaceEnergy(*a.mass(), around, 1000);
    std::printf("%s: roughness %lld -> %lld (smooth reference %lld, %.1f %% of the excess gone); moved", what,
                (long long)e1, (long long)e2, (long long)e0, 100.0 * double(e1 - e2) / double(e1 - e0));
    for (const int64_t m : moved)
        std::printf(" %lld", (long long)m);
    std::printf("; volume %llu -> %llu\n", (unsigned long long)vol, (unsigned long long)volume(*a.mass()));
    EXPECT_LE(e2 - e0, (e1 - e0) / 2) << what;
    EXPECT_EQ(a.totalMass(), mass) << what;
    EXPECT_EQ(totalMass(*a.mass()), mass) << what;
    EXPECT_NEAR(double(volume(*a.mass())), double(vol), 0.01 * double(vol)) << what;
    EXPECT_GT(moved[0], 0) << what;
    EXPECT_LT(moved[1], moved[0]) << what;
    EXPECT_TRUE(vdbclay_test::allClay(*a.mass(), [&](const Coord& c) {
        const int32_t m = a.mass()->tree().getValue(c);
        return m > 0 && m <= 1000;
    })) << what;
    return contentHash(*a.mass());
}

} // namespace

TEST_F(SmoothTest, ABumpySphereLosesHalfItsRoughnessWithMassExactAndVolumeKept)
{
    for (const int dims : {3, 2}) {
        // 3D: radius 10 with 60 bumps; 2D: radius 20 with 32 (about as many voxels on the rim).
        const double radius = dims == 3 ? 10 : 20;
        const Box around = dims == 3 ? kAround : Box{{{-26, -26, 0}}, {{26, 26, 0}}};
        const auto base = bumpySphere(0, dims, radius);
        const int64_t e0 = surfaceEnergy(*base->mass(), around, 1000, dims);
        auto a = bumpySphere(dims == 3 ? 60 : 32, dims, radius);
        const int64_t mass = a->totalMass();
        const uint64_t vol = volume(*a->mass());
        const int64_t e1 = surfaceEnergy(*a->mass(), around, 1000, dims);
        ASSERT_GT(e1, e0);
        const ShapePtr tool = makeSphere({{0, 0, 0}}, radius + 4);
        std::vector<int64_t> moved;
        for (int pass = 0; pass < 8; ++pass)
            moved.push_back(smooth(*a, *tool, 0.5).massMoved);
        const int64_t e2 = surfaceEnergy(*a->mass(), around, 1000, dims);
        std::printf("dims %d: roughness %lld -> %lld (smooth sphere %lld); moved", dims, (long long)e1,
                    (long long)e2, (long long)e0);
        for (const int64_t m : moved)
            std::printf(" %lld", (long long)m);
        std::printf("; volume %llu -> %llu\n", (unsigned long long)vol,
                    (unsigned long long)volume(*a->mass()));
        EXPECT_LE(e2 - e0, (e1 - e0) / 2) << dims;
        EXPECT_EQ(a->totalMass(), mass);
        EXPECT_EQ(totalMass(*a->mass()), mass);
        EXPECT_NEAR(double(volume(*a->mass())), double(vol), 0.01 * double(vol)) << dims;
        EXPECT_GT(moved[0], 0);
        EXPECT_LT(moved[1], moved[0]) << dims;
        EXPECT_LT(moved.back(), moved[0] / 2) << dims;
        // No voxel is left overloaded or negative.
        EXPECT_TRUE(vdbclay_test::allClay(*a->mass(), [&](const Coord& c) {
            const int32_t m = a->mass()->tree().getValue(c);
            return m > 0 && m <= 1000;
        }));
    }
}

TEST_F(SmoothTest, FullCellBumpsLoseHalfTheirRoughnessTheSameOnAnyThreadCount)
{
    // Bumps of full cells several voxels wide: no voxel has room, so clay moves by the threshold
    // step (Smooth.h): the least sheltered surface voxels give to the most sheltered empty ones.
    const auto reference = fullCellBumpyBall(0);
    uint64_t hash0 = 0;
    for (const int threads : {1, 2, 3, 8}) {
        auto a = fullCellBumpyBall(40, threads);
        const uint64_t hash =
            expectSmoothed("full-cell bumps", *a, *reference, *makeSphere({{0, 0, 0}}, 14), kAround, 8, 1.0);
        if (threads == 1) hash0 = hash;
        EXPECT_EQ(hash, hash0) << threads;
    }
}

TEST_F(SmoothTest, APressedCubesTerracedTopLosesHalfItsRoughnessTheSameOnAnyThreadCount)
{
    // A brush (a box over the top, clear of the block's sides) on the dent and terraces.
    const auto reference = terracedTop(false);
    const ShapePtr brush = makeBox({{3, 9, 3}}, {{28, 22, 28}});
    const Box around{{{3, 9, 3}}, {{28, 22, 28}}};
    uint64_t hash0 = 0;
    for (const int threads : {1, 2, 3, 8}) {
        auto a = terracedTop(true, threads);
        const uint64_t hash = expectSmoothed("terraced top", *a, *reference, *brush, around, 8, 1.0);
        if (threads == 1) hash0 = hash;
        EXPECT_EQ(hash, hash0) << threads;
    }
}

TEST_F(SmoothTest, TheSmoothBumpsStudyLosesHalfItsBumpsRoughness)
{
    // data/scenes/studies/smooth-bumps.json: a ball at 0.9 Tc with bumps of full cells under a brush.
    // The roughness over the brush's sweep, with and without the brush, against the ball alone with
    // and without it: at 0.9 Tc the ball's inside counts as rough too and the brush packs its
    // surface layer, so the bumps' excess is the bumpy ball's roughness less the plain ball's under
    // the same brush. It loses 57 % of that excess (the bumps off the sweep's middle are only grazed).
    const Scene scene = vdbclay_test::loadTestScene("studies/smooth-bumps.json");
    Scene unbrushed = scene, plain = scene, plainUnbrushed = scene;
    unbrushed.tools.clear();
    plainUnbrushed.tools.clear();
    plain.clay.resize(1); // the ball alone
    plainUnbrushed.clay.resize(1);
    unbrushed.frames = plainUnbrushed.frames = 26;
    const Box swept{{{-33, 17, -9}}, {{33, 35, 9}}};
    auto roughness = [&](const Scene& s, int threads, uint64_t* hash = nullptr, RunSummary* out = nullptr) {
        Sculptor sc(s, threads);
        const RunSummary r = sc.run();
        if (hash) *hash = contentHash(*sc.mass());
        if (out) *out = r;
        return surfaceEnergy(*sc.mass(), swept, 1000);
    };
    const int64_t e0 = roughness(plainUnbrushed, 2), e1 = roughness(unbrushed, 2), e3 = roughness(plain, 2);
    uint64_t hash0 = 0;
    for (const int threads : {1, 2, 3, 8}) {
        uint64_t hash = 0;
        RunSummary r;
        const int64_t e2 = roughness(scene, threads, &hash, &r);
        EXPECT_EQ(r.massDrift, 0);
        EXPECT_EQ(r.massFinal, r.massInitial);
        if (threads == 1) {
            std::printf("smooth-bumps.json over the brush's sweep: roughness %lld unbrushed, %lld brushed "
                        "(%.1f %% less); the ball alone %lld unbrushed, %lld brushed; the bumps' excess "
                        "%lld -> %lld (%.1f %% gone)\n",
                        (long long)e1, (long long)e2, 100.0 * double(e1 - e2) / double(e1), (long long)e0,
                        (long long)e3, (long long)(e1 - e0), (long long)(e2 - e3),
                        100.0 * (1.0 - double(e2 - e3) / double(e1 - e0)));
            EXPECT_LE(e2 - e3, (e1 - e0) / 2);
            hash0 = hash;
        }
        EXPECT_EQ(hash, hash0) << threads;
    }
}

TEST_F(SmoothTest, TheSmoothTerracesStudyLosesHalfItsRoughness)
{
    // data/scenes/studies/smooth-terraces.json: a block at Tc pressed by a small plate, then a brush
    // over the dent and its terraces. The roughness over the brush's sweep, against the scene
    // without the brush and the block never pressed (the smooth reference).
    const Scene scene = vdbclay_test::loadTestScene("studies/smooth-terraces.json");
    Scene unbrushed = scene, plain = scene;
    unbrushed.tools.resize(1); // the plate
    plain.tools.clear();
    unbrushed.frames = plain.frames = 32;
    const Box swept{{{-19, 8, 7}}, {{51, 26, 25}}};
    auto roughness = [&](const Scene& s, int threads, uint64_t* hash = nullptr) {
        Sculptor sc(s, threads);
        const RunSummary r = sc.run();
        EXPECT_EQ(r.massDrift, 0);
        EXPECT_EQ(r.massFinal, r.massInitial);
        if (hash) *hash = contentHash(*sc.mass());
        return surfaceEnergy(*sc.mass(), swept, 1000);
    };
    const int64_t e0 = roughness(plain, 2), e1 = roughness(unbrushed, 2);
    uint64_t hash0 = 0;
    for (const int threads : {1, 2, 3, 8}) {
        uint64_t hash = 0;
        const int64_t e2 = roughness(scene, threads, &hash);
        if (threads == 1) {
            std::printf(
                "smooth-terraces.json over the brush's sweep: roughness %lld unbrushed, %lld brushed, "
                "%lld never pressed (%.1f %% of the excess gone)\n",
                (long long)e1, (long long)e2, (long long)e0, 100.0 * double(e1 - e2) / double(e1 - e0));
            EXPECT_LE(e2 - e0, (e1 - e0) / 2);
            hash0 = hash;
        }
        EXPECT_EQ(hash, hash0) << threads;
    }
}

TEST_F(SmoothTest, AFlatFaceDoesNotMove)
{
    auto a = std::make_unique<Automaton>(clayBox(Coord(-20, -20, -20), Coord(20, 0, 20), 1000), options());
    const SmoothReport r = smooth(*a, *makeSphere({{0, 0, 0}}, 8.0), 1.0, 3);
    EXPECT_EQ(r.massMoved, 0);
    EXPECT_EQ(r.voxels, 0u);
    EXPECT_TRUE(r.region.empty());
}

TEST_F(SmoothTest, NothingChangesOutsideTheToolAndNoClayCrossesAnObstacle)
{
    // A wall through the bumpy sphere's middle (x = 0): the clay on either side keeps its mass.
    auto wall = openvdb::MaskGrid::create(false);
    auto a0 = bumpySphere(60);
    auto clay = a0->mass()->deepCopy();
    auto acc0 = clay->getAccessor();
    for (int y = -20; y <= 20; ++y)
        for (int z = -20; z <= 20; ++z) {
            wall->tree().setValueOn(Coord(0, y, z));
            acc0.setValueOff(Coord(0, y, z), 0);
        }
    Automaton a(clay, options(), wall);
    auto sideMass = [&](int sign) {
        int64_t m = 0;
        for (auto it = a.mass()->tree().cbeginValueOn(); it; ++it)
            if ((it.getCoord().x() > 0) == (sign > 0) && it.getCoord().x() != 0) m += *it;
        return m;
    };
    const int64_t left = sideMass(-1), right = sideMass(1);
    const auto before = a.mass()->deepCopy();
    // A tool over the upper part only.
    const ShapePtr tool = makeSphere({{0, 9, 0}}, 7.5);
    int64_t moved = 0;
    for (int i = 0; i < 4; ++i)
        moved += smooth(a, *tool, 1.0).massMoved;
    EXPECT_GT(moved, 0);
    EXPECT_EQ(sideMass(-1), left);
    EXPECT_EQ(sideMass(1), right);
    auto acc = a.mass()->getConstAccessor();
    auto old = before->getConstAccessor();
    uint64_t changed = 0;
    for (int x = -16; x <= 16; ++x)
        for (int y = -16; y <= 16; ++y)
            for (int z = -16; z <= 16; ++z) {
                const Coord c(x, y, z);
                if (acc.getValue(c) == old.getValue(c)) continue;
                ++changed;
                ASSERT_LT(tool->distance(Vec3{{double(x), double(y), double(z)}}), 0)
                    << x << " " << y << " " << z;
                ASSERT_NE(x, 0);
            }
    EXPECT_GT(changed, 0u);
}

TEST_F(SmoothTest, BadStrengthOrPassesAreRefused)
{
    Automaton a(clayBox(Coord(0, 0, 0), Coord(3, 3, 3), 1000), options());
    const ShapePtr tool = makeSphere({{0, 0, 0}}, 3.0);
    expectError([&] { smooth(a, *tool, 0.0); }, "smooth: the strength must lie in (0, 1]");
    expectError([&] { smooth(a, *tool, 1.5); }, "smooth: the strength must lie in (0, 1]");
    expectError([&] { smooth(a, *tool, 0.5, 0); }, "smooth: passes must be >= 1");
}

TEST_F(SmoothTest, ASmoothToolInASceneIsTheSameOnAnyThreadCount)
{
    // A pressed cube's terraced top, then a smooth brush sweeping across it.
    const Scene s = parseScene(R"({"threshold": 1000, "rule": "prorata",
        "clay": [{"shape": "box", "min": [0,0,0], "max": [15,15,15], "mass": 900}],
        "tools": [{"shape": "sphere", "center": [8,18,8], "radius": 3, "path": [{"translate": [0,-0.5,0], "frames": 6}]},
                  {"shape": "sphere", "center": [-2,15,8], "radius": 5, "action": "smooth", "strength": 1,
                   "path": [{"translate": [1.5,0,0], "frames": 14}]}],
        "obstacles": [{"shape": "box", "min": [-20,-4,-20], "max": [40,-1,40]}],
        "settle": {"max_steps": 300}})",
                               "s.json", "");
    uint64_t hash0 = 0;
    int64_t smoothed0 = 0;
    for (const int threads : {1, 2, 3, 8}) {
        Sculptor sc(s, threads);
        int64_t smoothed = 0;
        const RunSummary r = sc.run(0, [&](const FrameReport& f) { smoothed += f.massSmoothed; });
        EXPECT_EQ(r.massDrift, 0);
        EXPECT_EQ(r.massAdded, 0);
        EXPECT_EQ(r.massFinal, r.massInitial);
        EXPECT_GT(smoothed, 0);
        if (threads == 1) {
            hash0 = contentHash(*sc.mass());
            smoothed0 = smoothed;
        } else {
            EXPECT_EQ(contentHash(*sc.mass()), hash0) << threads;
            EXPECT_EQ(smoothed, smoothed0) << threads;
        }
    }
}

TEST_F(SmoothTest, SurfaceTensionSmoothsTheDentAndKeepsMassExact)
{
    // A ball poked by a small sphere: with "surface_tension" the clay round the dent is smoother
    // (a lower surfaceEnergy near the tool), the mass exact, the clay the same on any thread count
    // (tests/TestSurfaceTension.cc: which surface it smooths, resuming, its work).
    const std::string body = R"("threshold": 1000, "rule": "prorata",
        "clay": [{"shape": "sphere", "center": [0,0,0], "radius": 12, "mass": 1000}],
        "tools": [{"shape": "sphere", "center": [0,15,0], "radius": 3.5, "path": [{"translate": [0,-1,0], "frames": 6}]}],
        "settle": {"max_steps": 3000})";
    const Scene off = parseScene("{" + body + "}", "s.json", "");
    EXPECT_EQ(off.surfaceTension, 0.0);
    const Scene on = parseScene("{\"surface_tension\": 0.5, " + body + "}", "s.json", "");
    EXPECT_EQ(on.surfaceTension, 0.5);
    expectError([] { parseScene(R"({"surface_tension": 1.5})", "s.json", ""); },
                "s.json: surface_tension: must lie in [0, 1] (0: off), got 1.5");
    expectError([] { parseScene(R"({"surface_tension": true})", "s.json", ""); },
                "s.json: surface_tension: expected a number");
    Sculptor a(off, 2);
    const RunSummary ra = a.run();
    uint64_t hash = 0;
    int64_t smoothed0 = 0;
    for (const int threads : {1, 2, 3, 8}) {
        Sculptor b(on, threads);
        int64_t smoothed = 0;
        const RunSummary rb = b.run(0, [&](const FrameReport& f) { smoothed += f.massSmoothed; });
        EXPECT_EQ(rb.massDrift, 0);
        EXPECT_EQ(rb.massFinal, ra.massFinal);
        EXPECT_GT(smoothed, 0);
        const Box near{{{-8, 2, -8}}, {{8, 16, 8}}};
        EXPECT_LT(surfaceEnergy(*b.mass(), near, 1000), surfaceEnergy(*a.mass(), near, 1000));
        if (threads == 1) {
            hash = contentHash(*b.mass());
            smoothed0 = smoothed;
        } else {
            EXPECT_EQ(contentHash(*b.mass()), hash) << threads;
            EXPECT_EQ(smoothed, smoothed0) << threads;
        }
    }
}

TEST_F(SmoothTest, SmoothRegionChangesOnlyItsRegion)
{
    auto a = bumpySphere(60);
    const auto before = a->mass()->deepCopy();
    const int64_t mass = a->totalMass();
    const Box region{{{-16, 3, -16}}, {{16, 16, 16}}}; // the upper part
    const int64_t e0 = surfaceEnergy(*a->mass(), kAround, 1000);
    int64_t moved = 0;
    for (int i = 0; i < 4; ++i)
        moved += smoothRegion(*a, region, 0.5).massMoved;
    EXPECT_GT(moved, 0);
    EXPECT_EQ(a->totalMass(), mass);
    EXPECT_LT(surfaceEnergy(*a->mass(), kAround, 1000), e0);
    auto acc = a->mass()->getConstAccessor();
    auto old = before->getConstAccessor();
    for (int x = -16; x <= 16; ++x)
        for (int y = -16; y <= 2; ++y)
            for (int z = -16; z <= 16; ++z)
                ASSERT_EQ(acc.getValue(Coord(x, y, z)), old.getValue(Coord(x, y, z)))
                    << x << " " << y << " " << z;
}
