// Scene files (every malformed input refused with a clear error) and running scenes.
#include <vdbclay/IO.h>
#include <vdbclay/Metrics.h>
#include <vdbclay/Scene.h>
#include <vdbclay/Sculpt.h>

#include <openvdb/io/File.h>
#include <openvdb/openvdb.h>

#include <gtest/gtest.h>

#include "AllocationCounter.h"
#include "TempDirTest.h"

#include <cmath>
#include <cstdio>
#include <fstream>
#include <string>
#include <sys/stat.h>
#include <unistd.h>

using namespace vdbclay;

namespace {

class SceneTest : public vdbclay_test::TempDirTest {
protected:
    std::string write(const std::string& name, const std::string& text)
    {
        const std::string p = file(name);
        std::ofstream(p, std::ios::binary) << text;
        return p;
    }
};

/// Parses @a json and expects an Error whose message contains every one of @a needles.
void expectRefused(const std::string& json, std::initializer_list<const char*> needles)
{
    try {
        parseScene(json, "s.json", "");
        ADD_FAILURE() << "accepted: " << json;
    } catch (const Error& e) {
        const std::string msg = e.what();
        EXPECT_EQ(msg.rfind("s.json: ", 0), 0u) << "message must start with the file: " << msg;
        for (const char* n : needles)
            EXPECT_NE(msg.find(n), std::string::npos) << "\"" << n << "\" not in: " << msg;
        EXPECT_EQ(msg.find('\n'), std::string::npos) << "one line: " << msg;
    }
}

const std::string kPlate =
    R"({"shape": "box", "min": [0,10,0], "max": [9,12,9], "path": [{"translate": [0,-1,0], "frames": 3}]})";

std::string scene(const std::string& extra, const std::string& tools = "[" + kPlate + "]")
{
    // A field given in @a extra replaces the default's (a duplicate key is refused).
    const std::string tc = extra.find("\"threshold\"") == std::string::npos ? R"("threshold": 100, )" : "";
    return "{" + tc + R"("clay": [{"shape": "box", "min": [0,0,0], "max": [7,7,7], "mass": 90}], "tools": )" +
           tools + (extra.empty() ? "" : ", " + extra) + "}";
}

} // namespace

TEST_F(SceneTest, TheMinimumSceneParsesAsWritten)
{
    const Scene s = parseScene(R"({"dimensions": 3, "threshold": 1000, "rule": "prorata",
   "clay":  [{"shape": "box", "min": [0,0,0], "max": [31,31,31], "mass": 800}],
   "tools": [{"shape": "box", "min": [-8,32,-8], "max": [39,40,39], "path": [{"translate": [0,-1,0], "frames": 8}]}],
   "obstacles": [{"shape": "box", "min": [-64,-4,-64], "max": [96,-1,96]}],
   "settle": {"max_steps": 100000}})",
                               "min.json", "");
    EXPECT_EQ(s.dimensions, 3);
    EXPECT_EQ(s.rule.threshold, 1000);
    EXPECT_EQ(s.rule.rule, Rule::Prorata);
    ASSERT_EQ(s.clay.size(), 1u);
    EXPECT_EQ(s.clay[0].mass, 800);
    ASSERT_EQ(s.tools.size(), 1u);
    EXPECT_EQ(s.tools[0].pathFrames(), 8u);
    EXPECT_EQ(s.frames, 8u);
    EXPECT_EQ(s.settle.maxSteps, 100000u);
    const Pose p = s.tools[0].poseAt(3);
    EXPECT_EQ(p.translation, (Vec3{{0, -3, 0}}));
    EXPECT_EQ(s.tools[0].poseAt(100).translation, (Vec3{{0, -8, 0}})); // stays at the end of its path
}

TEST_F(SceneTest, DefaultSceneIsThePressedCube)
{
    const Scene s = defaultScene();
    EXPECT_EQ(s.frames, 8u);
    EXPECT_EQ(s.clay.size(), 1u);
    EXPECT_EQ(s.obstacles.size(), 1u);
}

TEST_F(SceneTest, EveryMalformedInputIsRefusedWithFieldAndReason)
{
    expectRefused("{\"threshold\": 100,\n \"clay\": [}", {"invalid JSON", "line 2"});
    expectRefused("", {"invalid JSON"});
    expectRefused("[1, 2]", {"expected an object"});
    expectRefused(scene(R"("colour": "red")"), {"colour", "unknown field"});
    expectRefused(scene(R"("rule": "rule4")"), {"rule", "rule4", "prorata"});
    expectRefused(scene(R"("threshold": 0)"), {"threshold", "Tc must be > 0"});
    expectRefused(scene(R"("threshold": -3)"), {"threshold", "> 0"});
    expectRefused(scene(R"("threshold": 1.5)"), {"threshold", "integer"});
    expectRefused(scene(R"("threshold": "big")"), {"threshold", "expected an integer, got string"});
    expectRefused(scene(R"("alpha": 1.0)"), {"alpha", "(0, 1)"});
    expectRefused(scene(R"("alpha": 0)"), {"alpha", "(0, 1)"});
    expectRefused(scene(R"("dimensions": 4)"), {"dimensions", "[2, 3]"});
    expectRefused(scene(R"("settle": {"max_step": 10})"), {"settle.max_step", "unknown field"});
    expectRefused(scene(R"("outputs": {"vdb": 3})"), {"outputs.vdb", "string"});
    // clay
    expectRefused(R"({"clay": [{"shape": "blob", "mass": 5}]})", {"clay[0].shape", "unknown shape \"blob\""});
    expectRefused(R"({"clay": [{"shape": "box", "min": [0,0,0], "max": [1,1,1], "mass": -5}]})",
                  {"clay[0].mass", "must be > 0"});
    expectRefused(R"({"clay": [{"shape": "box", "min": [0,0,0], "max": [1,1,1], "mass": 3000000000}]})",
                  {"clay[0].mass", "exceeds", "2147483647"});
    expectRefused(R"({"clay": [{"shape": "box", "min": [0,0,0], "max": [1,1,1]}]})",
                  {"clay[0]", "missing field \"mass\""});
    expectRefused(R"({"clay": [{"shape": "box", "min": [0,0,0], "max": [1,1,1], "mass": 5, "radius": 2}]})",
                  {"clay[0].radius", "unknown field for a box"});
    expectRefused(R"({"clay": [{"shape": "box", "min": [0,0], "max": [1,1,1], "mass": 5}]})",
                  {"clay[0].min", "array of 3 numbers"});
    expectRefused(R"({"clay": [{"shape": "box", "min": [5,0,0], "max": [1,1,1], "mass": 5}]})",
                  {"clay[0]", "min must not exceed max"});
    expectRefused(R"({"clay": {"shape": "box"}})", {"clay", "expected an array"});
    // tools
    expectRefused(scene("", R"([{"shape": "sphere", "center": [0,0,0], "radius": 0, "path": [{}]}])"),
                  {"tools[0].radius", "must be > 0"});
    expectRefused(
        scene("", R"([{"shape": "cylinder", "center": [0,0,0], "radius": 2, "height": 0, "path": [{}]}])"),
        {"tools[0].height", "must be > 0"});
    expectRefused(
        scene(
            "",
            R"([{"shape": "cylinder", "center": [0,0,0], "radius": 2, "height": 3, "axis": "w", "path": [{}]}])"),
        {"tools[0].axis"});
    expectRefused(scene("", R"([{"shape": "sphere", "center": [0,0,0], "radius": 2, "path": []}])"),
                  {"tools[0].path", "empty path"});
    expectRefused(scene("", R"([{"shape": "sphere", "center": [0,0,0], "radius": 2}])"),
                  {"tools[0]", "missing field \"path\""});
    expectRefused(
        scene("", R"([{"shape": "sphere", "center": [0,0,0], "radius": 2, "path": [{"frames": 0}]}])"),
        {"tools[0].path[0].frames", "[1, 1000000]"});
    expectRefused(
        scene("", R"([{"shape": "sphere", "center": [0,0,0], "radius": 2, "path": [{"move": [1,0,0]}]}])"),
        {"tools[0].path[0].move", "unknown field"});
    expectRefused(scene("", R"([{"shape": "sphere", "center": [0,0,"a"], "radius": 2, "path": [{}]}])"),
                  {"tools[0].center[2]", "expected a number"});
    // obstacles never move
    expectRefused(R"({"obstacles": [{"shape": "sphere", "center": [0,0,0], "radius": 2, "path": [{}]}]})",
                  {"obstacles[0].path", "never move"});
}

