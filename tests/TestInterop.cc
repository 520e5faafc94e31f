// Working with other tools: meshes in world units that round-trip, metadata a FloatGrid-only reader
// finds, start files made with another Tc, the up axis.
#include <vdbclay/IO.h>
#include <vdbclay/Metrics.h>
#include <vdbclay/Scene.h>
#include <vdbclay/Sculpt.h>
#include <vdbclay/Shapes.h>

#include <openvdb/io/File.h>
#include <openvdb/openvdb.h>

#include <gtest/gtest.h>

#include <cmath>
#include <cstdlib>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <sstream>
#include <string>

using namespace vdbclay;
using openvdb::Coord;
namespace fs = std::filesystem;

namespace {

class InteropTest : public ::testing::Test {
protected:
    static void SetUpTestSuite() { openvdb::initialize(); }
    void SetUp() override
    {
        char tmpl[] = "/tmp/vdbclay-test-interop-XXXXXX";
        ASSERT_NE(mkdtemp(tmpl), nullptr);
        dir = tmpl;
    }
    void TearDown() override
    {
        std::error_code ec;
        fs::remove_all(dir, ec);
    }
    std::string file(const std::string& name) const { return dir + "/" + name; }
    std::string dir;
};

std::string errorOf(const std::function<void()>& f)
{
    try {
        f();
    } catch (const Error& e) {
        return e.what();
    }
    return "";
}

bool contains(const std::string& s, const std::string& part)
{
    return s.find(part) != std::string::npos;
}

/// A box of full cells (mass @a m) over voxels lo..hi, with voxel size @a vs.
MassGridPtr boxClay(Coord lo, Coord hi, int32_t m, double vs)
{
    auto g = openvdb::Int32Grid::create(0);
    g->tree().fill(openvdb::CoordBBox(lo, hi), m, true);
    g->tree().voxelizeActiveTiles();
    g->setTransform(openvdb::math::Transform::createLinearTransform(vs));
    return g;
}

/// Min and max of the "v x y z" lines of an OBJ.
void objBounds(const std::string& path, Vec3& lo, Vec3& hi)
{
    lo = {{1e300, 1e300, 1e300}};
    hi = {{-1e300, -1e300, -1e300}};
    std::ifstream in(path);
    std::string line;
    while (std::getline(in, line)) {
        if (line.rfind("v ", 0) != 0) continue;
        std::istringstream is(line.substr(2));
        Vec3 p;
        is >> p[0] >> p[1] >> p[2];
        for (int i = 0; i < 3; ++i) {
            lo[i] = std::min(lo[i], p[i]);
            hi[i] = std::max(hi[i], p[i]);
        }
    }
}

} // namespace

// Issue 14 item 1: the mesh of a .vdb with voxel size 0.1 is in the same world units as the .vdb,
// and mesh clay read back at that voxel size lands on the same voxels.
TEST_F(InteropTest, MeshOutputIsInWorldUnitsAndRoundTripsAsMeshClay)
{
    const double vs = 0.1;
    const MassGridPtr clay = boxClay(Coord(-3, 2, 5), Coord(16, 11, 14), 1000, vs);
    ClayMeta meta;
    meta.voxelSize = vs;
    writeClayFile(file("box.vdb"), *clay, meta);
    const ClayFile f = readClayFile(file("box.vdb"));
    writeSurfaceMesh(file("box.obj"), *f.mass, 1000);

    // Faces where density crosses 0.5: half-way between a full voxel centre and an empty one.
    Vec3 lo, hi;
    objBounds(file("box.obj"), lo, hi);
    const Vec3 wantLo{{-3.5 * vs, 1.5 * vs, 4.5 * vs}}, wantHi{{16.5 * vs, 11.5 * vs, 14.5 * vs}};
    for (int i = 0; i < 3; ++i) {
        EXPECT_NEAR(lo[i], wantLo[i], 1e-6) << "axis " << i;
        EXPECT_NEAR(hi[i], wantHi[i], 1e-6) << "axis " << i;
    }

    const MassGridPtr back = makeClay(*loadMesh(file("box.obj"), vs), 1000);
    EXPECT_EQ(clayVoxelCount(*back), uint64_t(20 * 10 * 10));
    EXPECT_EQ(totalMass(*back), totalMass(*clay));
    EXPECT_EQ(contentHash(*back), contentHash(*clay)); // same voxels, same masses: same place
}

// The PLY writer goes through the same transform.
TEST_F(InteropTest, PlyOutputIsInWorldUnitsToo)
{
    const MassGridPtr clay = boxClay(Coord(0, 0, 0), Coord(3, 3, 3), 500, 2.0);
    writeSurfaceMesh(file("c.ply"), *clay, 500);
    std::ifstream in(file("c.ply"));
    std::string line;
    double maxX = -1e300;
    bool body = false;
    while (std::getline(in, line)) {
        if (line == "end_header") {
            body = true;
            continue;
        }
        if (!body || line.rfind("3 ", 0) == 0) continue;
        std::istringstream is(line);
        double x, y, z;
        if (is >> x >> y >> z) maxX = std::max(maxX, x);
    }
    EXPECT_NEAR(maxX, 3.5 * 2.0, 1e-6);
}

