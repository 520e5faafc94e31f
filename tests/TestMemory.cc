// The memory estimate against the heap a run really takes: each part against what the run allocates
// for it (the clay's leaves, the output grids, the whole run), above it and within a small factor,
// and the global layer's bound following the tools' reach, not the whole body.
//
// This executable counts the heap through tests/AllocationCounter.h: the live bytes malloc handed out
// and their peak. Aligned new keeps the library's own implementation and is not counted. The figures
// do not depend on time or load; they depend on the allocator only through the usable sizes, which
// only make the measured peak larger (a stricter test of an upper bound). The estimate's program part
// (MemoryEstimate::processBytes: code, libraries, threads) is no heap: the heap figures are compared
// with the rest (heapOf).
#include <vdbclay/IO.h>
#include <vdbclay/Metrics.h>
#include <vdbclay/Scene.h>
#include <vdbclay/Sculpt.h>

#include <openvdb/io/File.h>
#include <openvdb/openvdb.h>

#include <gtest/gtest.h>

#include <cstdint>
#include <cstdio>
#include <string>

#include <unistd.h>

#include "AllocationCounter.h"      // the byte-counting operator new and delete
#include "sculpt/FramePolicy.h"     // frame_policy::tryStepsBeforeLayer
#include "sculpt/MemoryEstimate.h"  // memory_internal: voxelsWithinFaceSteps, the bytes per part
#include "transport/SolverTuning.h" // transport_internal::kCellIndexSlotsMax
#include "TestRng.h"

using namespace vdbclay;

namespace {

class MemoryTest : public ::testing::Test {
protected:
    static void SetUpTestSuite() { openvdb::initialize(); }
};

/// The estimate's heap: all of it but the program.
uint64_t heapOf(const MemoryEstimate& e)
{
    return e.total() - e.processBytes;
}

/// The heap's peak above what was in use before, over building the Sculptor and running @a scene.
uint64_t peakOfRun(const std::string& json, int threads)
{
    alloc_counter::resetPeak();
    const int64_t before = alloc_counter::liveBytes.load();
    {
        Sculptor sc(parseScene(json, "s.json", ""), threads);
        sc.run();
    }
    return uint64_t(alloc_counter::peakBytes.load() - before);
}

/// The heap's peak above what was in use before, over building the Sculptor, running @a scene and
/// writing its output (what `vdbclay run SCENE -o OUT.vdb` does); @a held: what the Sculptor holds
/// after the run; @a outputPeak: the part of the peak the write took above that.
uint64_t peakOfRunAndOutput(const std::string& json, int threads, uint64_t* held = nullptr,
                            uint64_t* outputPeak = nullptr)
{
    const std::string path = "/tmp/vdbclay-memory-out-" + std::to_string(::getpid()) + ".vdb";
    alloc_counter::resetPeak();
    const int64_t before = alloc_counter::liveBytes.load();
    int64_t runPeak = 0;
    {
        Sculptor sc(parseScene(json, "s.json", ""), threads);
        sc.run();
        runPeak = alloc_counter::peakBytes.load();
        const int64_t atEnd = alloc_counter::liveBytes.load();
        if (held) *held = uint64_t(atEnd - before);
        alloc_counter::resetPeak();
        writeClayFile(path, *sc.mass(), sc.checkpointMeta());
        if (outputPeak) *outputPeak = uint64_t(alloc_counter::peakBytes.load() - atEnd);
    }
    std::remove(path.c_str());
    return uint64_t(std::max(runPeak, alloc_counter::peakBytes.load()) - before);
}

/// transport_study's stroke (a sphere tool r 6 dipped 9 into a clay sphere @a w wide, slid 2 voxels a
/// frame for 12 frames), global transport, with @a push and a step budget of @a maxSteps per frame,
/// the clay at @a mass per voxel (Tc: 1000). 2D (@a dims 2): a disc and a circle tool in the z = 0 plane.
std::string stroke(int w, const std::string& push = "compress", uint64_t maxSteps = 1000000, int dims = 3,
                   int mass = 1000)
{
    const int r = w / 2;
    const std::string z = dims == 2 ? "0" : std::to_string(r);
    return R"({"dimensions": )" + std::to_string(dims) +
           R"(, "threshold": 1000, "rule": "prorata", "seed": 1, "transport": "global", "push": ")" + push +
           R"(", "clay": [{"shape": "sphere", "center": [)" + std::to_string(r) + ", " + std::to_string(r) +
           ", " + z + R"(], "radius": )" + std::to_string(r) + R"(, "mass": )" + std::to_string(mass) + R"(}],
        "tools": [{"shape": "sphere", "center": [)" +
           std::to_string(r - 12) + ", " + std::to_string(2 * r - 3) + ", " + z +
           R"(], "radius": 6, "path": [{"translate": [2, 0, 0], "frames": 12}]}],
        "settle": {"max_steps": )" +
           std::to_string(maxSteps) + R"(}, "memory_budget": "none"})";
}

/// @a s (a stroke(), 512 wide unless @a box says where) with an obstacle box beside its tool, which
/// may wall the clay in.
Scene withObstacleBesideTheStroke(Scene s,
                                  const std::string& box = R"("min": [200,520,200], "max": [300,530,300])")
{
    s.obstacles.push_back(
        parseScene(R"({"clay": [{"shape": "box", "min": [0,0,0], "max": [1,1,1], "mass": 1}],
        "obstacles": [{"shape": "box", )" +
                       box + "}]}",
                   "t.json", "")
            .obstacles[0]);
    return s;
}

/// The global layer's bytes were it to cover every voxel of the clay's leaves (its whole body), with
/// a dense index as large as it gets (a tool's push seeds it).
uint64_t wholeBody(const MemoryEstimate& e)
{
    return e.clayVoxels * memory_internal::kTransportBytesPerCell +
           4 * uint64_t(transport_internal::kCellIndexSlotsMax);
}

} // namespace

TEST_F(MemoryTest, TheEstimateIsAboveTheHeapARunTakes)
{
    const std::string press =
        R"({"threshold": 1000, "rule": "prorata", "transport": "global", "push": "compress",
        "clay": [{"shape": "box", "min": [0,0,0], "max": [23,23,23], "mass": 1000}],
        "tools": [{"shape": "box", "min": [-12,24,-12], "max": [35,27,35], "path": [{"translate": [0,-1,0], "frames": 4}]}],
        "obstacles": [{"shape": "box", "min": [-30,-3,-30], "max": [50,-1,50]}],
        "settle": {"max_steps": 400000}})";
    const std::string poke =
        R"({"threshold": 1000, "rule": "prorata", "transport": "global", "push": "compress",
        "clay": [{"shape": "box", "min": [0,0,0], "max": [47,19,47], "mass": 1000}],
        "tools": [{"shape": "sphere", "center": [24,25,24], "radius": 5, "path": [{"translate": [0,-1,0], "frames": 6}]}],
        "obstacles": [{"shape": "box", "min": [-30,-3,-30], "max": [80,-1,80]}],
        "settle": {"max_steps": 400000}})";
    const std::string surface = std::string(poke).replace(poke.find("compress"), 8, "surface");
    for (const std::string& json : {press, poke, surface, stroke(64), stroke(128)}) {
        const MemoryEstimate e = estimateSceneMemory(parseScene(json, "s.json", ""));
        for (int threads : {1, 2}) {
            const uint64_t peak = peakOfRunAndOutput(json, threads);
            EXPECT_GE(heapOf(e), peak) << threads << " threads: " << e.describe() << "\n" << json;
        }
    }
}