TEST_F(SceneTest, NonFiniteNumbersAreRefused)
{
    // JSON has no NaN; a number too large for a double is the way a non-finite value sneaks in.
    try {
        parseScene(scene("", R"([{"shape": "sphere", "center": [0,0,0], "radius": 1e999, "path": [{}]}])"),
                   "s.json", "");
        ADD_FAILURE() << "accepted an infinite radius";
    } catch (const Error& e) {
        const std::string m = e.what();
        EXPECT_TRUE(m.find("radius") != std::string::npos || m.find("invalid JSON") != std::string::npos)
            << m;
    }
}

TEST_F(SceneTest, BadFilesNamedInAScene)
{
    // a mesh that does not exist, a mesh that is not closed, a level set file that is not a .vdb
    const std::string open = write("open.obj", "v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 3\n");
    const std::string text = write("notvdb.vdb", "hello, I am not a vdb\n");
    auto refused = [&](const std::string& json, std::initializer_list<const char*> needles) {
        try {
            parseScene(json, "s.json", dir);
            ADD_FAILURE() << "accepted: " << json;
        } catch (const Error& e) {
            for (const char* n : needles)
                EXPECT_NE(std::string(e.what()).find(n), std::string::npos) << e.what();
        }
    };
    refused(R"({"clay": [{"shape": "mesh", "file": "missing.obj", "mass": 5}]})", {"clay[0]", "missing.obj"});
    refused(R"({"clay": [{"shape": "mesh", "file": "open.obj", "mass": 5}]})", {"clay[0]", "open.obj"});
    refused(R"({"clay": [{"shape": "levelset", "file": "notvdb.vdb", "mass": 5}]})",
            {"clay[0]", "notvdb.vdb"});
    // a start file or clay .vdb that is missing, not a .vdb, or lacks the grid: refused when the
    // scene is set up
    const Scene s1 = parseScene(R"({"start": "nothere.vdb"})", "s.json", dir);
    EXPECT_THROW(Sculptor{s1}, Error);
    const Scene s2 = parseScene(R"({"clay": [{"shape": "vdb", "file": "notvdb.vdb"}]})", "s.json", dir);
    EXPECT_THROW(Sculptor{s2}, Error);
    auto grid = openvdb::FloatGrid::create(0.f);
    grid->setName("mass");
    openvdb::io::File(dir + "/float.vdb").write({grid});
    const Scene s3 = parseScene(R"({"clay": [{"shape": "vdb", "file": "float.vdb"}]})", "s.json", dir);
    try {
        Sculptor sc(s3);
        ADD_FAILURE() << "accepted a float grid as clay";
    } catch (const Error& e) {
        EXPECT_NE(std::string(e.what()).find("float.vdb"), std::string::npos) << e.what();
    }
}

TEST_F(SceneTest, ClayInsideAnObstacleOrOverflowingIsRefused)
{
    const Scene inside = parseScene(R"({"clay": [{"shape": "box", "min": [0,0,0], "max": [3,3,3], "mass": 5}],
        "obstacles": [{"shape": "sphere", "center": [2,2,2], "radius": 1}]})",
                                    "s.json", "");
    try {
        Sculptor sc(inside);
        ADD_FAILURE();
    } catch (const Error& e) {
        EXPECT_NE(std::string(e.what()).find("obstacles[0]"), std::string::npos) << e.what();
    }
    const Scene over =
        parseScene(R"({"clay": [{"shape": "box", "min": [0,0,0], "max": [3,3,3], "mass": 2000000000},
                                              {"shape": "box", "min": [3,3,3], "max": [4,4,4], "mass": 2000000000}]})",
                   "s.json", "");
    try {
        Sculptor sc(over);
        ADD_FAILURE();
    } catch (const Error& e) {
        EXPECT_NE(std::string(e.what()).find("clay[1]"), std::string::npos) << e.what();
        EXPECT_NE(std::string(e.what()).find("(3, 3, 3)"), std::string::npos) << e.what();
    }
}

TEST_F(SceneTest, DefaultSceneRunsWithExactMassAndNoClayInsideThePlate)
{
    Sculptor sc(defaultScene());
    const int64_t m0 = totalMass(*sc.mass());
    EXPECT_EQ(m0, int64_t(32) * 32 * 32 * 800);
    const RunSummary s = sc.run();
    EXPECT_EQ(s.frames, 8u);
    EXPECT_EQ(s.massInitial, m0);
    EXPECT_EQ(s.massFinal, m0);
    EXPECT_TRUE(s.settled);
    EXPECT_EQ(s.framesUnsettled, 0u);
    EXPECT_EQ(s.massTrapped, 0);
    // The plate ends 8 voxels down: its lower face at y = 23.5, so no clay at y >= 24 under it.
    auto acc = sc.mass()->getConstAccessor();
    for (int x = -8; x <= 39; ++x)
        for (int z = -8; z <= 39; ++z)
            for (int y = 24; y <= 32; ++y)
                ASSERT_EQ(acc.getValue(openvdb::Coord(x, y, z)), 0) << x << "," << y << "," << z;
    // The pressed clay spread sideways beyond the original cube.
    bool wider = false;
    for (auto it = sc.mass()->tree().cbeginValueOn(); it && !wider; ++it)
        wider = it.getCoord().x() < 0;
    EXPECT_TRUE(wider);
}