// Issue 14 item 2: Tc and the other vdbclay_* metadata are on the density FloatGrid as well, for
// readers that cannot load Int32 grids; round(density * Tc) gives the mass back.
TEST_F(InteropTest, DensityGridCarriesTheClayMetadata)
{
    const MassGridPtr clay = boxClay(Coord(0, 0, 0), Coord(4, 4, 4), 250, 0.5);
    clay->tree().setValue(Coord(2, 2, 2), 777);
    ClayMeta meta;
    meta.rule.threshold = 250;
    meta.seed = 42;
    meta.steps = 9;
    meta.voxelSize = 0.5;
    writeClayFile(file("m.vdb"), *clay, meta);

    openvdb::io::File vdb(file("m.vdb"));
    vdb.open();
    auto density = openvdb::gridPtrCast<openvdb::FloatGrid>(vdb.readGrid("density"));
    vdb.close();
    ASSERT_TRUE(density);
    EXPECT_EQ(density->metaValue<int32_t>("vdbclay_threshold"), 250);
    EXPECT_EQ(density->metaValue<int64_t>("vdbclay_seed"), 42);
    EXPECT_EQ(density->metaValue<int64_t>("vdbclay_steps"), 9);
    EXPECT_EQ(density->metaValue<std::string>("vdbclay_rule"), "prorata");
    EXPECT_EQ(density->metaValue<double>("vdbclay_voxel_size"), 0.5);
    int64_t total = 0;
    for (auto it = density->cbeginValueOn(); it; ++it)
        total += std::llround(double(*it) * 250.0);
    EXPECT_EQ(total, totalMass(*clay));
}

// Issue 14 item 3: a start file made with another Tc is refused, naming the file, both values and
// the way on.
TEST_F(InteropTest, AStartFileWithAnotherTcIsRefusedWithTheWayOn)
{
    const MassGridPtr clay = boxClay(Coord(0, 0, 0), Coord(7, 7, 7), 250, 1.0);
    ClayMeta meta;
    meta.rule.threshold = 250;
    writeClayFile(file("tc250.vdb"), *clay, meta);

    const Scene other = parseScene(R"({"start": "tc250.vdb", "frames": 1})", file("s.json"), dir);
    const std::string e = errorOf([&] { Sculptor s(other, 1); });
    for (const char* part : {"s.json", "start", "tc250.vdb", "Tc 250", "Tc 1000", "\"threshold\": 250"}) {
        EXPECT_TRUE(contains(e, part)) << "missing \"" << part << "\" in: " << e;
    }

    const Scene same =
        parseScene(R"({"start": "tc250.vdb", "frames": 1, "threshold": 250})", file("s.json"), dir);
    Sculptor s(same, 1);
    s.run();
    EXPECT_EQ(totalMass(*s.mass()), totalMass(*clay));
}

// Issue 14 item 6: "up": "z" rotates the file's transform so index y (vdbclay's up) is world z;
// the mesh follows the transform, and reading it (or the file's own surface level set) back with
// up z lands on the same voxels.
TEST_F(InteropTest, UpZIsWrittenIntoTheTransformAndRoundTrips)
{
    const double vs = 0.5;
    const MassGridPtr clay = boxClay(Coord(1, 2, 3), Coord(6, 12, 8), 1000, 1.0);
    setClayTransform(*clay, vs, UpAxis::Z);
    ClayMeta meta;
    meta.voxelSize = vs;
    meta.up = UpAxis::Z;
    writeClayFile(file("z.vdb"), *clay, meta);

    const ClayFile f = readClayFile(file("z.vdb"));
    EXPECT_EQ(f.meta.up, UpAxis::Z);
    EXPECT_EQ(f.meta.voxelSize, vs);
    const openvdb::Vec3d up = f.mass->transform().indexToWorld(openvdb::Vec3d(0, 1, 0));
    EXPECT_EQ(up, openvdb::Vec3d(0, 0, vs)); // exact: no rounded sine
    EXPECT_EQ(f.mass->transform().indexToWorld(openvdb::Vec3d(0, 0, 1)), openvdb::Vec3d(0, -vs, 0));
    EXPECT_TRUE(contains(describeVdb(file("z.vdb")), "vdbclay_up (string) = z"));

    writeSurfaceMesh(file("z.obj"), *f.mass, 1000);
    Vec3 lo, hi;
    objBounds(file("z.obj"), lo, hi);
    // World x = index x, world y = -index z, world z = index y.
    EXPECT_NEAR(lo[0], 0.5 * vs, 1e-6);
    EXPECT_NEAR(hi[0], 6.5 * vs, 1e-6);
    EXPECT_NEAR(lo[1], -8.5 * vs, 1e-6);
    EXPECT_NEAR(hi[1], -2.5 * vs, 1e-6);
    EXPECT_NEAR(lo[2], 1.5 * vs, 1e-6);
    EXPECT_NEAR(hi[2], 12.5 * vs, 1e-6);

    EXPECT_EQ(contentHash(*makeClay(*loadMesh(file("z.obj"), vs, UpAxis::Z), 1000)), contentHash(*clay));
    EXPECT_EQ(contentHash(*makeClay(*loadLevelSet(file("z.vdb"), vs, "surface", UpAxis::Z), 1000)),
              contentHash(*clay));
    // Read as y-up, the same mesh lies on its side: other voxels.
    EXPECT_NE(contentHash(*makeClay(*loadMesh(file("z.obj"), vs, UpAxis::Y), 1000)), contentHash(*clay));
}

