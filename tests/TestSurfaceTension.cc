// The scene's surface tension (lib/src/sculpt/SurfaceTension.h, "surface_tension"): the automaton
// records every voxel whose clay changes (automaton/ChangedClay.h); the first frame smooths the whole
// surface, bumps far from any tool included; later frames smooth only the surface that changed, so
// clay at rest is left as it is and the work follows the surface, not the volume; the mass is exact,
// obstacles hold no clay, the clay is the same on 1, 2, 3 and 8 threads in 2D and 3D, and a run
// stopped inside its frames and resumed from its checkpoints ends as the unbroken one.
#include <vdbclay/Automaton.h>
#include <vdbclay/IO.h>
#include <vdbclay/MemoryEstimate.h>
#include <vdbclay/Metrics.h>
#include <vdbclay/Scene.h>
#include <vdbclay/Sculpt.h>
#include <vdbclay/Smooth.h>

#include "automaton/AutomatonInternal.h"
#include "automaton/ChangedClay.h"
#include "sculpt/MemoryEstimate.h"
#include "sculpt/SurfaceTension.h"

#include <openvdb/openvdb.h>

#include "Builders.h"

#include <gtest/gtest.h>

#include <unistd.h>

#include <algorithm>
#include <array>
#include <cstdio>
#include <string>
#include <vector>

using namespace vdbclay;
using automaton_internal::ChangedClay;
using openvdb::Coord;

namespace {

class SurfaceTensionTest : public ::testing::Test {
protected:
    static void SetUpTestSuite() { openvdb::initialize(); }
};

Scene scene(const std::string& json)
{
    return parseScene(json, "s.json", "");
}

/// Whether voxel @a c lies in the box of its slot's entry in @a entries (compacted).
bool recorded(const std::vector<ChangedClay::Entry>& entries, const Coord& c)
{
    for (const ChangedClay::Entry& e : entries) {
        if (e.slot[0] != (c.x() >> 3) || e.slot[1] != (c.y() >> 3) || e.slot[2] != (c.z() >> 3)) continue;
        const Box& b = e.voxels;
        return c.x() >= b.min[0] && c.x() <= b.max[0] && c.y() >= b.min[1] && c.y() <= b.max[1] &&
               c.z() >= b.min[2] && c.z() <= b.max[2];
    }
    return false;
}

/// Every voxel where @a a and @a b differ (either grid's active voxels and tiles).
std::vector<Coord> differences(const MassGrid& a, const MassGrid& b)
{
    std::vector<Coord> out;
    auto ba = b.getConstAccessor(), aa = a.getConstAccessor();
    for (const MassGrid* g : {&a, &b})
        for (auto it = g->cbeginValueOn(); it; ++it) {
            openvdb::CoordBBox bb;
            it.getBoundingBox(bb);
            for (auto c = bb.begin(); c; ++c)
                if (aa.getValue(*c) != ba.getValue(*c)) out.push_back(*c);
        }
    return out;
}

} // namespace