TEST_F(SceneTest, ContinuingFromASavedRunIsIdenticalToAnUnbrokenRun)
{
    for (const char* rule : {"prorata", "bingham"}) {
        const std::string json = std::string(R"({"threshold": 100, "rule": ")") + rule + R"(", "seed": 3,
          "clay":  [{"shape": "box", "min": [0,0,0], "max": [11,11,11], "mass": 95}],
          "tools": [{"shape": "sphere", "center": [6,16,6], "radius": 4, "path": [{"translate": [0,-1,0], "frames": 6}]}],
          "obstacles": [{"shape": "box", "min": [-20,-3,-20], "max": [30,-1,30]}],
          "settle": {"max_steps": 5000}})";
        Sculptor whole(parseScene(json, "a.json", ""));
        whole.run();
        const uint64_t h = contentHash(*whole.mass());

        Sculptor first(parseScene(json, "a.json", ""));
        first.run(/*maxFrames=*/2);
        ClayMeta meta;
        meta.rule = first.scene().rule;
        meta.seed = first.scene().seed;
        meta.steps = first.automaton().stepCount();
        meta.frames = first.frame();
        const std::string saved = dir + "/part.vdb";
        writeClayFile(saved, *first.mass(), meta);

        Scene cont = parseScene(json, "a.json", "");
        cont.start = saved;
        Sculptor rest(cont);
        EXPECT_EQ(rest.frame(), 2u);
        rest.run();
        EXPECT_EQ(rest.frame(), 6u);
        EXPECT_EQ(contentHash(*rest.mass()), h) << rule;
        EXPECT_EQ(rest.automaton().stepCount(), whole.automaton().stepCount()) << rule;
    }
}

// ---- interrupts, checkpoints, the memory budget ---------------------------------------------------

namespace {

struct RunResult {
    uint64_t hash = 0, steps = 0, frames = 0;
    int checkpoints = 0, midFrame = 0; ///< checkpoints written, and those written inside a frame
};

RunResult unbroken(const Scene& s)
{
    Sculptor sc(s, 2);
    sc.run();
    return {contentHash(*sc.mass()), sc.automaton().stepCount(), sc.frame(), 0, 0};
}

/// Runs @a s, asking it to stop whenever another @a every steps have run; each time, writes the
/// checkpoint, then goes on in a new Sculptor started from it (as `vdbclay run --resume` does).
RunResult interrupted(Scene s, uint64_t every, const std::string& file)
{
    RunResult r;
    for (;;) {
        Sculptor sc(s, r.checkpoints % 2 ? 1 : 3); // thread counts differ too: same result
        const uint64_t stopAt = sc.automaton().stepCount() + every;
        sc.setStopRequest([&sc, stopAt] { return sc.automaton().stepCount() >= stopAt; });
        sc.run();
        if (!sc.stopped()) {
            EXPECT_TRUE(sc.done());
            r.hash = contentHash(*sc.mass());
            r.steps = sc.automaton().stepCount();
            r.frames = sc.frame();
            return r;
        }
        const ClayMeta m = sc.checkpointMeta();
        EXPECT_EQ(m.frameSteps > 0, sc.frameOpen());
        writeClayFile(file, *sc.mass(), m);
        ++r.checkpoints;
        if (m.frameSteps) ++r.midFrame;
        s.start = file;
        if (r.checkpoints > 100000) {
            ADD_FAILURE() << "no end";
            return r;
        }
    }
}

} // namespace

TEST_F(SceneTest, AStoppedRunResumedFromItsCheckpointIsIdenticalToAnUnbrokenRun)
{
    struct Case {
        const char* name;
        std::string json;
        std::vector<uint64_t> every;
    };
    const std::vector<Case> cases = {
        // tools, obstacles, and a step budget that cuts frames short
        {"press",
         R"({"threshold": 100, "seed": 5,
            "clay":  [{"shape": "box", "min": [0,0,0], "max": [11,11,11], "mass": 95}],
            "tools": [{"shape": "sphere", "center": [6,16,6], "radius": 4, "path": [{"translate": [0,-1,0], "frames": 6}]}],
            "obstacles": [{"shape": "box", "min": [-20,-3,-20], "max": [30,-1,30]}],
            "settle": {"max_steps": 30}})",
         {9, 30, 31}},
        // no tools: frames only continue settling, so quiet steps carry across frame boundaries
        {"no tools",
         R"({"threshold": 100, "rule": "bingham", "frames": 6,
            "clay":  [{"shape": "box", "min": [0,0,0], "max": [5,5,5], "mass": 400}],
            "obstacles": [{"shape": "box", "min": [-20,-3,-20], "max": [30,-1,30]}],
            "settle": {"max_steps": 25}})",
         {1, 24, 26}},
        // 2D, arata, a tolerance
        {"2d",
         R"({"dimensions": 2, "threshold": 100, "rule": "arata", "alpha": 0.3,
            "clay":  [{"shape": "box", "min": [0,0], "max": [15,15], "mass": 90}],
            "tools": [{"shape": "box", "min": [-4,16], "max": [19,18], "path": [{"translate": [0,-1], "frames": 5}]}],
            "obstacles": [{"shape": "box", "min": [-30,-3], "max": [40,-1]}],
            "settle": {"max_steps": 1000, "tolerance": 40}})",
         {13, 50}},
    };
    // About 100 checkpoints, each ~0.1 s (building the surface level set); on tmpfs where there is
    // one, as fsync on a loaded disk costs up to 0.5 s a file.
    const std::string ckpt = (::access("/dev/shm", W_OK) == 0 ? std::string("/dev/shm") : dir) +
                             "/vdbclay-test-ckpt-" + std::to_string(::getpid()) + ".vdb";
    for (const Case& c : cases) {
        const Scene s = parseScene(c.json, c.name, "");
        const RunResult whole = unbroken(s);
        for (uint64_t every : c.every) {
            const RunResult r = interrupted(s, every, ckpt);
            EXPECT_EQ(r.hash, whole.hash) << c.name << ", stopped every " << every << " steps";
            EXPECT_EQ(r.steps, whole.steps) << c.name << ", stopped every " << every << " steps";
            EXPECT_EQ(r.frames, whole.frames) << c.name;
            EXPECT_GT(r.checkpoints, 0) << c.name << ", every " << every;
            EXPECT_GT(r.midFrame, 0) << c.name << ", every " << every;
        }
    }
    std::remove(ckpt.c_str());
}