TEST_F(MemoryTest, TheClayLeavesCountedBoundTheLeavesBuilt)
{
    // Analytic shapes are counted leaf by leaf from their distance: at least the leaves the clay is
    // built in, and close to them (a leaf whose centre lies within a leaf's half-diagonal of the
    // surface may hold no voxel centre inside). A box is counted exactly; 2D, one layer of leaves.
    const char* shapes[] = {
        R"({"shape": "sphere", "center": [3.3, 70.1, -5.2], "radius": 61.7, "mass": 800})",
        R"({"shape": "cylinder", "center": [0, 0, 0], "radius": 40, "height": 90, "mass": 800})",
        R"({"shape": "capsule", "a": [-40, -10, 7], "b": [50, 30, 7], "radius": 17, "mass": 800})",
        R"({"shape": "box", "min": [-13, 5, 0], "max": [60, 41, 33], "mass": 800})",
        R"({"shape": "box", "min": [-13, 5, 0], "max": [60, 41, 33], "mass": 800,
            "transform": {"rotate": [30, 10, 0], "pivot": [20, 20, 16]}})",
        R"({"shape": "sphere", "center": [0, 0, 0], "radius": 20, "mass": 800,
            "transform": {"scale": [2.5, 1, 0.7], "translate": [5, 0, 0]}})"};
    for (int dims : {3, 2}) {
        for (const char* shape : shapes) {
            const std::string json =
                R"({"dimensions": )" + std::to_string(dims) + R"(, "clay": [)" + shape + "]}";
            Scene scene;
            try {
                scene = parseScene(json, "s.json", "");
            } catch (const Error&) {
                continue; // a field the 2D scene does not take
            }
            const MemoryEstimate e = estimateSceneMemory(scene);
            Sculptor sc(scene, 1);
            const uint64_t built = sc.mass()->tree().leafCount();
            EXPECT_GE(e.clayLeaves, built) << json;
            // In 3D the inside is tiles: the leaves counted are those whose centre lies within a
            // half-diagonal of the surface, on either side, where the slots holding both inside and
            // outside voxel centres are fewer.
            const uint64_t slack = dims == 3 ? built : built / 2;
            EXPECT_LE(e.clayLeaves, built + slack + 8) << json << ": " << built << " built";
            EXPECT_EQ(e.clayLeavesGrown, e.clayLeaves) << json; // at most Tc, no tool: it never moves
            EXPECT_GE(e.clayBytes, uint64_t(sc.mass()->memUsage())) << json;
            const bool plainBox = std::string(shape).find("transform") == std::string::npos &&
                                  std::string(shape).find("box") != std::string::npos;
            if (plainBox && dims == 2) {
                EXPECT_EQ(e.clayLeaves, built) << json;
            }
        }
    }
}