TEST_F(SurfaceTensionTest, TheAutomatonRecordsEveryVoxelItsStepsAndEditsChange)
{
    for (const int dims : {2, 3}) {
        auto g = vdbclay_test::clayBox(Coord(0, 0, 0), Coord(9, 9, dims == 2 ? 0 : 9), 400);
        Automaton a(g, vdbclay_test::automatonOptions(Rule::Prorata, 100, dims, 2));
        ChangedClay changed;
        automaton_internal::setChangedClay(a, &changed);
        auto before = g->deepCopy();
        a.run(7);
        std::vector<Coord> diff = differences(*before, *g);
        ASSERT_FALSE(diff.empty());
        std::vector<ChangedClay::Entry> e = changed.entries();
        for (const Coord& c : diff)
            EXPECT_TRUE(recorded(e, c)) << dims << "D step: " << c;
        // One entry a slot, in slot order, each box inside its slot.
        for (size_t i = 0; i < e.size(); ++i) {
            if (i > 0) {
                EXPECT_LT(e[i - 1].slot, e[i].slot);
            }
            for (int k = 0; k < 3; ++k) {
                EXPECT_EQ(e[i].voxels.min[size_t(k)] >> 3, e[i].slot[size_t(k)]);
                EXPECT_EQ(e[i].voxels.max[size_t(k)] >> 3, e[i].slot[size_t(k)]);
            }
        }
        // setMasses records its cells, edit its region's leaves.
        changed.clear();
        a.setMasses(Box{{{40, 3, 0}}, {{40, 3, 0}}}, {Automaton::CellMass{{{40, 3, 0}}, 7}});
        a.edit(Box{{{-20, 0, 0}}, {{-18, 1, 0}}},
               [](MassGrid& m) { m.tree().setValueOn(Coord(-19, 1, 0), 5); });
        e = changed.entries();
        EXPECT_TRUE(recorded(e, Coord(40, 3, 0)));
        EXPECT_TRUE(recorded(e, Coord(-19, 1, 0)));
        EXPECT_FALSE(recorded(e, Coord(0, 0, 0)));
        automaton_internal::setChangedClay(a, nullptr);
        a.run(4);
        EXPECT_EQ(changed.entries().size(), e.size());
    }
}

namespace {

/// A ball of clay at 0.9 Tc (radius 12 at the origin, Tc 1000: room everywhere, so a poke's clay
/// settles near it) with bumps of full cells (3^3 boxes) at +x, -x, -z and the bottom, and (@a tool)
/// a small sphere tool poking the top.
std::string bumpyBall(double tension, bool tool, int frames = 4)
{
    std::string s = R"({"threshold": 1000, "rule": "prorata", "frames": )" + std::to_string(frames) + ",";
    if (tension > 0) s += "\"surface_tension\": " + std::to_string(tension) + ",";
    s += R"("clay": [{"shape": "sphere", "center": [0,0,0], "radius": 12, "mass": 900},
                     {"shape": "box", "min": [12,-1,-1], "max": [14,1,1], "mass": 1000},
                     {"shape": "box", "min": [-14,-1,-1], "max": [-12,1,1], "mass": 1000},
                     {"shape": "box", "min": [-1,-1,-14], "max": [1,1,-12], "mass": 1000},
                     {"shape": "box", "min": [-1,-14,-1], "max": [1,-12,1], "mass": 1000}])";
    if (tool)
        s += R"(, "tools": [{"shape": "sphere", "center": [0,17,0], "radius": 3,
                "path": [{"translate": [0,-1,0], "frames": )" +
             std::to_string(frames) + "}]}]";
    return s + "}";
}

const Box kBumpX{{{8, -6, -6}}, {{18, 6, 6}}};        // around the +x bump
const Box kBumpBottom{{{-6, -18, -6}}, {{6, -8, 6}}}; // around the bottom's, far from the tool

} // namespace

TEST_F(SurfaceTensionTest, TheFirstFrameSmoothsTheWholeSurfaceAndClayAtRestIsLeftAsItIs)
{
    // No tool: frame 1 smooths the bumps (a lower roughness round each, the mass exact); frames 2
    // and 3 change nothing, so nothing is smoothed again and the clay stays as frame 1 left it.
    Sculptor off(scene(bumpyBall(0, false, 3)), 2);
    off.run();
    Sculptor on(scene(bumpyBall(0.5, false, 3)), 2);
    const int64_t mass0 = on.automaton().totalMass();
    std::vector<FrameReport> frames;
    on.run(1, [&](const FrameReport& f) { frames.push_back(f); });
    ASSERT_EQ(frames.size(), 1u);
    EXPECT_GT(frames[0].massSmoothed, 0);
    EXPECT_GT(frames[0].tensionBoxes, 0u);
    EXPECT_EQ(on.automaton().totalMass(), mass0);
    EXPECT_LT(surfaceEnergy(*on.mass(), kBumpX, 1000), surfaceEnergy(*off.mass(), kBumpX, 1000));
    const Box bumpZ{{{-6, -6, -18}}, {{6, 6, -8}}};
    EXPECT_LT(surfaceEnergy(*on.mass(), bumpZ, 1000), surfaceEnergy(*off.mass(), bumpZ, 1000));
    const uint64_t hash1 = contentHash(*on.mass());
    on.run(0, [&](const FrameReport& f) { frames.push_back(f); });
    ASSERT_EQ(frames.size(), 3u);
    for (size_t i = 1; i < 3; ++i) {
        EXPECT_EQ(frames[i].massSmoothed, 0);
        EXPECT_EQ(frames[i].tensionVoxels, 0u);
    }
    EXPECT_EQ(contentHash(*on.mass()), hash1);
    EXPECT_EQ(on.automaton().totalMass(), mass0);
}