TEST_F(SceneTest, StoppingWaitsForAStepThatResumesExactlyAndSavesTheOpenFrame)
{
    const Scene s = parseScene(R"({"threshold": 100, "seed": 1,
        "clay":  [{"shape": "box", "min": [0,0,0], "max": [11,11,11], "mass": 95}],
        "tools": [{"shape": "box", "min": [-2,12,-2], "max": [13,14,13], "path": [{"translate": [0,-1,0], "frames": 3}]}],
        "settle": {"max_steps": 100000}})",
                               "s.json", "");
    Sculptor sc(s);
    bool stop = false;
    sc.setStopRequest([&] { return stop; });
    // A stop request before the first frame: nothing runs.
    stop = true;
    RunSummary r = sc.run();
    EXPECT_TRUE(sc.stopped());
    EXPECT_EQ(r.frames, 0u);
    EXPECT_EQ(sc.automaton().stepCount(), 0u);
    // During frame 1: it stops after its first step (which moved clay), the frame left open.
    FrameReport f = sc.runFrame();
    EXPECT_FALSE(f.finished);
    EXPECT_TRUE(sc.stopped());
    EXPECT_TRUE(sc.frameOpen());
    // Its first (even) step changes nothing: the overloaded layer y = 10 meets only the plate's
    // cells at y = 11 in even blocks. A resumed automaton would not know that step was quiet (and
    // would settle one step later), so the stop waits for step 2, which moves clay.
    EXPECT_EQ(f.settle.steps, 2u);
    EXPECT_EQ(f.settle.blocksUpdated > 0, true);
    EXPECT_EQ(sc.frame(), 0u);
    const ClayMeta m = sc.checkpointMeta();
    EXPECT_EQ(m.frames, 0u);
    EXPECT_EQ(m.frameSteps, 2u);
    EXPECT_EQ(m.steps, 2u);
    // The file records it; a Sculptor started from it reopens frame 1 without pushing again.
    const std::string file = dir + "/open.vdb";
    writeClayFile(file, *sc.mass(), m);
    EXPECT_EQ(readClayFile(file).meta.frameSteps, 2u);
    Scene cont = s;
    cont.start = file;
    Sculptor rest(cont);
    EXPECT_TRUE(rest.frameOpen());
    EXPECT_EQ(rest.frame(), 0u);
    const FrameReport g = rest.runFrame();
    EXPECT_TRUE(g.finished);
    EXPECT_EQ(g.push.voxelsPushed, 0u);
    EXPECT_EQ(rest.frame(), 1u);
    // Without a stop request the first Sculptor finishes the frame the same way.
    stop = false;
    const FrameReport h = sc.runFrame();
    EXPECT_TRUE(h.finished);
    EXPECT_EQ(h.settle.steps, g.settle.steps);
    EXPECT_EQ(contentHash(*sc.mass()), contentHash(*rest.mass()));
    // A frame boundary is a checkpoint without frameSteps (0 is not written at all).
    EXPECT_EQ(sc.checkpointMeta().frameSteps, 0u);
}

// The Sculptor settles through Automaton::settle(SettleOptions): a stopped frame says Stopped, and
// a frame stopped and resumed in the middle keeps settle's no-room schedule in frame steps. The
// 2D piston of TestSculptor (clay pressed into a closed tube with no room) stops its first frame
// with NoRoom after exactly 8192 steps; stopped at step 5000 and resumed from the checkpoint, the
// resumed part runs the other 3192 steps and stops with NoRoom at the same step, same clay.
TEST_F(SceneTest, AStoppedFrameSaysStoppedAndKeepsTheNoRoomScheduleWhenResumed)
{
    const std::string json = R"({"dimensions": 2, "threshold": 100, "rule": "prorata",
        "clay": [{"shape": "box", "min": [0,0], "max": [7,3], "mass": 100}],
        "tools": [{"shape": "box", "min": [0,4], "max": [7,30], "path": [{"translate": [0,-1], "frames": 4}]}],
        "obstacles": [{"shape": "box", "min": [-3,-3], "max": [10,-1]}, {"shape": "box", "min": [-3,0], "max": [-1,40]},
                      {"shape": "box", "min": [8,0], "max": [10,40]}]})";
    const Scene s = parseScene(json, "piston.json", "");
    Sculptor whole(s, 1);
    const FrameReport w = whole.runFrame();
    ASSERT_TRUE(w.finished);
    ASSERT_EQ(w.settle.reason, StopReason::NoRoom);
    ASSERT_EQ(w.settle.steps, 8192u);

    Sculptor first(s, 2);
    first.setStopRequest([&first] { return first.automaton().stepCount() >= 5000; });
    const FrameReport a = first.runFrame();
    EXPECT_FALSE(a.finished);
    EXPECT_EQ(a.settle.reason, StopReason::Stopped);
    EXPECT_EQ(a.settle.steps, 5000u);
    EXPECT_EQ(first.checkpointMeta().frameSteps, 5000u);
    const std::string file = dir + "/piston.vdb";
    writeClayFile(file, *first.mass(), first.checkpointMeta());

    Scene cont = s;
    cont.start = file;
    Sculptor rest(cont, 3);
    const FrameReport b = rest.runFrame();
    EXPECT_TRUE(b.finished);
    EXPECT_EQ(b.settle.reason, StopReason::NoRoom);
    EXPECT_EQ(b.settle.steps, 8192u - 5000u);
    EXPECT_EQ(rest.automaton().stepCount(), 8192u);
    EXPECT_EQ(b.settle.residualOverload, w.settle.residualOverload);
    EXPECT_EQ(contentHash(*rest.mass()), contentHash(*whole.mass()));
}

TEST_F(SceneTest, AnOpenFrameIsOnlyFinishedByTheSceneThatBeganIt)
{
    const std::string json = R"({"threshold": 100, "seed": 1,
        "clay":  [{"shape": "box", "min": [0,0,0], "max": [11,11,11], "mass": 95}],
        "tools": [{"shape": "box", "min": [-2,12,-2], "max": [13,14,13], "path": [{"translate": [0,-1,0], "frames": 3}]}]})";
    Sculptor sc(parseScene(json, "s.json", ""));
    sc.setStopRequest([] { return true; });
    sc.runFrame();
    const std::string file = dir + "/open.vdb";
    writeClayFile(file, *sc.mass(), sc.checkpointMeta());
    Scene other = parseScene(json, "s.json", "");
    other.start = file;
    other.seed = 2;
    try {
        Sculptor bad(other);
        ADD_FAILURE() << "resumed an open frame with another seed";
    } catch (const Error& e) {
        const std::string m = e.what();
        EXPECT_NE(m.find("during frame 1"), std::string::npos) << m;
        EXPECT_NE(m.find("seed 1"), std::string::npos) << m;
        EXPECT_NE(m.find("has 2"), std::string::npos) << m;
    }
    other.seed = 1;
    other.frames = 0; // fewer frames than the open one
    EXPECT_THROW(Sculptor{other}, Error);
}

TEST_F(SceneTest, ByteSizesParseExactlyAndNonsenseIsRefused)
{
    EXPECT_EQ(parseByteSize("8G"), uint64_t(8) << 30);
    EXPECT_EQ(parseByteSize("512M"), uint64_t(512) << 20);
    EXPECT_EQ(parseByteSize("1.5GiB"), uint64_t(3) << 29);
    EXPECT_EQ(parseByteSize("64k"), uint64_t(64) << 10);
    EXPECT_EQ(parseByteSize("2 TB"), uint64_t(2) << 40);
    EXPECT_EQ(parseByteSize("1000000"), 1000000u);
    EXPECT_EQ(parseByteSize("none"), kNoMemoryBudget);
    EXPECT_EQ(parseByteSize("Unlimited"), kNoMemoryBudget);
    for (const char* bad : {"", "G", "abc", "0", "0.1", "-5G", "5X", "1e30G", "8GG"}) {
        EXPECT_THROW(parseByteSize(bad), Error) << bad;
    }
    EXPECT_EQ(formatBytes(900), "900 B");
    EXPECT_EQ(formatBytes(uint64_t(3) << 29), "1.50 GiB");
    EXPECT_EQ(formatBytes(uint64_t(512) << 20), "512 MiB");
    // In a scene: a size string or a byte count.
    EXPECT_EQ(parseScene(R"({"memory_budget": "2G"})", "s.json", "").memoryBudget, uint64_t(2) << 30);
    EXPECT_EQ(parseScene(R"({"memory_budget": 4096})", "s.json", "").memoryBudget, 4096u);
    EXPECT_EQ(parseScene(R"({"memory_budget": "none"})", "s.json", "").memoryBudget, kNoMemoryBudget);
    EXPECT_EQ(parseScene("{}", "s.json", "").memoryBudget, 0u);
    expectRefused(R"({"memory_budget": "lots"})", {"memory_budget", "\"lots\" is not a size"});
    expectRefused(R"({"memory_budget": 0})", {"memory_budget", "[1, "});
    expectRefused(R"({"memory_budget": true})", {"memory_budget", "expected an integer"});
}