TEST_F(MemoryTest, EachPartBoundsWhatTheRunAllocatesForIt)
{
    // A sphere 128 wide at Tc, alone and stroked by a small tool (the automaton settling it: its leaf
    // table built): writing the .vdb takes, beyond the run's own grids, no more than the output's
    // figure and more than 40 % of it (the figure gives values to every leaf of the surface's band
    // around the clay's leaves, grown to the tools' reach; the sweep gives them to 57 % of those on
    // the stroked sphere); the clay's tree, the tools' cells and the automaton's state after the run
    // no more than theirs; the whole run's and write's peak no more than the estimate's heap, and
    // more than half of it.
    const std::string still =
        R"({"clay": [{"shape": "sphere", "center": [64, 64, 64], "radius": 64, "mass": 1000}]})";
    const std::string stroked =
        R"({"rule": "prorata", "seed": 1, "clay": [{"shape": "sphere", "center": [64, 64, 64], "radius": 64, "mass": 1000}],
        "tools": [{"shape": "sphere", "center": [52, 125, 64], "radius": 6, "path": [{"translate": [2, 0, 0], "frames": 4}]}]})";
    for (const std::string& json : {still, stroked}) {
        const MemoryEstimate e = estimateSceneMemory(parseScene(json, "s.json", ""));
        uint64_t held = 0, output = 0;
        const uint64_t peak = peakOfRunAndOutput(json, 1, &held, &output);
        EXPECT_GE(e.outputBytes, output) << e.describe();
        EXPECT_LE(2 * e.outputBytes, 5 * output) << e.describe() << "; the write takes " << output;
        EXPECT_GE(e.clayBytes + e.obstacleBytes + e.toolBytes + e.automatonBytes, held) << e.describe();
        EXPECT_GE(heapOf(e), peak) << e.describe();
        EXPECT_LE(heapOf(e), 2 * peak) << e.describe() << "; the run peaks at " << peak;
    }
}

TEST_F(MemoryTest, TheOutputPartCountsOnlyTheGridsTheFileHolds)
{
    // The stroked 128-wide sphere: the mass alone needs no float grid, the density one, the surface
    // (swept from the density) both and the sweep's scratch; each write takes no more than its figure.
    Scene s = parseScene(
        R"({"rule": "prorata", "seed": 1, "clay": [{"shape": "sphere", "center": [64, 64, 64], "radius": 64, "mass": 1000}],
        "tools": [{"shape": "sphere", "center": [52, 125, 64], "radius": 6, "path": [{"translate": [2, 0, 0], "frames": 4}]}]})",
        "s.json", "");
    const MemoryEstimate all = estimateSceneMemory(s);
    Sculptor sc(s, 1);
    sc.run();
    const std::string path = "/tmp/vdbclay-memory-grids-" + std::to_string(::getpid()) + ".vdb";
    uint64_t last = 0;
    for (const char* names : {"mass", "density", "surface"}) {
        s.outputs.grids = parseClayGrids(names);
        const MemoryEstimate e = estimateSceneMemory(s);
        EXPECT_GT(e.outputBytes, last) << names; // each one more than the one before
        last = e.outputBytes;
        alloc_counter::resetPeak();
        const int64_t before = alloc_counter::liveBytes.load();
        writeClayFile(path, *sc.mass(), sc.checkpointMeta(), s.outputs.grids);
        const uint64_t written = uint64_t(alloc_counter::peakBytes.load() - before);
        EXPECT_GE(e.outputBytes, written) << names << ": " << e.describe();
    }
    std::remove(path.c_str());
    s.outputs.grids = parseClayGrids("mass");
    EXPECT_EQ(estimateSceneMemory(s).outputBytes,
              memory_internal::kOutputWriteBytes +
                  all.clayLeavesGrown * memory_internal::kOutputWriteBytesPerLeaf);
    s.outputs.grids = parseClayGrids("surface");
    EXPECT_EQ(estimateSceneMemory(s).outputBytes, all.outputBytes);
}