TEST_F(InteropTest, ScenesTakeUpAndRunsWriteIt)
{
    const Scene s = parseScene(R"({"up": "z", "voxel_size": 0.25, "frames": 1,
        "clay": [{"shape": "box", "min": [0,0,0], "max": [3,3,3], "mass": 1000}]})",
                               "up.json", dir);
    EXPECT_EQ(s.up, UpAxis::Z);
    Sculptor sc(s, 1);
    sc.run();
    EXPECT_EQ(sc.checkpointMeta().up, UpAxis::Z);
    EXPECT_EQ(sc.mass()->transform().indexToWorld(openvdb::Vec3d(0, 4, 0)), openvdb::Vec3d(0, 0, 1));
    EXPECT_EQ(parseScene("{}", "d.json", dir).up, UpAxis::Y);
    const std::string e = errorOf([&] { parseScene(R"({"up": "x"})", "bad.json", dir); });
    EXPECT_TRUE(contains(e, "bad.json: up:") && contains(e, "\"x\"")) << e;
}

namespace {
const char* kUnitCubeObj = "v 0 0 0\nv 1 0 0\nv 1 1 0\nv 0 1 0\nv 0 0 1\nv 1 0 1\nv 1 1 1\nv 0 1 1\n"
                           "f 1 4 3 2\nf 5 6 7 8\nf 1 2 6 5\nf 2 3 7 6\nf 3 4 8 7\nf 4 1 5 8\n";
} // namespace

// Issue 14 item 7: every shape can be placed: translate, rotate, uniform or per-axis scale, meshes
// included; voxel counts are exact where the voxel-centre rule makes them so.
TEST_F(InteropTest, TransformPlacesEveryShapeIncludingMeshes)
{
    {
        std::ofstream o(file("cube.obj"));
        o << kUnitCubeObj;
    }
    // The unit cube scaled by 8.4 about the origin, moved by (10.3, 0.3, -2.7): it spans
    // 10.3..18.7 in x (voxel centres 11..18), 0.3..8.7 in y, -2.7..5.7 in z: 8^3 voxels. Placed
    // vertex by vertex, the level set is as sharp as at scale 1.
    const Scene s = parseScene(R"({"clay": [
        {"shape": "mesh", "file": "cube.obj", "mass": 7,
         "transform": {"scale": 8.4, "translate": [10.3, 0.3, -2.7]}},
        {"shape": "box", "min": [0, 0, 0], "max": [3, 1, 0], "mass": 5,
         "transform": {"rotate": [0, 0, 90], "pivot": [0, 0, 0], "translate": [-20, 0, 0]}},
        {"shape": "sphere", "center": [0, 0, 0], "radius": 3.2, "mass": 3,
         "transform": {"scale": [2, 1, 1], "translate": [0, 40, 0]}}]})",
                               file("t.json"), dir);
    ASSERT_EQ(s.clay.size(), 3u);
    const MassGridPtr cube = makeClay(*s.clay[0].shape.shape, 7);
    EXPECT_EQ(clayVoxelCount(*cube), uint64_t(8 * 8 * 8));
    const openvdb::CoordBBox cb = cube->evalActiveVoxelBoundingBox();
    EXPECT_EQ(cb, openvdb::CoordBBox(Coord(11, 1, -2), Coord(18, 8, 5)));

    // The 4x2x1 box turned 90 degrees about z: x -> y, y -> -x, then moved by -20 in x.
    const MassGridPtr box = makeClay(*s.clay[1].shape.shape, 5);
    EXPECT_EQ(clayVoxelCount(*box), uint64_t(8));
    EXPECT_EQ(box->evalActiveVoxelBoundingBox(), openvdb::CoordBBox(Coord(-21, 0, 0), Coord(-20, 3, 0)));

    // A sphere stretched 2x along x is the ellipsoid (x/6.4)^2 + y^2/3.2^2 + z^2/3.2^2 < 1.
    const MassGridPtr ell = makeClay(*s.clay[2].shape.shape, 3);
    uint64_t want = 0;
    for (int x = -7; x <= 7; ++x)
        for (int y = -4; y <= 4; ++y)
            for (int z = -4; z <= 4; ++z)
                if ((x / 6.4) * (x / 6.4) + (y * y + z * z) / (3.2 * 3.2) < 1) ++want;
    EXPECT_EQ(clayVoxelCount(*ell), want);
    EXPECT_EQ(ell->evalActiveVoxelBoundingBox().min().y(), 40 - 3);

    for (const char* bad : {R"({"clay": [{"shape": "sphere", "center": [0,0,0], "radius": 2, "mass": 1,
                                "transform": {"scale": 0}}]})",
                            R"({"clay": [{"shape": "sphere", "center": [0,0,0], "radius": 2, "mass": 1,
                                "transform": {"spin": 1}}]})"}) {
        const std::string e = errorOf([&] { parseScene(bad, "b.json", dir); });
        EXPECT_TRUE(contains(e, "b.json: clay[0].transform")) << e;
    }
}