TEST_F(SceneTest, MemoryEstimateCountsLeavesOfTheShapesAndTheirGrowth)
{
    // A 32^3 cube is 4^3 = 64 slots, all of them tiles; the estimate counts the 56 whose centre lies
    // within a leaf's half-diagonal of its surface. The floor -64..96 x -4..-1: 21 x 1 x 21 leaves.
    const Scene still =
        parseScene(R"({"clay": [{"shape": "box", "min": [0,0,0], "max": [31,31,31], "mass": 800}],
        "obstacles": [{"shape": "box", "min": [-64,-4,-64], "max": [96,-1,96]}]})",
                   "s.json", "");
    const MemoryEstimate a = estimateSceneMemory(still);
    EXPECT_EQ(a.clayLeaves, 56u);
    EXPECT_EQ(a.clayLeavesGrown, 56u); // at 800 < Tc with no tool it never moves
    EXPECT_EQ(a.clayVoxels, 56u * 512 + 32u * 32 * 32);
    EXPECT_EQ(a.obstacleLeaves, 21u * 21u);
    EXPECT_EQ(a.toolVoxels, 0u);
    EXPECT_GE(a.clayBytes, 56u * (512u * 4u));
    EXPECT_EQ(a.total(), a.processBytes + a.clayBytes + a.obstacleBytes + a.toolBytes + a.automatonBytes +
                             std::max(a.pushBytes + a.transportBytes, a.outputBytes));

    // The default scene: the plate -8..39 x 32..40 x -8..39 (48 x 9 x 48 voxels) sweeps down to
    // y = 24. Grown by a leaf, the clay covers leaves -1..4 on every axis (216) and the sweep
    // -16..47 x 16..48 x -16..47, leaves -2..5 x 2..6 x -2..5 (320); they share -1..4 x 2..4 x
    // -1..4 (108): 428 leaves.
    const Scene def = defaultScene();
    const MemoryEstimate d = estimateSceneMemory(def);
    EXPECT_EQ(d.clayLeaves, 56u);
    EXPECT_EQ(d.toolVoxels, 48u * 9u * 48u);
    EXPECT_EQ(d.clayLeavesGrown, 428u);
    // Honest: the run stays inside the estimate, leaves and bytes.
    Sculptor sc(def);
    sc.run();
    EXPECT_LE(sc.mass()->tree().leafCount(), d.clayLeavesGrown);
    EXPECT_LE(sc.mass()->memUsage(), d.clayBytes);
    EXPECT_LE(sc.automaton().obstacles()->memUsage(), d.obstacleBytes + d.toolBytes);

    // Two lumps far apart are two areas, not one huge box: each 3^3 leaves once grown.
    // (Over Tc, so that they move: clay at most Tc that no tool reaches keeps its leaves.)
    const Scene apart =
        parseScene(R"({"clay": [{"shape": "box", "min": [0,0,0], "max": [7,7,7], "mass": 1200},
        {"shape": "box", "min": [100000,0,0], "max": [100007,7,7], "mass": 1200}]})",
                   "s.json", "");
    EXPECT_EQ(estimateSceneMemory(apart).clayLeavesGrown, 2u * 27u);
    // No more leaves than units of mass: each leaf holds at least one.
    const Scene light = parseScene(R"({"clay": [{"shape": "box", "min": [0,0,0], "max": [0,0,0], "mass": 5}],
        "tools": [{"shape": "box", "min": [0,0,0], "max": [800,800,800], "path": [{"translate": [1,0,0]}]}]})",
                                   "s.json", "");
    EXPECT_EQ(estimateSceneMemory(light).clayLeavesGrown, 5u);
    // 2D: one layer of leaves.
    const Scene flat = parseScene(
        R"({"dimensions": 2, "clay": [{"shape": "box", "min": [0,0], "max": [15,15], "mass": 1200}]})",
        "s.json", "");
    EXPECT_EQ(estimateSceneMemory(flat).clayLeaves, 4u);
    EXPECT_EQ(estimateSceneMemory(flat).clayLeavesGrown, 16u);
}

TEST_F(SceneTest, ASceneOverItsMemoryBudgetIsRefusedBeforeAnyWork)
{
    // A sphere of radius 3000 voxels: about 1.4e10 voxels of clay, far over 1 GiB.
    Scene big = parseScene(R"({"memory_budget": "1G",
        "clay": [{"shape": "sphere", "center": [0,0,0], "radius": 3000, "mass": 800}]})",
                           "big.json", "");
    const MemoryEstimate e = estimateSceneMemory(big);
    EXPECT_GT(e.total(), uint64_t(1) << 40);
    const int64_t newCalls0 = alloc_counter::newCalls.load();
    try {
        Sculptor sc(big);
        ADD_FAILURE() << "accepted";
    } catch (const Error& err) {
        const std::string m = err.what();
        EXPECT_EQ(m.rfind("big.json: needs about ", 0), 0u) << m;
        EXPECT_NE(m.find("memory budget of 1.00 GiB"), std::string::npos) << m;
        EXPECT_NE(m.find(formatBytes(e.total())), std::string::npos) << m;
        EXPECT_NE(m.find("leaves"), std::string::npos) << m;
        EXPECT_EQ(m.find('\n'), std::string::npos) << m;
    }
    // Refused from the bounds alone: no clay was built. Building it would allocate a node for each of
    // its ~2.7e7 leaves; the refusal takes a few hundred allocations (strings, the scene's shapes).
    EXPECT_LT(alloc_counter::newCalls.load() - newCalls0, 10000);
    EXPECT_THROW(checkMemoryBudget(big), Error);
    // The default budget applies too, and a small scene passes it.
    big.memoryBudget = 0;
    EXPECT_GT(defaultMemoryBudget(), uint64_t(64) << 20);
    if (e.total() > defaultMemoryBudget()) {
        EXPECT_THROW(checkMemoryBudget(big), Error);
    }
    EXPECT_NO_THROW(checkMemoryBudget(defaultScene()));
    // "none" lifts it (only checked, not run).
    big.memoryBudget = kNoMemoryBudget;
    EXPECT_NO_THROW(checkMemoryBudget(big));
    // The default scene under a budget just below its estimate is refused, at it accepted.
    Scene def = defaultScene();
    def.memoryBudget = estimateSceneMemory(def).total() - 1;
    EXPECT_THROW(Sculptor{def}, Error);
    def.memoryBudget += 1;
    EXPECT_NO_THROW(Sculptor{def});
}

// ---- bad input in scene files, and the memory estimate from what is built ------------------------