TEST_F(MemoryTest, TheGlobalLayersEstimateFollowsTheToolNotTheWholeBody)
{
    // A small tool stroking a large sphere (compress push, no obstacle near): the layer's domain is the
    // clay within the tool's reach, so the estimate counts that, not every voxel of the body.
    const Scene s = parseScene(stroke(512), "s.json", "");
    const MemoryEstimate e = estimateSceneMemory(s);
    EXPECT_LT(e.transportBytes * 20, wholeBody(e)) << e.describe();
    EXPECT_LT(e.total(), uint64_t(2) << 30) << e.describe();
    // The same stroke 160 wide: the estimate stays above the run's heap, within a small factor (the
    // layer's domain bound, the tool's diagonal + 5 face steps around the chains, spans much of a body
    // this small, while the run's reach is the contact's width + 2).
    const std::string small = stroke(160);
    const MemoryEstimate es = estimateSceneMemory(parseScene(small, "s.json", ""));
    const uint64_t peak = peakOfRunAndOutput(small, 1);
    EXPECT_GE(heapOf(es), peak) << es.describe();
    EXPECT_LE(heapOf(es), 20 * peak) << es.describe() << "; peak " << peak;
    // A tool that covers the clay (a plate wider than it) compresses all of it: the whole body.
    Scene covered = s;
    covered.tools[0] = parseScene(R"({"clay": [{"shape": "box", "min": [0,0,0], "max": [1,1,1], "mass": 1}],
        "tools": [{"shape": "box", "min": [-10,512,-10], "max": [522,515,522], "path": [{"translate": [0,-1,0], "frames": 12}]}]})",
                                  "t.json", "")
                           .tools[0];
    const MemoryEstimate ec = estimateSceneMemory(covered);
    EXPECT_EQ(ec.transportBytes, wholeBody(ec));
    // An obstacle beside the tool may wall the clay in (the reach then doubles up to the whole body).
    const MemoryEstimate ew = estimateSceneMemory(withObstacleBesideTheStroke(s));
    EXPECT_EQ(ew.transportBytes, wholeBody(ew));
}

TEST_F(MemoryTest, TheSurfacePushsLayerEstimateFollowsTheToolAndStaysAboveTheHeap)
{
    // The surface push's layer runs after the automaton's try (frame_policy); its seeds stay in the
    // push's region whatever the try did, so the domain is bounded by the tool's reach under any step
    // budget. These strokes' frames settle in 0-1 steps after the layer. 3D: a 256-wide sphere (the
    // grown sweep does not span it); 2D: a 1024-wide disc (a 2D contact is the number of voxels
    // entered, a reach of ~170).
    for (uint64_t maxSteps : {uint64_t(16), uint64_t(100000)})
        for (const std::string& json :
             {stroke(256, "surface", maxSteps), stroke(1024, "surface", maxSteps, 2)}) {
            const MemoryEstimate e = estimateSceneMemory(parseScene(json, "s.json", ""));
            EXPECT_LT(e.transportBytes, wholeBody(e)) << e.describe(); // the bound applies
            EXPECT_GT(e.transportBytes, 0u);
            for (int threads : {1, 2}) {
                const uint64_t peak = peakOfRun(json, threads);
                EXPECT_GE(heapOf(e), peak) << threads << " threads: " << e.describe() << "\n" << json;
            }
        }
    // The 512-wide surface stroke at Tc: saturated clay, where the try never runs (trySaturated), so
    // one figure under any step budget, a small part of the whole body's.
    const MemoryEstimate e512 = estimateSceneMemory(parseScene(stroke(512, "surface", 16), "s.json", ""));
    EXPECT_LT(e512.transportBytes * 20, wholeBody(e512)) << e512.describe();
    EXPECT_LT(e512.total(), uint64_t(2) << 30) << e512.describe();
    for (uint64_t maxSteps : {uint64_t(1), uint64_t(17), uint64_t(100000), uint64_t(5000000)})
        EXPECT_EQ(
            estimateSceneMemory(parseScene(stroke(512, "surface", maxSteps), "s.json", "")).transportBytes,
            e512.transportBytes)
            << maxSteps;
    // At 0.9 Tc the try may run before the layer: any budget up to 16 gives the figure with no try
    // (a chunk that reaches the budget ends the frame); 17 lets the try run 16 steps first, a larger
    // margin; from 33 on (the try's 32 steps or more can cross the push's region) one figure.
    const auto loose = [](uint64_t maxSteps) {
        return estimateSceneMemory(parseScene(stroke(512, "surface", maxSteps, 3, 900), "s.json", ""));
    };
    EXPECT_EQ(frame_policy::tryStepsBeforeLayer(16), 0u);
    EXPECT_EQ(frame_policy::tryStepsBeforeLayer(17), 16u);
    EXPECT_EQ(frame_policy::tryStepsBeforeLayer(33), 32u);
    EXPECT_EQ(loose(1).transportBytes, loose(16).transportBytes);
    EXPECT_EQ(loose(16).transportBytes, e512.transportBytes);
    const uint64_t at17 = loose(17).transportBytes;
    EXPECT_GT(at17, e512.transportBytes);
    const MemoryEstimate eDefault = loose(100000);
    EXPECT_GT(eDefault.transportBytes, at17);
    for (uint64_t maxSteps : {uint64_t(33), uint64_t(5000000)})
        EXPECT_EQ(loose(maxSteps).transportBytes, eDefault.transportBytes) << maxSteps;
    EXPECT_LT(eDefault.transportBytes * 4, wholeBody(eDefault)) << eDefault.describe();
    EXPECT_LT(eDefault.total(), uint64_t(6) << 30) << eDefault.describe();
    // The layer's arrays serve one frame at a time, so its figure is the largest frame's and does not
    // grow with the stroke's length.
    std::string longer = stroke(512, "surface", 100000, 3, 900);
    longer.replace(longer.find(R"("frames": 12)"), 12, R"("frames": 48)");
    const MemoryEstimate eLong = estimateSceneMemory(parseScene(longer, "s.json", ""));
    EXPECT_LE(eLong.transportCells, eDefault.transportCells + eDefault.transportCells / 50)
        << eLong.describe();
    EXPECT_GE(eLong.transportCells, eDefault.transportCells) << eLong.describe();
}

