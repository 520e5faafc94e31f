// Scene files (every malformed input refused with a clear error) and running scenes.
#include <vdbclay/IO.h>
#include <vdbclay/Metrics.h>
#include <vdbclay/Scene.h>
#include <vdbclay/Sculpt.h>

#include <openvdb/openvdb.h>

#include <gtest/gtest.h>

#include <cstdio>
#include <fstream>
#include <string>
#include <unistd.h>

using namespace vdbclay;

namespace {

class SceneTest : public ::testing::Test {
protected:
    static void SetUpTestSuite() { openvdb::initialize(); }
    void SetUp() override
    {
        char tmpl[] = "/tmp/vdbclay-scene-XXXXXX";
        ASSERT_NE(mkdtemp(tmpl), nullptr);
        dir = tmpl;
    }
    void TearDown() override { std::system(("rm -rf '" + dir + "'").c_str()); }
    std::string write(const std::string& name, const std::string& text)
    {
        const std::string p = dir + "/" + name;
        std::ofstream(p, std::ios::binary) << text;
        return p;
    }
    std::string dir;
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
        for (const char* n : needles) EXPECT_NE(msg.find(n), std::string::npos) << "\"" << n << "\" not in: " << msg;
        EXPECT_EQ(msg.find('\n'), std::string::npos) << "one line: " << msg;
    }
}

const std::string kPlate =
    R"({"shape": "box", "min": [0,10,0], "max": [9,12,9], "path": [{"translate": [0,-1,0], "frames": 3}]})";

std::string scene(const std::string& extra, const std::string& tools = "[" + kPlate + "]")
{
    return R"({"threshold": 100, "clay": [{"shape": "box", "min": [0,0,0], "max": [7,7,7], "mass": 90}], "tools": )" +
           tools + (extra.empty() ? "" : ", " + extra) + "}";
}

} // namespace

TEST_F(SceneTest, TheIssuesMinimumSceneParsesAsWritten)
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

TEST_F(SceneTest, DefaultSceneIsTheIssuesExample)
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
    expectRefused(scene("", R"([{"shape": "cylinder", "center": [0,0,0], "radius": 2, "height": 0, "path": [{}]}])"),
                  {"tools[0].height", "must be > 0"});
    expectRefused(scene("", R"([{"shape": "cylinder", "center": [0,0,0], "radius": 2, "height": 3, "axis": "w", "path": [{}]}])"),
                  {"tools[0].axis"});
    expectRefused(scene("", R"([{"shape": "sphere", "center": [0,0,0], "radius": 2, "path": []}])"),
                  {"tools[0].path", "empty path"});
    expectRefused(scene("", R"([{"shape": "sphere", "center": [0,0,0], "radius": 2}])"),
                  {"tools[0]", "missing field \"path\""});
    expectRefused(scene("", R"([{"shape": "sphere", "center": [0,0,0], "radius": 2, "path": [{"frames": 0}]}])"),
                  {"tools[0].path[0].frames", "[1, 1000000]"});
    expectRefused(scene("", R"([{"shape": "sphere", "center": [0,0,0], "radius": 2, "path": [{"move": [1,0,0]}]}])"),
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
        parseScene(scene("", R"([{"shape": "sphere", "center": [0,0,0], "radius": 1e999, "path": [{}]}])"), "s.json", "");
        ADD_FAILURE() << "accepted an infinite radius";
    } catch (const Error& e) {
        const std::string m = e.what();
        EXPECT_TRUE(m.find("radius") != std::string::npos || m.find("invalid JSON") != std::string::npos) << m;
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
            for (const char* n : needles) EXPECT_NE(std::string(e.what()).find(n), std::string::npos) << e.what();
        }
    };
    refused(R"({"clay": [{"shape": "mesh", "file": "missing.obj", "mass": 5}]})", {"clay[0]", "missing.obj"});
    refused(R"({"clay": [{"shape": "mesh", "file": "open.obj", "mass": 5}]})", {"clay[0]", "open.obj"});
    refused(R"({"clay": [{"shape": "levelset", "file": "notvdb.vdb", "mass": 5}]})", {"clay[0]", "notvdb.vdb"});
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
    const Scene over = parseScene(R"({"clay": [{"shape": "box", "min": [0,0,0], "max": [3,3,3], "mass": 2000000000},
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
            for (int y = 24; y <= 32; ++y) ASSERT_EQ(acc.getValue(openvdb::Coord(x, y, z)), 0) << x << "," << y << "," << z;
    // The pressed clay spread sideways beyond the original cube.
    bool wider = false;
    for (auto it = sc.mass()->tree().cbeginValueOn(); it && !wider; ++it) wider = it.getCoord().x() < 0;
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