TEST_F(SceneTest, TheOutputsGridsNameWhatTheVdbHolds)
{
    EXPECT_EQ(clayGridsName(parseScene(scene(""), "s.json", "").outputs.grids), "mass,density,surface");
    const Scene s =
        parseScene(scene(R"("outputs": {"vdb": "a.vdb", "grids": ["surface", "mass"]})"), "s.json", "");
    EXPECT_EQ(clayGridsName(s.outputs.grids), "mass,surface");
    expectRefused(
        scene(R"("outputs": {"grids": []})"),
        {"outputs.grids: expected a non-empty array of grid names (mass, density, surface), got []"});
    expectRefused(
        scene(R"("outputs": {"grids": "mass"})"),
        {"outputs.grids: expected a non-empty array of grid names (mass, density, surface), got string"});
    expectRefused(scene(R"("outputs": {"grids": ["mass", 3]})"), {"outputs.grids[1]: expected a string"});
    expectRefused(scene(R"("outputs": {"grids": ["mass", "fog"]})"),
                  {"outputs.grids: \"fog\" is not a grid of a clay file (mass, density or surface)"});
    expectRefused(scene(R"("outputs": {"grids": ["mass,density"]})"),
                  {"outputs.grids[0]: \"mass,density\" is not a grid of a clay file"});
    expectRefused(scene(R"("outputs": {"grids": ["density", "density"]})"),
                  {"outputs.grids: grid \"density\" is named twice"});
}

TEST_F(SceneTest, TypesDuplicatesAndEmptyStringsAreRefusedWithTheField)
{
    expectRefused(R"({"description": {"a": [1]}})", {"description: expected a string, got object"});
    expectRefused(R"({"comment": 5})", {"comment: expected a string, got number"});
    expectRefused(R"({"clay": [{"shape": "box", "min": [0,0,0], "max": [1,1,1], "mass": 5, "name": [1]}]})",
                  {"clay[0].name: expected a string, got array"});
    // nlohmann keeps the last duplicate: Tc would silently be 5.
    expectRefused(R"({"threshold": 1000, "threshold": 5})", {"threshold: duplicate field"});
    expectRefused(R"({"settle": {"max_steps": 5, "max_steps": 6}})", {"max_steps: duplicate field"});
    // The same key in different objects is fine.
    EXPECT_NO_THROW(parseScene(R"({"settle": {"max_steps": 5}, "outputs": {"vdb": "a.vdb"},
        "clay": [{"shape": "box", "min": [0,0,0], "max": [1,1,1], "mass": 5},
                 {"shape": "box", "min": [5,0,0], "max": [6,1,1], "mass": 5}]})",
                               "s.json", ""));
    expectRefused(R"({"start": ""})", {"start: expected a non-empty string"});
    expectRefused(R"({"outputs": {"vdb": ""}})", {"outputs.vdb: expected a non-empty string"});
    expectRefused(R"({"rule": ""})", {"rule: expected a non-empty string"});
    expectRefused(R"({"clay": [{"shape": "mesh", "file": "", "mass": 5}]})",
                  {"clay[0].file: expected a non-empty string"});
}

TEST_F(SceneTest, StartAndClayTogetherAreRefused)
{
    expectRefused(
        R"({"start": "a.vdb", "clay": [{"shape": "box", "min": [0,0,0], "max": [1,1,1], "mass": 5}]})",
        {"start: a scene starts either from a file", "not both"});
    // An empty clay list beside a start file says nothing contrary.
    EXPECT_EQ(parseScene(R"({"start": "a.vdb", "clay": []})", "s.json", "").start, "a.vdb");
}

TEST_F(SceneTest, NumbersOutOfRangeNameTheirField)
{
    expectRefused(R"({"voxel_size": 1e-300})",
                  {"voxel_size: expected a number in [0.0001, 1e+06]", "1e-300"});
    expectRefused(R"({"voxel_size": 1e300})", {"voxel_size: expected a number in"});
    EXPECT_EQ(parseScene(R"({"voxel_size": 0.001})", "s.json", "").voxelSize, 0.001);
    const std::string box = R"("shape": "box", "min": [0,10,0], "max": [4,12,4])";
    expectRefused(R"({"tools": [{)" + box + R"(, "path": [{"rotate": [1e308,0,0], "frames": 2}]}]})",
                  {"tools[0].path[0].rotate[0]: the tool turns at most 1e+09 degrees"});
    expectRefused(
        R"({"tools": [{)" + box + R"(, "path": [{"translate": [0,3e9,0]}]}]})",
        {"tools[0].path[0].translate[1]: the tool's movement along its path so far must lie within +-2^30"});
    // Movements add up over segments and frames.
    expectRefused(R"({"tools": [{)" + box +
                      R"(, "path": [{"translate": [6e8,0,0]}, {"translate": [1e6,0,0], "frames": 600}]}]})",
                  {"tools[0].path[1].translate[0]"});
    expectRefused(R"({"tools": [{)" + box + R"(, "pivot": [0,5e9,0], "path": [{"translate": [0,-1,0]}]}]})",
                  {"tools[0].pivot[1]: a pivot must lie within +-2^30"});
}

TEST_F(SceneTest, In2DToolsAndObstaclesStayInTheZ0Layer)
{
    expectRefused(
        R"({"dimensions": 2, "tools": [{"shape": "box", "min": [0,10,3], "max": [4,12,5], "path": [{"translate": [0,-1]}]}]})",
        {"tools[0]: a 2D scene happens in the z = 0 layer, but this box holds no voxel there"});
    // Bounds a voxel loose do not let a box at z 1..5 pass.
    expectRefused(R"({"dimensions": 2, "obstacles": [{"shape": "box", "min": [0,0,1], "max": [4,4,5]}]})",
                  {"obstacles[0]: a 2D scene happens in the z = 0 layer"});
    expectRefused(
        R"({"dimensions": 2, "tools": [{"shape": "box", "min": [0,10,0], "max": [4,12,0], "path": [{"translate": [0,0,1]}]}]})",
        {"tools[0].path[0].translate[2]: a 2D scene's tools move in the z = 0 plane"});
    expectRefused(
        R"({"dimensions": 2, "tools": [{"shape": "box", "min": [0,10,0], "max": [4,12,0], "path": [{"rotate": [0,30,0]}]}]})",
        {"tools[0].path[0].rotate: a 2D scene's tools turn about z only"});
    expectRefused(R"({"dimensions": 2, "obstacles": [{"shape": "sphere", "center": [0,0,9], "radius": 2}]})",
                  {"obstacles[0]: a 2D scene happens in the z = 0 layer"});
    // Turning about z, moving in x and y, and shapes that cross z = 0 are what 2D scenes do.
    EXPECT_NO_THROW(parseScene(R"({"dimensions": 2,
        "tools": [{"shape": "box", "min": [0,10,-1], "max": [4,12,1], "path": [{"translate": [1,-1], "rotate": [0,0,5]}]}],
        "obstacles": [{"shape": "sphere", "center": [0,0,0.5], "radius": 2}]})",
                               "s.json", ""));
}