TEST_F(MemoryTest, TheLayersCellsAreCountedExactlyWithinTheFaceSteps)
{
    // voxelsWithinFaceSteps against a voxel-by-voxel count: boxes of 1-7 voxels a side, a reach of
    // 0-9 face steps, a window that cuts the octahedron anywhere (or misses it), 3D and 2D.
    using memory_internal::voxelsWithinFaceSteps;
    vdbclay_test::Rng rng(20261201);
    auto box = [&](int spread, int most) {
        Box b;
        for (int a = 0; a < 3; ++a) {
            b.min[a] = rng.range(-spread, spread);
            b.max[a] = b.min[a] + rng.range(0, most - 1);
        }
        return b;
    };
    uint64_t nonzero = 0;
    for (int trial = 0; trial < 3000; ++trial) {
        const int dims = trial % 3 == 0 ? 2 : 3;
        Box b = box(6, 7), within = box(14, 24);
        if (dims == 2) b.min[2] = b.max[2] = 0;
        const int64_t r = rng.range(0, 9);
        uint64_t brute = 0;
        for (int64_t x = within.min[0]; x <= within.max[0]; ++x)
            for (int64_t y = within.min[1]; y <= within.max[1]; ++y)
                for (int64_t z = within.min[2]; z <= within.max[2]; ++z) {
                    if (dims == 2 && z != 0) continue;
                    int64_t d = 0;
                    const int64_t v[3] = {x, y, z};
                    for (int a = 0; a < 3; ++a)
                        d += v[a] < b.min[a] ? b.min[a] - v[a] : v[a] > b.max[a] ? v[a] - b.max[a] : 0;
                    brute += d <= r ? 1 : 0;
                }
        nonzero += brute > 0 ? 1 : 0;
        ASSERT_EQ(voxelsWithinFaceSteps(b, r, within, dims), brute)
            << "trial " << trial << ", dims " << dims << ", reach " << r;
    }
    EXPECT_GT(nonzero, 500u); // the windows meet the octahedra often enough to test something
    // A whole octahedron of radius r around one voxel: (2r + 1)(2r^2 + 2r + 3) / 3 voxels.
    const Box one{{{0, 0, 0}}, {{0, 0, 0}}}, everywhere{{{-100, -100, -100}}, {{100, 100, 100}}};
    for (int64_t r : {0, 1, 2, 17, 90})
        EXPECT_EQ(voxelsWithinFaceSteps(one, r, everywhere, 3),
                  uint64_t((2 * r + 1) * (2 * r * r + 2 * r + 3) / 3))
            << r;
    // More rows than it may count: it says so (the caller counts the leaves' voxels instead).
    const Box huge{{{-1000000, -1000000, 0}}, {{1000000, 1000000, 10}}};
    EXPECT_EQ(voxelsWithinFaceSteps(one, 5000000, huge, 3), UINT64_MAX);
}

TEST_F(MemoryTest, TheLayersCountedCellsBoundTheCellsEveryFrameSolves)
{
    // The figure behind transportBytes: no frame's layer solves more cells than the estimate counts,
    // for the strokes (3D, surface and compress; 2D surface) and a sphere poked into a slab.
    const std::string poke =
        R"({"threshold": 1000, "rule": "prorata", "transport": "global", "push": "compress",
        "clay": [{"shape": "box", "min": [0,0,0], "max": [127,23,127], "mass": 1000}],
        "tools": [{"shape": "sphere", "center": [64,26,64], "radius": 3, "path": [{"translate": [0,-1,0], "frames": 6}]}],
        "settle": {"max_steps": 100000}})";
    std::string longer = stroke(160, "surface", 100000); // 24 frames: the largest frame's cells count
    longer.replace(longer.find(R"("frames": 12)"), 12, R"("frames": 24)");
    for (const std::string& json :
         {longer, stroke(128, "compress"), stroke(512, "surface", 100000, 2), poke}) {
        const Scene scene = parseScene(json, "s.json", "");
        const MemoryEstimate e = estimateSceneMemory(scene);
        ASSERT_LT(e.transportCells, e.clayVoxels) << json; // the bound applies
        Sculptor sc(scene, 2);
        uint64_t most = 0, solved = 0;
        while (!sc.done()) {
            const FrameReport f = sc.runFrame();
            most = std::max(most, f.transport.unknowns);
            solved += f.transport.solves;
        }
        EXPECT_GT(solved, 0u) << json; // the layer ran
        EXPECT_GE(e.transportCells, most) << e.describe() << "\n" << json;
    }
}