namespace {
/// An OBJ of the boxes given as (min, max) corners, 6 quads each, vertices shared where they coincide.
std::string boxesObj(const std::vector<std::pair<Vec3, Vec3>>& boxes)
{
    std::ostringstream o;
    int base = 0;
    for (const auto& [lo, hi] : boxes) {
        for (int c = 0; c < 8; ++c) {
            o << "v " << ((c & 1) ? hi[0] : lo[0]) << ' ' << ((c & 2) ? hi[1] : lo[1]) << ' '
              << ((c & 4) ? hi[2] : lo[2]) << '\n';
        }
        // Outward quads of corners (bit 0 = x, bit 1 = y, bit 2 = z), 1-based.
        const int q[6][4] = {{0, 2, 3, 1}, {4, 5, 7, 6}, {0, 1, 5, 4},
                             {2, 6, 7, 3}, {0, 4, 6, 2}, {1, 3, 7, 5}};
        for (const auto& f : q)
            o << "f " << base + f[0] + 1 << ' ' << base + f[1] + 1 << ' ' << base + f[2] + 1 << ' '
              << base + f[3] + 1 << '\n';
        base += 8;
    }
    return o.str();
}
} // namespace

// Issue 14 item 4: a closed but non-manifold mesh (two boxes sharing an edge: 4 faces on it) is
// accepted and fills both boxes; a mesh with a hole is refused with the way on.
TEST_F(InteropTest, ClosedNonManifoldMeshesAreAcceptedOpenOnesExplained)
{
    {
        std::ofstream o(file("two.obj"));
        o << boxesObj({{{{-0.5, -0.5, -0.5}}, {{7.5, 7.5, 7.5}}}, {{{7.5, 7.5, -0.5}}, {{15.5, 15.5, 7.5}}}});
    }
    const MassGridPtr clay = makeClay(*loadMesh(file("two.obj")), 9);
    EXPECT_EQ(clayVoxelCount(*clay), uint64_t(2 * 512));
    EXPECT_EQ(clay->tree().getValue(Coord(7, 7, 3)), 9);
    EXPECT_EQ(clay->tree().getValue(Coord(8, 8, 3)), 9);
    EXPECT_EQ(clay->tree().getValue(Coord(7, 8, 3)), 0);
    EXPECT_EQ(clay->tree().getValue(Coord(8, 7, 3)), 0);

    // A box without its top (+y) face: open, 4 open edges, filled by the winding number.
    std::string open = boxesObj({{{{-0.5, -0.5, -0.5}}, {{5.5, 5.5, 5.5}}}});
    open.erase(open.find("f 3 7 8 4\n"), std::strlen("f 3 7 8 4\n"));
    {
        std::ofstream o(file("open.obj"));
        o << open;
    }
    const ShapePtr s = loadMesh(file("open.obj"));
    EXPECT_TRUE(contains(s->describe(), "open: 4 open edges")) << s->describe();
    EXPECT_EQ(clayVoxelCount(*makeClay(*s, 1)), uint64_t(6 * 6 * 6));

    // A single triangle encloses nothing: refused, naming the file and why.
    {
        std::ofstream o(file("tri.obj"));
        o << "v 0 0 0\nv 4 0 0\nv 0 4 0\nf 1 2 3\n";
    }
    const std::string e = errorOf([&] { loadMesh(file("tri.obj")); });
    EXPECT_TRUE(contains(e, "tri.obj") && contains(e, "open") && contains(e, "encloses no volume")) << e;
}