TEST_F(SceneTest, SceneFilesThatAreNotFilesAreRefusedBeforeReadingFar)
{
    const std::string dir = "/tmp/vdbclay-scene-dir-" + std::to_string(::getpid());
    ASSERT_EQ(::mkdir(dir.c_str(), 0755), 0);
    try {
        loadScene(dir);
        ADD_FAILURE() << "accepted a directory";
    } catch (const Error& e) {
        EXPECT_NE(std::string(e.what()).find("is a directory, expected a scene file"), std::string::npos)
            << e.what();
    }
    ::rmdir(dir.c_str());
    // /dev/zero never ends: refused after 16 MiB, not after memory runs out.
    try {
        loadScene("/dev/zero");
        ADD_FAILURE() << "accepted /dev/zero";
    } catch (const Error& e) {
        EXPECT_NE(std::string(e.what()).find("/dev/zero: more than 16.0 MiB"), std::string::npos) << e.what();
    }
}

TEST_F(SceneTest, MemoryEstimateCountsSharedNodesAndLeavesNotBoxes)
{
    // 20000 copies of one static tool: their cells are one set of cells (it was "122 GiB").
    std::string tools;
    for (int i = 0; i < 20000; ++i) {
        tools += std::string(i ? "," : "") +
                 R"({"shape": "box", "min": [0,10,0], "max": [9,12,9], "path": [{"translate": [0,0,0]}]})";
    }
    const Scene copies =
        parseScene(R"({"clay": [{"shape": "box", "min": [0,0,0], "max": [7,7,7], "mass": 800}],
        "tools": [)" + tools +
                       "]}",
                   "s.json", "");
    const MemoryEstimate c = estimateSceneMemory(copies);
    EXPECT_LE(c.toolVoxels, 12u * 5u * 12u); // one tool's bounds (tightened while the budget lasts)
    EXPECT_LE(c.toolSlots, 3u * 1u * 3u);
    EXPECT_LT(c.total() - c.processBytes, uint64_t(16) << 20) << c.describe();

    // 20000 one-voxel boxes 10 voxels apart: 20000 leaves, not 20000 upper nodes (it was "566 GiB").
    std::string boxes;
    for (int i = 0; i < 20000; ++i) {
        const std::string x = std::to_string(10 * i);
        boxes += std::string(i ? "," : "") + R"({"shape": "box", "min": [)" + x + ",0,0], \"max\": [" + x +
                 R"(,0,0], "mass": 800})";
    }
    const Scene dots = parseScene(R"({"clay": [)" + boxes + "]}", "s.json", "");
    const MemoryEstimate d = estimateSceneMemory(dots);
    EXPECT_EQ(d.clayLeaves, 20000u);
    EXPECT_LT(d.total(), uint64_t(1) << 30) << d.describe();

    // Clay at most Tc per voxel that no tool reaches never moves: its leaves are all it needs (the
    // 56 of its 64 slots near its surface: the inside is tiles).
    const Scene still = parseScene(
        R"({"clay": [{"shape": "box", "min": [0,0,0], "max": [31,31,31], "mass": 800}]})", "s.json", "");
    EXPECT_EQ(estimateSceneMemory(still).clayLeavesGrown, 56u);
    // ... unless shapes overlap and add up over Tc.
    const Scene stacked =
        parseScene(R"({"clay": [{"shape": "box", "min": [0,0,0], "max": [31,31,31], "mass": 800},
        {"shape": "box", "min": [0,0,0], "max": [31,31,31], "mass": 800}]})",
                   "s.json", "");
    EXPECT_EQ(estimateSceneMemory(stacked).clayLeavesGrown, 216u);

    // A 2x2x2 box at 2^31 - 1 per cell spreads over 8 * (2^31 - 1) / 1000 voxels at least (it was
    // estimated at 10.6 MiB, and peaked at 300-420 MB): 2 * ceil(17179870 / 512) leaves.
    const Scene dense = parseScene(
        R"({"clay": [{"shape": "box", "min": [0,0,0], "max": [1,1,1], "mass": 2147483647}]})", "s.json", "");
    const MemoryEstimate e = estimateSceneMemory(dense);
    EXPECT_EQ(e.clayLeavesGrown, 2u * ((17179870u + 511u) / 512u));
    EXPECT_GT(e.total(), uint64_t(40) << 20);
}

TEST_F(SceneTest, MemoryEstimateOfFileClayCountsItsRealLeaves)
{
    // 2000 voxels scattered over +-2^29: 2000 leaves (it was "13.4 EiB", from their bounding box).
    const std::string path = "/tmp/vdbclay-scattered-" + std::to_string(::getpid()) + ".vdb";
    auto g = openvdb::Int32Grid::create(0);
    g->setName("mass");
    auto acc = g->getAccessor();
    for (int i = 0; i < 2000; ++i) {
        const int64_t v = int64_t((uint64_t(i) * 2654435761u) % (1u << 30)) - (1 << 29);
        acc.setValueOn(
            openvdb::Coord(int32_t(v), int32_t((v * 7) % (1 << 29)), int32_t((v * 13) % (1 << 29))), 500);
    }
    // Written by OpenVDB alone: writeClayFile's surface level set of 2000 isolated voxels spread
    // over 2^30 takes minutes (levelSetRebuild), and only the mass grid matters here.
    {
        openvdb::io::File out(path);
        out.write({g});
        out.close();
    }
    const Scene sc = parseScene(R"({"clay": [{"shape": "vdb", "file": ")" + path + R"("}]})", "s.json", "");
    const MemoryEstimate e = estimateSceneMemory(sc);
    EXPECT_EQ(e.clayLeaves, g->tree().leafCount());
    // Each scattered voxel really holds its own internal nodes (about 300 KiB): the grid alone is
    // about 600 MB. The estimate counts those nodes, twice for growth, and the output grids.
    EXPECT_GE(e.clayBytes, uint64_t(g->memUsage()));
    EXPECT_LT(e.total(), uint64_t(16) << 30) << e.describe();
    std::remove(path.c_str());
}

namespace {

/// The clay after running @a json to the end (2 threads): its content hash.
uint64_t hashAfterRun(const std::string& json, const std::string& baseDir = "")
{
    Sculptor s(parseScene(json, "s.json", baseDir), 2);
    s.run();
    return contentHash(*s.mass());
}

} // namespace