TEST_F(MemoryTest, ClayFromAFileThatRecordsItsLargestCellKeepsTheReachBound)
{
    // A clay file records its largest cell (vdbclay_max_mass); at most Tc, the clay cannot overflow
    // with no tool near, so the surface stroke on clay read from a file keeps the tool's bound (without
    // the record: the whole body, its largest cell unknown without reading its voxels). The estimate
    // reads the record from the file's metadata only; it stays above the run's heap.
    const std::string dir = "/tmp/vdbclay-memory-" + std::to_string(::getpid());
    const std::string path = dir + "-sphere.vdb", bare = dir + "-bare.vdb", over = dir + "-over.vdb";
    const Scene shapes = parseScene(stroke(256, "surface", 100000), "s.json", "");
    {
        Sculptor start(shapes, 2); // frame 0: the sphere as built
        writeClayFile(path, *start.mass(), start.checkpointMeta());
        // The same clay without the record (another writer), and recording a cell over Tc.
        MassGridPtr g = openvdb::gridPtrCast<openvdb::Int32Grid>(start.mass()->deepCopyGrid());
        g->setName("mass");
        openvdb::io::File(bare).write({g});
        g->insertMeta("vdbclay_max_mass", openvdb::Int64Metadata(1001));
        openvdb::io::File(over).write({g});
    }
    auto fromFile = [&](const std::string& file) {
        std::string json = stroke(256, "surface", 100000);
        const size_t a = json.find(R"({"shape": "sphere")"), b = json.find("}]", a);
        return json.replace(a, b + 1 - a, R"({"shape": "vdb", "file": ")" + file + R"("})");
    };
    const std::string json = fromFile(path);
    const MemoryEstimate e = estimateSceneMemory(parseScene(json, "s.json", ""));
    EXPECT_GT(e.transportBytes, 0u);
    EXPECT_LT(e.transportBytes, wholeBody(e)) << e.describe(); // the bound applies
    for (int threads : {1, 2}) {
        const uint64_t peak = peakOfRun(json, threads);
        EXPECT_GE(heapOf(e), peak) << threads << " threads: " << e.describe();
    }
    for (const std::string& file : {bare, over}) {
        const MemoryEstimate w = estimateSceneMemory(parseScene(fromFile(file), "s.json", ""));
        EXPECT_EQ(w.transportBytes, wholeBody(w)) << file;
    }
    // A tool whose sweep has no corner outside the file's bounds may start inside its clay (the
    // file's voxels are not read to tell): the whole body.
    Scene buried = parseScene(json, "s.json", "");
    buried.tools[0] = parseScene(R"({"clay": [{"shape": "box", "min": [0,0,0], "max": [1,1,1], "mass": 1}],
        "tools": [{"shape": "sphere", "center": [200,200,128], "radius": 6, "path": [{"translate": [2,0,0], "frames": 12}]}]})",
                                 "t.json", "")
                          .tools[0];
    const MemoryEstimate eb = estimateSceneMemory(buried);
    EXPECT_EQ(eb.transportBytes, wholeBody(eb));
    for (const std::string& file : {path, bare, over})
        std::remove(file.c_str());
}