TEST_F(SurfaceTensionTest, LaterFramesSmoothWhereTheToolChangedTheClayOnly)
{
    // The tool pokes the top from frame 1 on: the bump at the bottom, smoothed in frame 1, does not
    // change after it; round the dent the clay is smoother than without surface tension.
    const Scene s = scene(bumpyBall(0.5, true, 5));
    Sculptor sc(s, 2);
    sc.run(1);
    auto after1 = sc.mass()->deepCopy();
    uint64_t later = 0, boxes = 0;
    int64_t smoothed = 0;
    const RunSummary r = sc.run(0, [&](const FrameReport& f) {
        later += f.tensionVoxels;
        boxes += f.tensionBoxes;
        smoothed += f.massSmoothed;
    });
    EXPECT_EQ(r.massDrift, 0);
    EXPECT_GT(later, 0u);
    EXPECT_GT(smoothed, 0);
    // The run's summary (the --stats file's mass_smoothed, tension_boxes, tension_voxels) sums its frames.
    EXPECT_EQ(r.massSmoothed, smoothed);
    EXPECT_EQ(r.tensionBoxes, boxes);
    EXPECT_EQ(r.tensionVoxels, later);
    auto now = sc.mass()->getConstAccessor();
    auto then = after1->getConstAccessor();
    const Box& b = kBumpBottom;
    for (int x = b.min[0]; x <= b.max[0]; ++x)
        for (int y = b.min[1]; y <= b.max[1]; ++y)
            for (int z = b.min[2]; z <= b.max[2]; ++z)
                ASSERT_EQ(now.getValue(Coord(x, y, z)), then.getValue(Coord(x, y, z)))
                    << x << " " << y << " " << z;
    Sculptor off(scene(bumpyBall(0, true, 5)), 2);
    off.run();
    const Box near{{{-8, 2, -8}}, {{8, 16, 8}}};
    EXPECT_LT(surfaceEnergy(*sc.mass(), near, 1000), surfaceEnergy(*off.mass(), near, 1000));
}