// "units": "world": the same scene given in world units, y up or z up (Blender's coordinates), at
// voxel size 0.5, is the voxel-index scene: the same clay, tools, turns, paths and obstacles, hash
// for hash after the run.
TEST_F(SceneTest, WorldUnitsAreTheSameScene)
{
    const std::string voxels = R"({"threshold": 1000,
        "clay": [{"shape": "box", "min": [0,0,0], "max": [9,9,9], "mass": 800}],
        "tools": [{"shape": "cylinder", "center": [5,13,5], "radius": 3, "height": 4, "axis": "x",
                   "transform": {"rotate": [0,30,0], "pivot": [5,13,5]},
                   "path": [{"translate": [0,-1,0], "rotate": [0,10,0], "frames": 3}]}],
        "obstacles": [{"shape": "cylinder", "center": [5,-2,5], "radius": 20, "height": 2}]})";
    // Up z: index (x, y, z) is world (x, -z, y) x 0.5.
    const std::string worldZ = R"({"threshold": 1000, "units": "world", "up": "z", "voxel_size": 0.5,
        "clay": [{"shape": "box", "min": [0,-4.5,0], "max": [4.5,0,4.5], "mass": 800}],
        "tools": [{"shape": "cylinder", "center": [2.5,-2.5,6.5], "radius": 1.5, "height": 2, "axis": "x",
                   "transform": {"rotate": [0,0,30], "pivot": [2.5,-2.5,6.5]},
                   "path": [{"translate": [0,0,-0.5], "rotate": [0,0,10], "frames": 3}]}],
        "obstacles": [{"shape": "cylinder", "center": [2.5,-2.5,-1], "radius": 10, "height": 1}]})";
    // Up y: world units are voxel indices x 0.5.
    const std::string worldY = R"({"threshold": 1000, "units": "world", "voxel_size": 0.5,
        "clay": [{"shape": "box", "min": [0,0,0], "max": [4.5,4.5,4.5], "mass": 800}],
        "tools": [{"shape": "cylinder", "center": [2.5,6.5,2.5], "radius": 1.5, "height": 2, "axis": "x",
                   "transform": {"rotate": [0,30,0], "pivot": [2.5,6.5,2.5]},
                   "path": [{"translate": [0,-0.5,0], "rotate": [0,10,0], "frames": 3}]}],
        "obstacles": [{"shape": "cylinder", "center": [2.5,-1,2.5], "radius": 10, "height": 1}]})";
    const Scene z = parseScene(worldZ, "s.json", "");
    ASSERT_EQ(z.tools.size(), 1u);
    EXPECT_EQ(z.tools[0].path[0].translate, (Vec3{{0, -1, 0}}));
    EXPECT_EQ(z.tools[0].path[0].rotateDeg, (Vec3{{0, 10, 0}}));
    EXPECT_EQ(z.tools[0].shape.shape->bounds().min,
              parseScene(voxels, "s.json", "").tools[0].shape.shape->bounds().min);
    const uint64_t expected = hashAfterRun(voxels);
    EXPECT_EQ(hashAfterRun(worldZ), expected);
    EXPECT_EQ(hashAfterRun(worldY), expected);
    // "voxels" is the default, and may be said.
    EXPECT_EQ(hashAfterRun(voxels.substr(0, 1) + R"("units": "voxels", )" + voxels.substr(1)), expected);
}

TEST_F(SceneTest, WorldUnitsRefusals)
{
    expectRefused(scene(R"("units": "metres")"), {"units", "expected \"voxels\"", "\"metres\""});
    expectRefused(scene(R"("units": "world", "dimensions": 2, "up": "z")"), {"units", "2D", "\"up\": \"y\""});
    const std::string turning =
        R"([{"shape": "box", "min": [0,10,0], "max": [9,12,9], "path": [{"rotate": [0,5,5], "frames": 3}]}])";
    expectRefused(scene(R"("units": "world", "up": "z")", turning),
                  {"tools[0].path[0].frames", "about both world y and z", "one segment per frame"});
}

// A mesh (or level set) may carry its own "up" for its file: a z-up mesh in a y-up scene lands as
// it does in a z-up scene.
TEST_F(SceneTest, AShapeCarriesItsFilesUp)
{
    {
        std::ofstream o(file("wedge.obj"));
        o << "v 0 0 0\nv 4 0 0\nv 0 2 0\nv 0 0 6\nf 1 3 2\nf 1 2 4\nf 1 4 3\nf 2 3 4\n";
    }
    const std::string mesh = R"({"shape": "mesh", "file": "wedge.obj", "mass": 1000)";
    const Scene sceneUp = parseScene(R"({"up": "z", "clay": [)" + mesh + "}]}", "s.json", dir);
    const Scene shapeUp = parseScene(R"({"clay": [)" + mesh + R"(, "up": "z"}]})", "s.json", dir);
    const Scene plain = parseScene(R"({"clay": [)" + mesh + "}]}", "s.json", dir);
    const Box a = sceneUp.clay[0].shape.shape->bounds(), b = shapeUp.clay[0].shape.shape->bounds(),
              c = plain.clay[0].shape.shape->bounds();
    EXPECT_EQ(a.min, b.min);
    EXPECT_EQ(a.max, b.max);
    EXPECT_NE(a.max, c.max); // y up: the wedge's height is its y, not its z
    expectRefused(R"({"clay": [)" + mesh + R"(, "up": "x"}]})", {"clay[0].up", "\"x\""});
    expectRefused(R"({"clay": [{"shape": "box", "min": [0,0,0], "max": [1,1,1], "mass": 5, "up": "z"}]})",
                  {"clay[0].up", "unknown field"});
}

// A tool turning about world x, y and z at once (Blender's keyframed turns, one segment per frame)
// in a z-up world scene follows its world pose exactly at every frame.
TEST_F(SceneTest, WorldUnitsTurnsFollowTheWorldPose)
{
    std::string path;
    for (int k = 0; k < 12; ++k)
        path += std::string(k ? ", " : "") + R"({"rotate": [7, 11, 13], "translate": [0.25, 0, -0.5]})";
    const Scene sc = parseScene(R"({"units": "world", "up": "z", "voxel_size": 0.5,
        "clay": [{"shape": "box", "min": [0,0,0], "max": [2,2,2], "mass": 10}],
        "tools": [{"shape": "box", "min": [4,-2,4], "max": [6,0,6], "pivot": [5,-1,5], "path": [)" +
                                    path + "]}]}",
                                "s.json", "");
    const ToolSpec& t = sc.tools[0];
    const Vec3 pivotW{{5, -1, 5}}, pointW{{6, 0.5, 3}};
    for (uint64_t k = 0; k <= 12; ++k) {
        // The world pose: turned by (7k, 11k, 13k) degrees about x, then y, then z about the pivot,
        // which moved (0.25k, 0, -0.5k).
        const double r = M_PI / 180.0;
        const double ax = 7.0 * k * r, ay = 11.0 * k * r, az = 13.0 * k * r;
        Vec3 d{{pointW[0] - pivotW[0], pointW[1] - pivotW[1], pointW[2] - pivotW[2]}};
        d = {{d[0], std::cos(ax) * d[1] - std::sin(ax) * d[2], std::sin(ax) * d[1] + std::cos(ax) * d[2]}};
        d = {{std::cos(ay) * d[0] + std::sin(ay) * d[2], d[1], -std::sin(ay) * d[0] + std::cos(ay) * d[2]}};
        d = {{std::cos(az) * d[0] - std::sin(az) * d[1], std::sin(az) * d[0] + std::cos(az) * d[1], d[2]}};
        const Vec3 expectW{{pivotW[0] + d[0] + 0.25 * k, pivotW[1] + d[1], pivotW[2] + d[2] - 0.5 * k}};
        const Vec3 expect = worldToIndex(expectW, 0.5, UpAxis::Z);
        const Vec3 got = t.poseAt(k).apply(worldToIndex(pointW, 0.5, UpAxis::Z));
        for (int a = 0; a < 3; ++a)
            EXPECT_NEAR(got[a], expect[a], 1e-9) << "frame " << k << " axis " << a;
    }
}