TEST_F(MemoryTest, WhereTheReachBoundDoesNotHoldTheLayerCountsTheWholeBody)
{
    for (const std::string push : {"surface", "compress"}) {
        const Scene s = parseScene(stroke(512, push, 16), "s.json", "");
        ASSERT_LT(estimateSceneMemory(s).transportBytes * 20, wholeBody(estimateSceneMemory(s))) << push;
        // A plate wider than the clay covers it: its contact is the body's width.
        Scene covered = s;
        covered.tools[0] =
            parseScene(R"({"clay": [{"shape": "box", "min": [0,0,0], "max": [1,1,1], "mass": 1}],
            "tools": [{"shape": "box", "min": [-10,512,-10], "max": [522,515,522], "path": [{"translate": [0,-1,0], "frames": 12}]}]})",
                       "t.json", "")
                .tools[0];
        const MemoryEstimate ec = estimateSceneMemory(covered);
        EXPECT_EQ(ec.transportBytes, wholeBody(ec)) << push;
        // A tool that starts inside the clay has no room near it.
        Scene buried = s;
        buried.tools[0] =
            parseScene(R"({"clay": [{"shape": "box", "min": [0,0,0], "max": [1,1,1], "mass": 1}],
            "tools": [{"shape": "sphere", "center": [200,256,256], "radius": 6, "path": [{"translate": [2,0,0], "frames": 12}]}]})",
                       "t.json", "")
                .tools[0];
        const MemoryEstimate eb = estimateSceneMemory(buried);
        EXPECT_EQ(eb.transportBytes, wholeBody(eb)) << push;
        // One dipped into the sphere's flank at 45 degrees (its sweep within the sphere's box, but
        // sticking out of the sphere) enters from the surface: the bound holds.
        Scene flank = s;
        flank.tools[0] = parseScene(R"({"clay": [{"shape": "box", "min": [0,0,0], "max": [1,1,1], "mass": 1}],
            "tools": [{"shape": "sphere", "center": [435,435,250], "radius": 6, "path": [{"translate": [0,0,2], "frames": 12}]}]})",
                                    "t.json", "")
                             .tools[0];
        const MemoryEstimate ef = estimateSceneMemory(flank);
        EXPECT_LT(ef.transportBytes * 20, wholeBody(ef)) << push;
        // An obstacle beside the tool may wall the clay in.
        const MemoryEstimate ew = estimateSceneMemory(withObstacleBesideTheStroke(s));
        EXPECT_EQ(ew.transportBytes, wholeBody(ew)) << push;
        // Clay over Tc overflows wherever it is, with no tool near.
        Scene over = s;
        over.clay[0].mass = 1200;
        const MemoryEstimate eo = estimateSceneMemory(over);
        EXPECT_EQ(eo.transportBytes, wholeBody(eo)) << push;
        // So does clay where two shapes overlap and add up over Tc (the scene's first frame runs the
        // layer over every over cell even when no tool touches clay: frame_policy::layerRuns).
        Scene overlap = s;
        overlap.clay.push_back(
            parseScene(
                R"({"clay": [{"shape": "box", "min": [100,100,100], "max": [103,103,103], "mass": 1}]})",
                "t.json", "")
                .clay[0]);
        const MemoryEstimate el = estimateSceneMemory(overlap);
        EXPECT_EQ(el.transportBytes, wholeBody(el)) << push;
    }
}

TEST_F(MemoryTest, TheWholeBodysCellsAreNoMoreThanSevenPerFullCell)
{
    // The layer's domain holds full cells (at least Tc each: no more than the mass over Tc) and their
    // faces: a cylinder squeezed by a plate wider than it (the whole body) counts that, not every voxel
    // of the leaves its clay may reach; at least 7 per voxel of the clay as built, at most 7 per voxel
    // of its bounds (the mass bound counts those at Tc).
    const Scene squeeze = parseScene(
        R"({"threshold": 1000, "rule": "prorata", "push": "compress", "transport": "global",
        "clay": [{"shape": "cylinder", "center": [0, 15.5, 0], "radius": 16, "height": 32, "mass": 1000}],
        "tools": [{"shape": "box", "min": [-64, 32, -64], "max": [64, 35, 64], "path": [{"translate": [0, -1, 0], "frames": 16}]}],
        "obstacles": [{"shape": "box", "min": [-96, -3, -96], "max": [96, -1, 96]}]})",
        "s.json", "");
    const MemoryEstimate e = estimateSceneMemory(squeeze);
    EXPECT_LT(e.transportCells, e.clayLeavesGrown * 512) << e.describe();
    EXPECT_LE(e.transportCells, 7u * 33u * 32u * 33u) << e.describe();
    Sculptor sc(squeeze, 1);
    EXPECT_GE(e.transportCells, 7 * sc.mass()->activeVoxelCount()) << e.describe();
    uint64_t most = 0;
    while (!sc.done())
        most = std::max(most, sc.runFrame().transport.unknowns);
    EXPECT_GT(most, 0u);
    EXPECT_GE(e.transportCells, most);
}

TEST_F(MemoryTest, ClayHeldAsTilesIsCountedOnceWhereItsBoxesLeavesAreCounted)
{
    // A cube at Tc (tiles inside) under a plate wider than it: the clay may spread over its box, whose
    // leaves are all counted, tiles' voxels among them; the layer's cells are those voxels, not those
    // and the tiles' again. A ball poked by a small tool is counted by the leaves near its surface:
    // its voxels inside are counted beside them.
    const Scene press = parseScene(
        R"({"threshold": 1000, "rule": "prorata", "push": "compress", "transport": "global",
        "clay": [{"shape": "box", "min": [0, 0, 0], "max": [63, 63, 63], "mass": 1000}],
        "tools": [{"shape": "box", "min": [-32, 64, -32], "max": [95, 67, 95], "path": [{"translate": [0, -1, 0], "frames": 8}]}],
        "obstacles": [{"shape": "box", "min": [-128, -3, -128], "max": [192, -1, 192]}]})",
        "s.json", "");
    const MemoryEstimate pe = estimateSceneMemory(press);
    EXPECT_EQ(pe.clayVoxels, pe.clayLeavesGrown * 512) << pe.describe();
    const Scene poke = parseScene(
        R"({"threshold": 1000, "rule": "prorata", "push": "compress", "transport": "global",
        "clay": [{"shape": "sphere", "center": [64, 64, 64], "radius": 48, "mass": 1000}],
        "tools": [{"shape": "sphere", "center": [64, 115, 64], "radius": 3, "path": [{"translate": [0, -1, 0], "frames": 4}]}]})",
        "s.json", "");
    const MemoryEstimate ke = estimateSceneMemory(poke);
    EXPECT_GT(ke.clayVoxels, ke.clayLeavesGrown * 512) << ke.describe();
}