TEST_F(SurfaceTensionTest, TheWorkFollowsTheSurfaceNotTheVolume)
{
    // Balls at 0.9 Tc (tiles inside) of radius 64 and 128: the first frame reads about 4 times
    // more voxels for twice the radius (the surface), not 8 (the volume); a later frame's poke reads
    // about as much on each, a small part of the first frame's.
    std::vector<uint64_t> first, later;
    for (const int r : {64, 128}) {
        const std::string json = R"({"threshold": 1000, "surface_tension": 0.5, "frames": 3,
            "clay": [{"shape": "sphere", "center": [0,0,0], "radius": )" +
                                 std::to_string(r) + R"(, "mass": 900}],
            "tools": [{"shape": "sphere", "center": [0,)" +
                                 std::to_string(r + 4) +
                                 R"(,0], "radius": 3, "path": [{"translate": [0,-1,0], "frames": 3}]}]})";
        Sculptor sc(scene(json), 2);
        std::vector<uint64_t> v;
        sc.run(0, [&](const FrameReport& f) { v.push_back(f.tensionVoxels); });
        ASSERT_EQ(v.size(), 3u);
        first.push_back(v[0]);
        later.push_back(v[2]);
        std::printf("radius %d: frame 1 reads %llu voxels, frame 3 %llu\n", r, (unsigned long long)v[0],
                    (unsigned long long)v[2]);
    }
    for (size_t i = 1; i < first.size(); ++i) {
        EXPECT_LT(double(first[i]), 6.0 * double(first[i - 1])) << i;
        EXPECT_GT(double(first[i]), 2.5 * double(first[i - 1])) << i;
        EXPECT_GT(later[i], 0u);
        EXPECT_LT(double(later[i]), 2.0 * double(later[0])) << i;
    }
    EXPECT_LT(20 * later[1], first[1]);
}

TEST_F(SurfaceTensionTest, TheSameClayOnAnyThreadCountIn2DAnd3DWithObstaclesUntouched)
{
    const std::vector<std::string> scenes = {
        bumpyBall(0.7, true, 5),
        R"({"dimensions": 2, "threshold": 1000, "surface_tension": 1, "frames": 6,
            "clay": [{"shape": "sphere", "center": [0,0], "radius": 20, "mass": 950},
                     {"shape": "sphere", "center": [20.5,0], "radius": 2.5, "mass": 1000}],
            "obstacles": [{"shape": "box", "min": [-30,-30], "max": [30,-21]}],
            "tools": [{"shape": "sphere", "center": [0,26], "radius": 4, "path": [{"translate": [1,-1], "frames": 6}]}]})",
        R"({"threshold": 1000, "surface_tension": 1, "frames": 4,
            "clay": [{"shape": "box", "min": [0,0,0], "max": [23,15,23], "mass": 1000}],
            "obstacles": [{"shape": "box", "min": [-8,-4,-8], "max": [31,-1,31]},
                          {"shape": "box", "min": [24,0,4], "max": [26,10,19]}],
            "tools": [{"shape": "box", "min": [4,14,4], "max": [12,20,12], "path": [{"translate": [0,-1,0], "frames": 4}]}]})",
    };
    for (const std::string& json : scenes) {
        const Scene s = scene(json);
        uint64_t hash = 0;
        int64_t smoothed0 = 0;
        for (const int threads : {1, 2, 3, 8}) {
            Sculptor sc(s, threads);
            int64_t smoothed = 0;
            const RunSummary r = sc.run(0, [&](const FrameReport& f) { smoothed += f.massSmoothed; });
            EXPECT_EQ(r.massDrift, 0) << json;
            EXPECT_EQ(r.massFinal, r.massInitial) << json;
            EXPECT_GT(smoothed, 0) << json;
            if (threads == 1) {
                hash = contentHash(*sc.mass());
                smoothed0 = smoothed;
            } else {
                EXPECT_EQ(contentHash(*sc.mass()), hash) << threads << " threads: " << json;
                EXPECT_EQ(smoothed, smoothed0) << threads << " threads: " << json;
            }
            // No clay in a static obstacle.
            for (const ShapeSpec& o : s.obstacles) {
                const Box b = o.shape->bounds();
                auto acc = sc.mass()->getConstAccessor();
                for (int x = b.min[0]; x <= b.max[0]; ++x)
                    for (int y = b.min[1]; y <= b.max[1]; ++y)
                        for (int z = (s.dimensions == 2 ? 0 : b.min[2]);
                             z <= (s.dimensions == 2 ? 0 : b.max[2]); ++z)
                            if (o.shape->distance(Vec3{{double(x), double(y), double(z)}}) < 0) {
                                ASSERT_EQ(acc.getValue(Coord(x, y, z)), 0) << x << " " << y << " " << z;
                            }
            }
        }
    }
}

