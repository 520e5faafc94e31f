// The memory estimate against the heap a run really takes (issue 12: the global layer's estimate
// follows the tools' reach, not the whole body; round 5).
//
// This executable counts the heap through tests/AllocationCounter.h: the live bytes malloc handed out
// and their peak. Aligned new keeps the library's own implementation and is not counted. The figures
// do not depend on time or load; they depend on the allocator only through the usable sizes, which
// only make the measured peak larger (a stricter test of an upper bound).
#include <vdbclay/Metrics.h>
#include <vdbclay/Scene.h>
#include <vdbclay/Sculpt.h>

#include <openvdb/openvdb.h>

#include <gtest/gtest.h>

#include <cstdint>
#include <string>

#include "AllocationCounter.h" // the byte-counting operator new and delete

using namespace vdbclay;

namespace {

class MemoryTest : public ::testing::Test {
protected:
    static void SetUpTestSuite() { openvdb::initialize(); }
};

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

/// The stroke of transport_study (a sphere tool r 6 dipped 9 into a clay sphere @a w wide at Tc,
/// slid 2 voxels a frame for 12 frames), global + compress.
std::string stroke(int w)
{
    const int r = w / 2;
    return R"({"threshold": 1000, "rule": "prorata", "seed": 1, "transport": "global", "push": "compress",
        "clay": [{"shape": "sphere", "center": [)" +
           std::to_string(r) + ", " + std::to_string(r) + ", " + std::to_string(r) + R"(], "radius": )" +
           std::to_string(r) + R"(, "mass": 1000}],
        "tools": [{"shape": "sphere", "center": [)" +
           std::to_string(r - 12) + ", " + std::to_string(2 * r - 3) + ", " + std::to_string(r) +
           R"(], "radius": 6, "path": [{"translate": [2, 0, 0], "frames": 12}]}],
        "settle": {"max_steps": 1000000}, "memory_budget": "none"})";
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
            const uint64_t peak = peakOfRun(json, threads);
            EXPECT_GE(e.total(), peak) << threads << " threads: " << e.describe() << "\n" << json;
        }
    }
}

TEST_F(MemoryTest, TheGlobalLayersEstimateFollowsTheToolNotTheWholeBody)
{
    // A small tool stroking a large sphere (compress push, no obstacle near): the layer's domain is the
    // clay within the tool's reach, so the estimate counts that, not every voxel of the body (round 4b:
    // 50.1 GiB of 54.2 for the 512-wide stroke, whose whole run peaks at 664 MB; now 1.6 of 5.7 GiB).
    const Scene s = parseScene(stroke(512), "s.json", "");
    const MemoryEstimate e = estimateSceneMemory(s);
    const uint64_t whole = e.clayLeavesGrown * 512 * 360;
    EXPECT_LT(e.transportBytes * 20, whole) << e.describe();
    EXPECT_LT(e.total(), uint64_t(8) << 30) << e.describe();
    // The same stroke 160 wide: the estimate stays above the run's heap, within a small factor.
    const std::string small = stroke(160);
    const MemoryEstimate es = estimateSceneMemory(parseScene(small, "s.json", ""));
    const uint64_t peak = peakOfRun(small, 1);
    EXPECT_GE(es.total(), peak) << es.describe();
    EXPECT_LE(es.total(), 20 * peak) << es.describe() << "; peak " << peak;
    // A tool that covers the clay (a plate wider than it) compresses all of it: the whole body.
    Scene covered = s;
    covered.tools[0] = parseScene(R"({"clay": [{"shape": "box", "min": [0,0,0], "max": [1,1,1], "mass": 1}],
        "tools": [{"shape": "box", "min": [-10,512,-10], "max": [522,515,522], "path": [{"translate": [0,-1,0], "frames": 12}]}]})",
                                  "t.json", "")
                           .tools[0];
    const MemoryEstimate ec = estimateSceneMemory(covered);
    EXPECT_EQ(ec.transportBytes, ec.clayLeavesGrown * 512 * 360);
    // An obstacle beside the tool may wall the clay in (the reach then doubles up to the whole body).
    Scene walled = s;
    walled.obstacles.push_back(
        parseScene(R"({"clay": [{"shape": "box", "min": [0,0,0], "max": [1,1,1], "mass": 1}],
        "obstacles": [{"shape": "box", "min": [200,520,200], "max": [300,530,300]}]})",
                   "t.json", "")
            .obstacles[0]);
    const MemoryEstimate ew = estimateSceneMemory(walled);
    EXPECT_EQ(ew.transportBytes, ew.clayLeavesGrown * 512 * 360);
}