TEST_F(MemoryTest, ClayAtMostTcGrowsOnlyNearTheToolsWhereTheLayerMovesAllOfTheOverload)
{
    // A 256-wide ball at Tc stroked by a small tool, compress push and global layer: the push and the
    // layer move clay only within the layer's bound of the tool, so the clay's leaves grow there and
    // nowhere else; every frame's leaves stay within those counted. The same stroke with the surface
    // push on clay under Tc (the automaton's try may carry overload past the push's region), or
    // beside an obstacle (the reach may double up to the whole body), may grow anywhere on the
    // surface: a leaf of margin all round.
    const std::string json = stroke(256);
    const MemoryEstimate e = estimateSceneMemory(parseScene(json, "s.json", ""));
    EXPECT_LE(e.clayLeavesGrown, e.clayLeaves + e.clayLeaves / 4) << e.describe();
    Sculptor sc(parseScene(json, "s.json", ""), 1);
    uint64_t most = sc.mass()->tree().leafCount();
    sc.run(0, [&](const FrameReport&) { most = std::max<uint64_t>(most, sc.mass()->tree().leafCount()); });
    EXPECT_GE(e.clayLeavesGrown, most) << e.describe();
    EXPECT_GT(most, uint64_t(sc.mass()->tree().leafCount()) / 2); // the frames were seen
    const MemoryEstimate under =
        estimateSceneMemory(parseScene(stroke(256, "surface", 16, 3, 900), "s.json", ""));
    EXPECT_GE(under.clayLeavesGrown, under.clayLeaves + under.clayLeaves / 2) << under.describe();
    const MemoryEstimate walled = estimateSceneMemory(withObstacleBesideTheStroke(
        parseScene(json, "s.json", ""), R"("min": [150,262,100], "max": [170,270,160])"));
    EXPECT_GE(walled.clayLeavesGrown, walled.clayLeaves + walled.clayLeaves / 2) << walled.describe();
    // The scene's surface tension smooths the whole surface in the first frame.
    Scene tension = parseScene(json, "s.json", "");
    tension.surfaceTension = 0.5;
    const MemoryEstimate te = estimateSceneMemory(tension);
    EXPECT_GE(te.clayLeavesGrown, te.clayLeaves + te.clayLeaves / 2) << te.describe();
}

TEST_F(MemoryTest, EveryFrameOfAToolMovedByWholeVoxelsIsTightened)
{
    // A plate 256 x 4 x 256 voxels (a transformed box's bounds are up to two voxels loose on every
    // side) pressing 1 voxel a frame for 40 frames: each frame's bounds are tightened to the voxels
    // inside (the first frame's box, moved), not only while the distance budget lasts (2^21
    // evaluations: the first frames only; the later ones would count 260 x 8 x 260).
    const Scene press =
        parseScene(R"({"clay": [{"shape": "box", "min": [0,0,0], "max": [127,127,127], "mass": 800}],
        "tools": [{"shape": "box", "min": [-64,128,-64], "max": [191,131,191], "path": [{"translate": [0,-1,0], "frames": 40}]}]})",
                   "s.json", "");
    EXPECT_EQ(estimateSceneMemory(press).toolVoxels, 256u * 4u * 256u);
    const Scene flat = parseScene(
        R"({"dimensions": 2, "clay": [{"shape": "box", "min": [0,0], "max": [127,127], "mass": 800}],
        "tools": [{"shape": "box", "min": [-64,128], "max": [191,131], "path": [{"translate": [0,-1,0], "frames": 40}]}]})",
        "s.json", "");
    EXPECT_EQ(estimateSceneMemory(flat).toolVoxels, 256u * 4u);
}

TEST_F(MemoryTest, HugeClayCountedByItsBoundsIsEstimatedAtOnceAndDoesNotWrap)
{
    // Clay whose shape the estimate knows only by its bounds (a shape of no scene kind, as the
    // Python module's transformed level sets): a box 2e6 voxels wide holds 1.6e16 leaves, which the
    // count gives up on (a leaf held whole counts one test) for the boxes' count. The parts reach
    // exabytes; the total saturates at UINT64_MAX instead of wrapping below a budget.
    Scene s;
    s.source = "huge";
    ClaySpec c;
    c.shape.kind = "shape";
    c.shape.field = "clay[0]";
    c.shape.shape = makeBox({{-1e6, -1e6, -1e6}}, {{1e6, 1e6, 1e6}});
    c.mass = 1000;
    s.clay.push_back(c);
    const MemoryEstimate e = estimateSceneMemory(s);
    EXPECT_GE(e.clayLeaves, 250000ull * 250000ull * 250000ull);
    EXPECT_GE(e.total(), e.clayBytes);
    EXPECT_GE(e.total(), e.automatonBytes);
    EXPECT_THROW(checkMemoryBudget(s), Error);
}