namespace {

/// Runs @a s, stopping whenever another @a every steps have run: writes the checkpoint and goes on
/// in a new Sculptor started from it, on 3 then 1 thread. Returns the final hash; counts the
/// checkpoints written inside a frame, and those carrying the frame's changed clay.
uint64_t interrupted(Scene s, uint64_t every, const std::string& file, int& midFrame, int& withChanges)
{
    for (int n = 0; n < 10000; ++n) {
        Sculptor sc(s, n % 2 ? 1 : 3);
        const uint64_t stopAt = sc.automaton().stepCount() + every;
        sc.setStopRequest([&sc, stopAt] { return sc.automaton().stepCount() >= stopAt; });
        sc.run();
        if (!sc.stopped()) return contentHash(*sc.mass());
        const ClayMeta m = sc.checkpointMeta();
        writeClayFile(file, *sc.mass(), m);
        const ClayMeta back = readClayFile(file).meta;
        EXPECT_EQ(back.changedClay.size(), m.changedClay.size());
        midFrame += m.frameSteps > 0;
        withChanges += !back.changedClay.empty();
        s.start = file;
    }
    ADD_FAILURE() << "no end";
    return 0;
}

} // namespace

TEST_F(SurfaceTensionTest, ARunResumedFromItsCheckpointsEndsAsTheUnbrokenOne)
{
    const std::string ckpt =
        (::access("/dev/shm", W_OK) == 0 ? std::string("/dev/shm") : std::string("/tmp")) +
        "/vdbclay-test-tension-" + std::to_string(::getpid()) + ".vdb";
    const std::vector<std::string> scenes = {
        R"({"threshold": 100, "seed": 5, "surface_tension": 0.8,
            "clay":  [{"shape": "box", "min": [0,0,0], "max": [11,11,11], "mass": 95},
                      {"shape": "sphere", "center": [12,6,6], "radius": 1.5, "mass": 100}],
            "tools": [{"shape": "sphere", "center": [6,16,6], "radius": 4, "path": [{"translate": [0,-1,0], "frames": 6}]}],
            "obstacles": [{"shape": "box", "min": [-20,-3,-20], "max": [30,-1,30]}],
            "settle": {"max_steps": 30}})",
        R"({"dimensions": 2, "threshold": 100, "surface_tension": 1,
            "clay":  [{"shape": "box", "min": [0,0], "max": [15,15], "mass": 90}],
            "tools": [{"shape": "box", "min": [-4,16], "max": [19,18], "path": [{"translate": [0,-1], "frames": 5}]}],
            "obstacles": [{"shape": "box", "min": [-30,-3], "max": [40,-1]}]})",
    };
    for (const std::string& json : scenes) {
        const Scene s = scene(json);
        Sculptor whole(s, 2);
        whole.run();
        const uint64_t hash = contentHash(*whole.mass());
        for (const uint64_t every : {1, 9, 31}) {
            int midFrame = 0, withChanges = 0;
            EXPECT_EQ(interrupted(s, every, ckpt, midFrame, withChanges), hash) << every << ": " << json;
            EXPECT_GT(midFrame, 0) << every;
            EXPECT_GT(withChanges, 0) << every;
        }
    }
    std::remove(ckpt.c_str());
}

TEST_F(SurfaceTensionTest, EachBoxFitsTheMemoryEstimatesBlock)
{
    // Slots of a sphere's shell, of a plane and of a solid block: every box, grown by the shelters'
    // reach, holds at most tensionBlockVoxels, and the boxes cover every recorded voxel.
    for (const int dims : {2, 3}) {
        ChangedClay c;
        for (int x = -40; x <= 40; ++x)
            for (int y = -40; y <= 40; ++y)
                for (int z = (dims == 2 ? 0 : -40); z <= (dims == 2 ? 0 : 40); ++z) {
                    const int rr = x * x + y * y + z * z;
                    if ((rr >= 30 * 30 && rr <= 32 * 32) || y == 37 || (x > 20 && y > 20 && z > 20))
                        c.addVoxel(x, y, z);
                }
        const std::vector<ChangedClay::Entry> e = c.entries();
        const std::vector<Box> boxes = sculpt_internal::tensionBoxes(e, dims, kSurfaceTensionMargin);
        ASSERT_FALSE(boxes.empty());
        for (const Box& b : boxes) {
            uint64_t v = 1;
            for (int a = 0; a < dims; ++a)
                v *= uint64_t(b.max[size_t(a)] - b.min[size_t(a)] + 1 + 4);
            EXPECT_LE(v, sculpt_internal::tensionBlockVoxels(dims));
        }
        for (const ChangedClay::Entry& en : e) {
            bool in = false;
            for (const Box& b : boxes)
                in = in || (intersect(b, en.voxels).min == en.voxels.min &&
                            intersect(b, en.voxels).max == en.voxels.max);
            EXPECT_TRUE(in);
        }
    }
    // The estimate counts the journal and a block a thread when the scene has surface tension.
    const std::string body =
        R"("clay": [{"shape": "sphere", "center": [0,0,0], "radius": 40, "mass": 1000}]})";
    const MemoryEstimate off = estimateSceneMemory(scene("{" + body));
    const MemoryEstimate on = estimateSceneMemory(scene("{\"surface_tension\": 0.5, " + body));
    EXPECT_GE(on.pushBytes - off.pushBytes,
              uint64_t(sculpt_internal::tensionLanes(0)) * sculpt_internal::tensionBlockVoxels(3) *
                      memory_internal::kSmoothBytesPerVoxel +
                  2 * on.clayLeavesGrown * memory_internal::kChangedClayBytesPerSlot);
}

