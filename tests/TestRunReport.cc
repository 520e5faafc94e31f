// A run's report (vdbclay/RunReport.h) and the memory watchdog a Sculptor keeps (Sculpt.h:
// memoryBudget, outgrewBudget): the report's keys, and a run whose clay outgrows its budget stopping
// where its checkpoint resumes exactly.
#include <vdbclay/IO.h>
#include <vdbclay/Metrics.h>
#include <vdbclay/RunReport.h>
#include <vdbclay/Scene.h>
#include <vdbclay/Sculpt.h>
#include <vdbclay/Shapes.h>

#include <nlohmann/json.hpp>

#include <gtest/gtest.h>

#include "TempDirTest.h"

#include <climits>
#include <set>
#include <string>

using namespace vdbclay;

namespace {

class RunReportTest : public vdbclay_test::TempDirTest {
protected:
    /// A 2D scene of clay at 2^31 - 1 per voxel (a 3^2 square) read from a file: it spreads far
    /// beyond what the estimate sees in the file (8 MiB: outgrown after about 130 steps).
    Scene denseScene(const std::string& budget)
    {
        const MassGridPtr dense = makeClay(*makeBox({{0, 0, 0}}, {{2, 2, 0}}), INT32_MAX, 2);
        ClayMeta meta;
        meta.dimensions = 2;
        writeClayFile(file("dense.vdb"), *dense, meta);
        return parseScene(
            R"({"dimensions": 2, "memory_budget": ")" + budget +
                R"(", "settle": {"max_steps": 160}, "clay": [{"shape": "vdb", "file": "dense.vdb"}]})",
            "dense.json", dir);
    }
};

TEST_F(RunReportTest, JsonHasTheStatsKeysAndTheRunsValues)
{
    Scene scene = defaultScene();
    scene.frames = 2;
    Sculptor sc(scene, 2);
    const RunSummary s = sc.run();
    RunReport r = makeRunReport(sc, s, 2);
    r.setupSeconds = 0.25;
    r.heap = "system (test)";
    const nlohmann::json j = nlohmann::json::parse(runReportJson(r));
    std::set<std::string> keys;
    for (auto it = j.begin(); it != j.end(); ++it)
        keys.insert(it.key());
    // The CLI's --stats keys: tests/cli and the scripts that read the file rely on every one.
    const std::set<std::string> expected{"blocks_over_tc",
                                         "blocks_updated",
                                         "blocks_visited",
                                         "clay_voxels",
                                         "compaction",
                                         "content_hash",
                                         "frames",
                                         "frame_seconds",
                                         "frames_no_room",
                                         "frames_transport_no_room",
                                         "frames_unsettled",
                                         "heap",
                                         "heterogeneity_cv",
                                         "interior_cells",
                                         "interior_mean_density",
                                         "mass_added",
                                         "mass_drift",
                                         "mass_final",
                                         "mass_initial",
                                         "mass_removed",
                                         "mass_smoothed",
                                         "mass_trapped",
                                         "max_cell",
                                         "occupied_voxels",
                                         "output_seconds",
                                         "pass_busy_seconds",
                                         "pass_idle_seconds",
                                         "push",
                                         "push_seconds",
                                         "residual_overload",
                                         "rule",
                                         "scene",
                                         "seconds",
                                         "settled",
                                         "setup_seconds",
                                         "stage_seconds",
                                         "steps",
                                         "sweep",
                                         "tension_boxes",
                                         "tension_seconds",
                                         "tension_voxels",
                                         "threads",
                                         "threshold",
                                         "transport",
                                         "transport_iterations",
                                         "transport_mass_moved",
                                         "transport_seconds",
                                         "transport_solves"};
    EXPECT_EQ(keys, expected);
    EXPECT_EQ(j["scene"], scene.source);
    EXPECT_EQ(j["rule"], ruleName(scene.rule.rule));
    EXPECT_EQ(j["threshold"], scene.rule.threshold);
    EXPECT_EQ(j["threads"], 2);
    EXPECT_EQ(j["frames"], 2u);
    EXPECT_EQ(j["frame_seconds"].size(), 2u);
    EXPECT_EQ(j["steps"], s.steps);
    EXPECT_EQ(j["mass_initial"], s.massInitial);
    EXPECT_EQ(j["mass_final"], s.massFinal);
    EXPECT_EQ(j["mass_drift"], 0);
    EXPECT_EQ(j["clay_voxels"], clayVoxelCount(*sc.mass()));
    EXPECT_EQ(j["setup_seconds"], 0.25);
    EXPECT_EQ(j["heap"], "system (test)");
    EXPECT_EQ(j["stage_seconds"].size(), 4u);
    char hash[17];
    std::snprintf(hash, sizeof hash, "%016llx", (unsigned long long)contentHash(*sc.mass()));
    EXPECT_EQ(j["content_hash"], hash);
    EXPECT_EQ(runReportJson(r, -1).find('\n'), std::string::npos);
}

TEST_F(RunReportTest, BudgetIsResolvedOrNone)
{
    Scene scene = defaultScene();
    scene.memoryBudget = 0;
    EXPECT_EQ(Sculptor(scene).memoryBudget(), defaultMemoryBudget());
    scene.memoryBudget = uint64_t(1) << 30;
    EXPECT_EQ(Sculptor(scene).memoryBudget(), uint64_t(1) << 30);
    scene.memoryBudget = kNoMemoryBudget;
    EXPECT_EQ(Sculptor(scene).memoryBudget(), kNoMemoryBudget);
}

TEST_F(RunReportTest, OutgrownBudgetStopsTheRunWhereItsCheckpointResumesExactly)
{
    const Scene scene = denseScene("56M"); // the program's 48 MiB, and 8 MiB for the clay
    Sculptor sc(scene, 2);
    EXPECT_EQ(sc.memoryBudget(), uint64_t(56) << 20);
    sc.run();
    ASSERT_TRUE(sc.stopped());
    EXPECT_GT(sc.outgrewBudget(), sc.memoryBudget());
    EXPECT_TRUE(sc.frameOpen());
    writeClayFile(file("stopped.vdb"), *sc.mass(), sc.checkpointMeta());

    // Continued without a budget from where it stopped: the clay of a run that never stopped.
    Scene rest = scene;
    rest.clay.clear();
    rest.start = file("stopped.vdb");
    rest.memoryBudget = kNoMemoryBudget;
    Sculptor cont(rest, 1);
    cont.run();
    EXPECT_FALSE(cont.stopped());
    EXPECT_EQ(cont.outgrewBudget(), 0u);
    Scene whole = scene;
    whole.memoryBudget = kNoMemoryBudget;
    Sculptor unbroken(whole, 3);
    unbroken.run();
    EXPECT_EQ(contentHash(*cont.mass()), contentHash(*unbroken.mass()));
    EXPECT_EQ(cont.automaton().stepCount(), unbroken.automaton().stepCount());
}

TEST_F(RunReportTest, StopRequestIsNotTheBudget)
{
    Sculptor sc(denseScene("1G"), 2);
    sc.setStopRequest([] { return true; });
    sc.run();
    EXPECT_TRUE(sc.stopped());
    EXPECT_EQ(sc.outgrewBudget(), 0u);
}

} // namespace