namespace {

/// A ball of clay at 0.9 Tc of radius 40 with bumps of full cells (5^3 boxes) on every side, and a
/// sphere tool poking the top from frame 1 on: the first frame smooths a surface of many boxes on
/// several levels, the later frames the surface round the tool.
std::string bigBumpyBall(int frames)
{
    std::string s = R"({"threshold": 1000, "rule": "prorata", "surface_tension": 0.6, "frames": )" +
                    std::to_string(frames) + R"(,
        "clay": [{"shape": "sphere", "center": [0,0,0], "radius": 40, "mass": 900})";
    for (const int a : {0, 1, 2})
        for (const int sign : {-1, 1})
            for (const int off : {-20, 0, 20}) {
                std::array<int, 3> c{{off, -off, off / 2}};
                c[size_t(a)] = sign * 40;
                const int lo = -2, hi = 2;
                s += R"(, {"shape": "box", "min": [)" + std::to_string(c[0] + lo) + "," +
                     std::to_string(c[1] + lo) + "," + std::to_string(c[2] + lo) + R"(], "max": [)" +
                     std::to_string(c[0] + hi) + "," + std::to_string(c[1] + hi) + "," +
                     std::to_string(c[2] + hi) + R"(], "mass": 1000})";
            }
    s += R"(], "tools": [{"shape": "sphere", "center": [3,46,-2], "radius": 5,
                "path": [{"translate": [0,-2,0], "frames": )" +
         std::to_string(frames) + "}]}]}";
    return s;
}

} // namespace

TEST_F(SurfaceTensionTest, TheBoxesOfALevelMeetNoEarlierBoxOfItsOwnOrAHigherLevel)
{
    // The whole surface of the big bumpy ball: its boxes fall on many levels, many of several
    // boxes, and a box whose reads (the box grown by the shelters' reach) meet an earlier box lies on
    // a higher level than it.
    Sculptor sc(scene(bigBumpyBall(1)), 1);
    ChangedClay c;
    sculpt_internal::addWholeSurface(*sc.mass(), 3, c);
    const std::vector<Box> boxes = sculpt_internal::tensionBoxes(c.entries(), 3, kSurfaceTensionMargin);
    const std::vector<uint32_t> level = sculpt_internal::tensionLevels(boxes, 3);
    ASSERT_EQ(level.size(), boxes.size());
    const uint32_t levels = 1 + *std::max_element(level.begin(), level.end());
    std::vector<size_t> per(levels, 0);
    for (const uint32_t l : level)
        ++per[l];
    size_t several = 0;
    for (const size_t n : per)
        several += n > 1;
    // 161 boxes on 91 levels, 58 of them of 2 or 3 boxes.
    EXPECT_GT(levels, 1u);
    EXPECT_GE(several, 20u);
    for (size_t i = 0; i < boxes.size(); ++i) {
        Box reads = boxes[i];
        for (size_t a = 0; a < 3; ++a) {
            reads.min[a] -= 2;
            reads.max[a] += 2;
        }
        for (size_t j = 0; j < i; ++j)
            if (!intersect(reads, boxes[j]).empty()) {
                ASSERT_LT(level[j], level[i]) << j << " " << i;
            }
    }
}

TEST_F(SurfaceTensionTest, TheBoxesSmoothedLevelByLevelGiveWhatTheyGiveOneAfterTheOther)
{
    // smoothBoxes over the whole surface of the big bumpy ball on 1, 2, 3 and 8 threads: the clay,
    // the report and the changed clay recorded are those of smoothRegion over each box in turn.
    const Scene s = scene(bigBumpyBall(1));
    uint64_t hash = 0;
    int64_t moved = 0;
    uint64_t visited = 0;
    std::vector<Box> boxes;
    std::vector<ChangedClay::Entry> recordedSerially;
    {
        Sculptor sc(s, 1);
        ChangedClay surface;
        sculpt_internal::addWholeSurface(*sc.mass(), 3, surface);
        boxes = sculpt_internal::tensionBoxes(surface.entries(), 3, kSurfaceTensionMargin);
        ChangedClay changed;
        automaton_internal::setChangedClay(sc.automaton(), &changed);
        for (const Box& b : boxes) {
            const SmoothReport r = smoothRegion(sc.automaton(), b, 0.6, 1, {});
            moved += r.massMoved;
            visited += r.visited;
        }
        automaton_internal::setChangedClay(sc.automaton(), nullptr);
        hash = contentHash(*sc.mass());
        recordedSerially = changed.entries();
    }
    EXPECT_GT(moved, 0);
    for (const int threads : {1, 2, 3, 8}) {
        Sculptor sc(s, threads);
        ChangedClay changed;
        automaton_internal::setChangedClay(sc.automaton(), &changed);
        const sculpt_internal::TensionReport r = sculpt_internal::smoothBoxes(sc.automaton(), boxes, 0.6, {});
        automaton_internal::setChangedClay(sc.automaton(), nullptr);
        EXPECT_EQ(contentHash(*sc.mass()), hash) << threads;
        EXPECT_EQ(r.massMoved, moved) << threads;
        EXPECT_EQ(r.visited, visited) << threads;
        EXPECT_EQ(r.boxes, boxes.size()) << threads;
        EXPECT_LT(r.levels, r.boxes) << threads; // levels of several boxes
        const std::vector<ChangedClay::Entry> e = changed.entries();
        ASSERT_EQ(e.size(), recordedSerially.size()) << threads;
        for (size_t i = 0; i < e.size(); ++i) {
            EXPECT_EQ(e[i].slot, recordedSerially[i].slot) << threads;
            EXPECT_EQ(e[i].voxels.min, recordedSerially[i].voxels.min) << threads;
            EXPECT_EQ(e[i].voxels.max, recordedSerially[i].voxels.max) << threads;
        }
    }
}

TEST_F(SurfaceTensionTest, TheBigBumpyBallEndsTheSameOnAnyThreadCount)
{
    // Three frames (the whole surface, then the tool's dent twice) on 1, 2, 3 and 8 threads: one
    // hash, the one the boxes smoothed one after the other give (163 boxes, 2415695 clay moved).
    const Scene s = scene(bigBumpyBall(3));
    for (const int threads : {1, 2, 3, 8}) {
        Sculptor sc(s, threads);
        int64_t smoothed = 0;
        uint64_t boxes = 0;
        const RunSummary r = sc.run(0, [&](const FrameReport& f) {
            smoothed += f.massSmoothed;
            boxes += f.tensionBoxes;
        });
        EXPECT_EQ(r.massDrift, 0) << threads;
        EXPECT_GT(smoothed, 0) << threads;
        EXPECT_EQ(boxes, 163u) << threads;
        EXPECT_EQ(smoothed, 2415695) << threads;
        EXPECT_EQ(contentHash(*sc.mass()), 0xf9baa2aad830b90dull) << threads;
    }
}
