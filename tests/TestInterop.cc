// Working with other tools: meshes in world units that round-trip, metadata a FloatGrid-only reader
// finds, start files made with another Tc, the up axis.
#include <vdbclay/IO.h>
#include <vdbclay/Metrics.h>
#include <vdbclay/Scene.h>
#include <vdbclay/Sculpt.h>
#include <vdbclay/Shapes.h>
#include <vdbclay/SurfaceMesh.h>

#include <openvdb/io/File.h>
#include <openvdb/openvdb.h>
#include <openvdb/tools/LevelSetSphere.h>
#include <openvdb/tools/MeshToVolume.h>
#include <tbb/global_control.h>

#include <gtest/gtest.h>

#include "TempDirTest.h"

#include <array>
#include <cmath>
#include <cstdlib>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <iterator>
#include <sstream>
#include <string>
#include <utility>

using namespace vdbclay;
using openvdb::Coord;
namespace fs = std::filesystem;

namespace {

using InteropTest = vdbclay_test::TempDirTest;

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

/// The volume of a closed OBJ of triangles and polygons (divergence theorem).
double objVolumeOf(const std::string& path)
{
    std::ifstream in(path);
    std::vector<Vec3> v;
    double six = 0;
    std::string line;
    while (std::getline(in, line)) {
        std::istringstream is(line);
        std::string k;
        is >> k;
        if (k == "v") {
            Vec3 p;
            is >> p[0] >> p[1] >> p[2];
            v.push_back(p);
        } else if (k == "f") {
            std::vector<int> f;
            std::string w;
            while (is >> w)
                f.push_back(std::stoi(w) - 1);
            for (size_t i = 1; i + 1 < f.size(); ++i) {
                const Vec3 &a = v[f[0]], &b = v[f[i]], &c = v[f[i + 1]];
                six += a[0] * (b[1] * c[2] - b[2] * c[1]) - a[1] * (b[0] * c[2] - b[2] * c[0]) +
                       a[2] * (b[0] * c[1] - b[1] * c[0]);
            }
        }
    }
    return std::abs(six) / 6;
}

} // namespace

// The mesh of a .vdb with voxel size 0.1 is in the same world units as the .vdb, and mesh clay read
// back at that voxel size lands on the same voxels.
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

    // Read back, it lands on the same voxels: the same box, full inside and across each face. Its
    // volume is the mesh's: the surface at density 0.5 of whole cells cuts each convex edge of the
    // box by a quarter voxel of area per voxel of length (MeshRoundTripKeepsPlaceAndVolume: smooth
    // clay keeps its volume).
    const MassGridPtr back = makeClay(*loadMesh(file("box.obj"), vs), 1000);
    EXPECT_EQ(clayVoxelCount(*back), uint64_t(20 * 10 * 10));
    EXPECT_EQ(back->evalActiveVoxelBoundingBox(), clay->evalActiveVoxelBoundingBox());
    EXPECT_EQ(back->tree().getValue(Coord(-3, 6, 9)), 1000); // a face
    EXPECT_EQ(back->tree().getValue(Coord(5, 6, 9)), 1000);  // inside
    EXPECT_EQ(back->tree().getValue(Coord(5, 2, 5)), 750);   // an edge: 3/4 of it
    const double meshVolume = std::abs(objVolumeOf(file("box.obj"))) / (vs * vs * vs);
    EXPECT_NEAR(double(totalMass(*back)), meshVolume * 1000, 0.5 * 2000);
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

// Tc and the other vdbclay_* metadata are on the density FloatGrid as well, for readers that cannot
// load Int32 grids; round(density * Tc) gives the mass back.
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

// A start file made with another Tc is refused, naming the file, both values and the way on.
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

// "up": "z" rotates the file's transform so index y (vdbclay's up) is world z; the mesh follows the
// transform, and reading it (or the file's own surface level set) back with up z lands on the same
// voxels.
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

    // Read back with up z, mesh and level set make the clay the same files written y up make.
    const MassGridPtr yClay = boxClay(Coord(1, 2, 3), Coord(6, 12, 8), 1000, vs);
    ClayMeta yMeta;
    yMeta.voxelSize = vs;
    writeClayFile(file("y.vdb"), *yClay, yMeta);
    writeSurfaceMesh(file("y.obj"), *yClay, 1000);
    const MassGridPtr fromZ = makeClay(*loadMesh(file("z.obj"), vs, UpAxis::Z), 1000);
    EXPECT_EQ(contentHash(*fromZ), contentHash(*makeClay(*loadMesh(file("y.obj"), vs, UpAxis::Y), 1000)));
    EXPECT_EQ(fromZ->evalActiveVoxelBoundingBox(), clay->evalActiveVoxelBoundingBox());
    const MassGridPtr lsZ = makeClay(*loadLevelSet(file("z.vdb"), vs, "surface", UpAxis::Z), 1000);
    EXPECT_EQ(contentHash(*lsZ),
              contentHash(*makeClay(*loadLevelSet(file("y.vdb"), vs, "surface", UpAxis::Y), 1000)));
    EXPECT_EQ(lsZ->evalActiveVoxelBoundingBox(), clay->evalActiveVoxelBoundingBox());
    // Read as y-up, the same mesh lies on its side: other voxels.
    EXPECT_NE(contentHash(*makeClay(*loadMesh(file("z.obj"), vs, UpAxis::Y), 1000)), contentHash(*fromZ));
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

// Every shape can be placed: translate, rotate, uniform or per-axis scale, meshes included; voxel
// counts are exact where the voxel-centre rule makes them so.
TEST_F(InteropTest, TransformPlacesEveryShapeIncludingMeshes)
{
    {
        std::ofstream o(file("cube.obj"));
        o << kUnitCubeObj;
    }
    // The unit cube scaled by 8.4 about the origin, moved by (10.3, 0.3, -2.7): it spans
    // 10.3..18.7 in x (voxels 11..18 whole, 10 and 19 a fifth each), 0.3..8.7 in y, -2.7..5.7 in z:
    // 8^3 full voxels, and mesh clay keeps the volume: 6 x 64 face voxels of round(7 / 5) = 1, edges
    // and corners round(7 / 25) = round(7 / 125) = 0. Placed vertex by vertex, as sharp as at scale 1.
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
    EXPECT_EQ(clayVoxelCount(*cube), uint64_t(8 * 8 * 8 + 6 * 64));
    EXPECT_EQ(totalMass(*cube), int64_t(8 * 8 * 8 * 7 + 6 * 64));
    const openvdb::CoordBBox cb = cube->evalActiveVoxelBoundingBox();
    EXPECT_EQ(cb, openvdb::CoordBBox(Coord(10, 0, -3), Coord(19, 9, 6)));
    EXPECT_EQ(cube->tree().getValue(Coord(11, 1, -2)), 7);
    EXPECT_EQ(cube->tree().getValue(Coord(10, 4, 0)), 1);
    EXPECT_EQ(cube->tree().getValue(Coord(10, 0, 0)), 0);

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

// A closed but non-manifold mesh (two boxes sharing an edge: 4 faces on it) is accepted and fills both
// boxes; a mesh with a hole is refused with the way on.
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

// ---- Clay from a mesh or level set keeps its volume -----------------------------------------------

namespace {
/// A UV sphere of @a rings x @a segments, outward, centred at @a c (world units), as OBJ text.
std::string sphereObj(const Vec3& c, double r, int rings, int segments)
{
    std::ostringstream o;
    o.precision(17);
    o << "v " << c[0] << ' ' << c[1] + r << ' ' << c[2] << '\n'; // 1: north pole
    for (int i = 1; i < rings; ++i) {
        const double th = M_PI * i / rings;
        for (int j = 0; j < segments; ++j) {
            const double ph = 2 * M_PI * j / segments;
            o << "v " << c[0] + r * std::sin(th) * std::cos(ph) << ' ' << c[1] + r * std::cos(th) << ' '
              << c[2] + r * std::sin(th) * std::sin(ph) << '\n';
        }
    }
    const int south = 2 + (rings - 1) * segments;
    o << "v " << c[0] << ' ' << c[1] - r << ' ' << c[2] << '\n';
    auto at = [&](int ring, int j) { return 2 + (ring - 1) * segments + (j % segments); };
    for (int j = 0; j < segments; ++j) {
        o << "f 1 " << at(1, j + 1) << ' ' << at(1, j) << '\n';
        for (int i = 1; i + 1 < rings; ++i)
            o << "f " << at(i, j) << ' ' << at(i, j + 1) << ' ' << at(i + 1, j + 1) << ' ' << at(i + 1, j)
              << '\n';
        o << "f " << south << ' ' << at(rings - 1, j) << ' ' << at(rings - 1, j + 1) << '\n';
    }
    return o.str();
}

/// Voxels holding more than 0 and less than @a m0: each may be off by half a unit of rounding.
uint64_t partialVoxels(const MassGrid& g, int32_t m0)
{
    uint64_t n = 0;
    for (auto it = g.cbeginValueOn(); it; ++it)
        if (*it > 0 && *it < m0) ++n;
    return n;
}

void writeText(const std::string& path, const std::string& text)
{
    std::ofstream o(path);
    o << text;
}
} // namespace

// Blender's 16-unit cube, faces on voxel centres: by the voxel-centre rule it would be 17^3 voxels
// (+20 %); coverage gives a face voxel half its mass, an edge voxel a quarter, a corner an eighth:
// 16^3 x m0 exactly (15^3 + 6 x 15^2 / 2 + 12 x 15 / 4 + 8 / 8 = 4096).
TEST_F(InteropTest, MeshClayOfA16UnitCubeWithFacesOnVoxelCentresHoldsExactly16Cubed)
{
    writeText(file("cube16.obj"), boxesObj({{{{-8, -8, -8}}, {{8, 8, 8}}}}));
    const MassGridPtr cube = makeClay(*loadMesh(file("cube16.obj")), 1000);
    EXPECT_EQ(totalMass(*cube), int64_t(4096) * 1000);
    EXPECT_EQ(clayVoxelCount(*cube), uint64_t(17 * 17 * 17));
    EXPECT_EQ(cube->tree().getValue(Coord(0, 0, 0)), 1000);
    EXPECT_EQ(cube->tree().getValue(Coord(8, 0, 0)), 500); // a face through the voxel centre: half
    EXPECT_EQ(cube->tree().getValue(Coord(-8, 0, 0)), 500);
    EXPECT_EQ(cube->tree().getValue(Coord(0, 0, -8)), 500);
    EXPECT_EQ(cube->tree().getValue(Coord(8, -8, 0)), 250); // an edge: a quarter
    EXPECT_EQ(cube->tree().getValue(Coord(8, 8, -8)), 125); // a corner: an eighth
    EXPECT_EQ(cube->tree().getValue(Coord(9, 0, 0)), 0);
    // The same cube from Blender (z up, voxel size 0.5, 8 units): the same clay.
    writeText(file("cube8z.obj"), boxesObj({{{{-4, -4, -4}}, {{4, 4, 4}}}}));
    EXPECT_EQ(contentHash(*makeClay(*loadMesh(file("cube8z.obj"), 0.5, UpAxis::Z), 1000)),
              contentHash(*cube));
    // Inside out (every face reversed), it is the same solid.
    std::string flipped;
    {
        std::istringstream is(boxesObj({{{{-8, -8, -8}}, {{8, 8, 8}}}}));
        std::string line;
        while (std::getline(is, line)) {
            if (line[0] == 'f') {
                std::istringstream ls(line.substr(2));
                int a, b, c, d;
                ls >> a >> b >> c >> d;
                line = "f " + std::to_string(d) + " " + std::to_string(c) + " " + std::to_string(b) + " " +
                       std::to_string(a);
            }
            flipped += line + "\n";
        }
    }
    writeText(file("inside-out.obj"), flipped);
    EXPECT_EQ(contentHash(*makeClay(*loadMesh(file("inside-out.obj")), 1000)), contentHash(*cube));
}

// A sphere mesh, a rotated cube and a cube moved by fractions of a voxel hold their mesh's volume
// x m0, up to the rounding of each partly covered voxel to a whole unit (half a unit each).
TEST_F(InteropTest, MeshClayHoldsTheMeshVolume)
{
    struct Case {
        const char* name;
        std::string obj;
        Placement place;
    };
    Placement rotated;
    rotated.rotateDeg = {{30, 45, 10}};
    rotated.translate = {{0.3, -0.2, 0.45}};
    Placement moved;
    moved.translate = {{0.25, 0.25, 0.25}};
    const std::vector<Case> cases = {
        {"sphere", sphereObj({{0.3, 0.1, -0.2}}, 10, 24, 48), Placement()},
        {"rotated cube", boxesObj({{{{-8, -8, -8}}, {{8, 8, 8}}}}), rotated},
        {"moved cube", boxesObj({{{{-8, -8, -8}}, {{8, 8, 8}}}}), moved},
    };
    for (const Case& c : cases) {
        writeText(file("m.obj"), c.obj);
        const double volume = objVolumeOf(file("m.obj"));
        const int32_t m0 = 1000;
        const MassGridPtr clay = makeClay(*loadMesh(file("m.obj"), 1.0, UpAxis::Y, c.place), m0);
        const double err = double(totalMass(*clay)) - volume * m0;
        EXPECT_LE(std::abs(err), 0.5 * double(partialVoxels(*clay, m0)) + 1e-6 * volume * m0) << c.name;
        EXPECT_LT(std::abs(err), 0.005 * volume * m0) << c.name;
        std::printf("%s: mesh volume %.4f voxels, clay %.4f (%+.5f %%)\n", c.name, volume,
                    double(totalMass(*clay)) / m0, 100 * err / (volume * m0));
    }
}

namespace {
/// A sampled estimate, for comparison: 4^3 sign samples of a shape's distance().
double supersampledVolume(const Shape& s)
{
    const Box b = s.bounds();
    int64_t inside = 0;
    for (int32_t x = b.min[0]; x <= b.max[0]; ++x)
        for (int32_t y = b.min[1]; y <= b.max[1]; ++y)
            for (int32_t z = b.min[2]; z <= b.max[2]; ++z)
                for (int i = 0; i < 64; ++i) {
                    const Vec3 p{
                        {x + ((i & 3) - 1.5) / 4, y + (((i >> 2) & 3) - 1.5) / 4, z + ((i >> 4) - 1.5) / 4}};
                    if (s.distance(p) < 0) ++inside;
                }
    return double(inside) / 64;
}
} // namespace

// Why sampling a mesh's level set loses volume: a trilinear level set rounds convex edges and corners
// inward, so sign samples of it miss part of every edge voxel. Exact coverage does not sample it.
TEST_F(InteropTest, ExactMeshCoverageAgainstSamplesOfTheLevelSet)
{
    writeText(file("cube16.obj"), boxesObj({{{{-8, -8, -8}}, {{8, 8, 8}}}}));
    Placement moved;
    moved.translate = {{0.25, 0.25, 0.25}};
    const ShapePtr s = loadMesh(file("cube16.obj"), 1.0, UpAxis::Y, moved);
    const double sampled = supersampledVolume(*s);
    const double exact = double(totalMass(*makeClay(*s, 1 << 20))) / (1 << 20);
    std::printf("cube moved by 1/4 voxel, 4096 voxels: exact coverage %.4f, 4^3 samples of the level set "
                "%.4f (%+.2f %%)\n",
                exact, sampled, 100 * (sampled - 4096) / 4096);
    EXPECT_NEAR(exact, 4096, 0.01);
    EXPECT_LT(sampled, 4096 * 0.995); // more than the 0.5 % that level set clay may lose
}

// Level sets (and meshes that are open) fill by clamp(1/2 - d, 0, 1) at voxel centres: within 0.5 %
// of a ball's volume at radius 10 (1 / (4 r^2) = 0.25 % by the ramp, plus sampling), exact on faces
// parallel to the axes, and a placed level set keeps its volume x scale^3.
TEST_F(InteropTest, LevelSetClayHoldsItsVolume)
{
    const double r = 10;
    auto ball = openvdb::tools::createLevelSetSphere<openvdb::FloatGrid>(
        float(r), openvdb::Vec3f(0.3f, 0.1f, 0.f), 1.f);
    ball->setName("ball");
    openvdb::io::File(file("ball.vdb")).write({ball});
    const double want = 4.0 / 3.0 * M_PI * r * r * r;
    const ShapePtr ls = loadLevelSet(file("ball.vdb"));
    EXPECT_TRUE(ls->keepsVolume());
    const double got = double(totalMass(*makeClay(*ls, 1000))) / 1000;
    EXPECT_NEAR(got, want, 0.005 * want);
    Placement twice;
    twice.scale = {{2, 2, 2}};
    const ShapePtr big = makePlaced(ls, twice);
    EXPECT_TRUE(big->keepsVolume());
    const double gotBig = double(totalMass(*makeClay(*big, 1000))) / 1000;
    EXPECT_NEAR(gotBig, 8 * want, 0.005 * 8 * want);
    // At half the voxel size the same ball is 8 times as many voxels.
    const double gotFine = double(totalMass(*makeClay(*loadLevelSet(file("ball.vdb"), 0.5), 1000))) / 1000;
    EXPECT_NEAR(gotFine, 8 * want, 0.005 * 8 * want);
    std::printf(
        "level-set ball r = %g: %.3f voxels (%+.3f %%), placed x2: %+.3f %%, voxel size 0.5: %+.3f %%\n", r,
        got, 100 * (got - want) / want, 100 * (gotBig - 8 * want) / (8 * want),
        100 * (gotFine - 8 * want) / (8 * want));
    // Balls of other radii, at the level set's own voxel size: the ramp adds 1 / (4 r^2); the
    // curvature-corrected ramp (DistanceCoverage.cc, curvedRamp) does not.
    for (const double radius : {4.0, 6.0, 10.0, 20.0}) {
        auto b = openvdb::tools::createLevelSetSphere<openvdb::FloatGrid>(
            float(radius), openvdb::Vec3f(0.2f, 0.45f, 0.1f), 1.f);
        openvdb::io::File(file("b.vdb")).write({b});
        const ShapePtr s = loadLevelSet(file("b.vdb"));
        const double exact = 4.0 / 3.0 * M_PI * radius * radius * radius;
        const double v = double(totalMass(*makeClay(*s, 1 << 20))) / (1 << 20);
        double rampSum = 0;
        const Box bb = s->bounds();
        for (int32_t x = bb.min[0] - 1; x <= bb.max[0] + 1; ++x)
            for (int32_t y = bb.min[1] - 1; y <= bb.max[1] + 1; ++y)
                for (int32_t z = bb.min[2] - 1; z <= bb.max[2] + 1; ++z)
                    rampSum += std::min(
                        std::max(0.5 - s->distance(Vec3{{double(x), double(y), double(z)}}), 0.0), 1.0);
        std::printf("level-set ball r = %g: %+.3f %% (the ramp %+.3f %%)\n", radius,
                    100 * (v - exact) / exact, 100 * (rampSum - exact) / exact);
        EXPECT_NEAR(v, exact, 0.005 * exact);
        EXPECT_LT(std::fabs(v - exact), std::fabs(rampSum - exact)) << radius;
    }
    // Analytic shapes keep the voxel-centre rule.
    EXPECT_FALSE(makeSphere({{0, 0, 0}}, 3)->keepsVolume());
    EXPECT_FALSE(makePlaced(makeBox({{0, 0, 0}}, {{2, 2, 2}}), twice)->keepsVolume());
}

namespace {
/// A level set (voxel size 1, half width 3) of the closed mesh @a points / @a quads, written to
/// @a path as grid "shape".
void writeMeshLevelSet(const std::string& path, const std::vector<openvdb::Vec3s>& points,
                       const std::vector<openvdb::Vec4I>& quads)
{
    auto ls = openvdb::tools::meshToLevelSet<openvdb::FloatGrid>(
        *openvdb::math::Transform::createLinearTransform(1.0), points, std::vector<openvdb::Vec3I>(), quads,
        3.f);
    ls->setName("shape");
    openvdb::io::File(path).write({ls});
}

/// The 8 corners of the cube [-h, h]^3, rotated by @a degZ about z then @a degX about x, moved by @a t,
/// and its 6 outward faces.
void cubeMesh(double h, double degZ, double degX, const openvdb::Vec3d& t,
              std::vector<openvdb::Vec3s>& points, std::vector<openvdb::Vec4I>& quads)
{
    const double cz = std::cos(degZ * M_PI / 180), sz = std::sin(degZ * M_PI / 180);
    const double cx = std::cos(degX * M_PI / 180), sx = std::sin(degX * M_PI / 180);
    points.clear();
    for (int i = 0; i < 8; ++i) {
        const double x = (i & 1) ? h : -h, y = (i & 2) ? h : -h, z = (i & 4) ? h : -h;
        const double x1 = cz * x - sz * y, y1 = sz * x + cz * y;
        const double y2 = cx * y1 - sx * z, z2 = sx * y1 + cx * z;
        points.emplace_back(float(x1 + t[0]), float(y2 + t[1]), float(z2 + t[2]));
    }
    quads = {{0, 2, 3, 1}, {4, 5, 7, 6}, {0, 1, 5, 4}, {2, 6, 7, 3}, {0, 4, 6, 2}, {1, 3, 7, 5}};
}

/// The volume of the plain ramp, for comparison: the sum of clamp(1/2 - d, 0, 1) at voxel centres.
double rampVolume(const Shape& s)
{
    const Box b = s.bounds();
    double v = 0;
    for (int32_t x = b.min[0] - 1; x <= b.max[0] + 1; ++x)
        for (int32_t y = b.min[1] - 1; y <= b.max[1] + 1; ++y)
            for (int32_t z = b.min[2] - 1; z <= b.max[2] + 1; ++z)
                v += std::min(std::max(0.5 - s.distance(Vec3{{double(x), double(y), double(z)}}), 0.0), 1.0);
    return v;
}

double clayVolumeOfLevelSet(const std::string& path, int32_t m0)
{
    return double(totalMass(*makeClay(*loadLevelSet(path), m0))) / m0;
}
} // namespace

// A level set of a polyhedron keeps its volume at its edges and corners too (DistanceCoverage.cc):
// the ramp counted a voxel whose centre lies on a convex edge as 1/2 instead of 1/4 (+1.2 % on this
// 16-voxel cube); the planes recognised in the distance field give the exact part at any offset and
// orientation, and at a concave edge. Faces on voxel centres give the mesh clay's exact values.
TEST_F(InteropTest, LevelSetClayOfSharpShapesHoldsTheirVolume)
{
    const int32_t m0 = 1 << 20; // fine enough that rounding each voxel adds < 0.01 voxel in all
    std::vector<openvdb::Vec3s> points;
    std::vector<openvdb::Vec4I> quads;
    cubeMesh(8, 0, 0, {0, 0, 0}, points, quads);
    writeMeshLevelSet(file("cube.vdb"), points, quads);
    const MassGridPtr cube = makeClay(*loadLevelSet(file("cube.vdb")), 1000);
    EXPECT_EQ(totalMass(*cube), int64_t(4096) * 1000);
    EXPECT_EQ(cube->tree().getValue(Coord(8, 0, 0)), 500);  // a face through the voxel centre: half
    EXPECT_EQ(cube->tree().getValue(Coord(8, -8, 0)), 250); // an edge: a quarter (the ramp: half)
    EXPECT_EQ(cube->tree().getValue(Coord(8, 8, -8)), 125); // a corner: an eighth (the ramp: half)
    // The same clay as the cube's mesh makes (exact coverage of the mesh itself).
    writeText(file("cube16.obj"), boxesObj({{{{-8, -8, -8}}, {{8, 8, 8}}}}));
    EXPECT_EQ(contentHash(*cube), contentHash(*makeClay(*loadMesh(file("cube16.obj")), 1000)));

    struct Case {
        double degZ, degX;
        openvdb::Vec3d t;
    };
    for (const Case& c :
         {Case{0, 0, {0.25, 0.25, 0.25}}, Case{0, 0, {0.5, 0.5, 0.5}}, Case{0, 0, {0.1, 0.35, 0.7}},
          Case{30, 20, {0.13, 0.13, 0.13}}, Case{45, 0, {0.5, 0, 0.3}}}) {
        cubeMesh(8, c.degZ, c.degX, c.t, points, quads);
        writeMeshLevelSet(file("cube.vdb"), points, quads);
        const double v = clayVolumeOfLevelSet(file("cube.vdb"), m0);
        const double r = rampVolume(*loadLevelSet(file("cube.vdb")));
        std::printf(
            "level-set cube 16, rotated %g/%g, moved %g %g %g: %.4f voxels (%+.4f %%; the ramp %+.3f %%)\n",
            c.degZ, c.degX, c.t[0], c.t[1], c.t[2], v, 100 * (v - 4096) / 4096, 100 * (r - 4096) / 4096);
        // Float samples of the level set; a rotated cube's edges cross voxels at every offset.
        EXPECT_NEAR(v, 4096, (c.degZ == 0 && c.degX == 0) ? 0.01 : 0.001 * 4096);
    }

    // Sampled off the level set's own voxel centres (another voxel size, or moved by a transform),
    // the distance is interpolated trilinearly, which rounds the edges inward (the ramp: -0.5 % to
    // -0.7 %); the faces' planes rebuild them.
    cubeMesh(8, 30, 20, {0.13, 0.13, 0.13}, points, quads);
    writeMeshLevelSet(file("cube.vdb"), points, quads);
    Placement moved;
    moved.translate = {{0.37, 0.37, 0.37}};
    for (const double vs : {1.0, 0.8}) {
        const ShapePtr ls = makePlaced(loadLevelSet(file("cube.vdb"), vs), moved);
        const double want = 4096 / (vs * vs * vs);
        const double v = double(totalMass(*makeClay(*ls, m0))) / m0, r = rampVolume(*ls);
        std::printf(
            "level-set cube 16 rotated, read at voxel size %g and moved 0.37: %.4f voxels (%+.4f %%; the "
            "ramp %+.3f %%)\n",
            vs, v, 100 * (v - want) / want, 100 * (r - want) / want);
        EXPECT_NEAR(v, want, 0.003 * want);
    }

    // An L-shaped prism: a concave edge (the distance is the min of two planes outside it). OpenVDB's
    // meshToLevelSet is not exact there (at offset 0 the voxel on the edge reads -1, its diagonal
    // neighbours inside -1.81 for -1.41), so the edge's voxels fall back to the ramp: +0.2 % and
    // +0.4 % (the ramp alone: +1.8 %; with the exact distance, the rule gives +0.06 % / +0.03 %).
    const std::vector<openvdb::Vec3s> l2 = {{-8, -8, 0}, {8, -8, 0}, {8, 0, 0},
                                            {0, 0, 0},   {0, 8, 0},  {-8, 8, 0}};
    for (const double off : {0.0, 0.3}) {
        points.clear();
        for (const float z : {-8.f, 8.f})
            for (const auto& p : l2)
                points.emplace_back(p[0] + float(off), p[1] + float(off), z + float(off));
        quads.clear();
        for (uint32_t i = 0; i < 6; ++i) // the sides, outward
            quads.emplace_back(i, (i + 1) % 6, 6 + (i + 1) % 6, 6 + i);
        // The caps as fans from the concave corner (index 3): the L is star-shaped from it.
        const uint32_t inv = openvdb::util::INVALID_IDX;
        for (const auto& t : std::vector<std::array<uint32_t, 2>>{{4, 5}, {5, 0}, {0, 1}, {1, 2}}) {
            quads.emplace_back(3, t[1], t[0], inv);         // bottom (z = -8), facing -z
            quads.emplace_back(9, 6 + t[0], 6 + t[1], inv); // top (z = 8), facing +z
        }
        writeMeshLevelSet(file("l.vdb"), points, quads);
        const double want = (16 * 16 - 8 * 8) * 16;
        const double v = clayVolumeOfLevelSet(file("l.vdb"), m0),
                     r = rampVolume(*loadLevelSet(file("l.vdb")));
        std::printf("level-set L prism moved %g: %.4f voxels (%+.4f %%; the ramp %+.3f %%)\n", off, v,
                    100 * (v - want) / want, 100 * (r - want) / want);
        EXPECT_NEAR(v, want, 0.005 * want);
    }

    // The fractions do not depend on the thread count.
    cubeMesh(8, 30, 20, {0.13, 0.13, 0.13}, points, quads);
    writeMeshLevelSet(file("cube.vdb"), points, quads);
    uint64_t hashes[2];
    for (int i = 0; i < 2; ++i) {
        tbb::global_control threads(tbb::global_control::max_allowed_parallelism, i == 0 ? 1 : 3);
        hashes[i] = contentHash(*makeClay(*loadLevelSet(file("cube.vdb")), 1000));
    }
    EXPECT_EQ(hashes[0], hashes[1]);
}

// Mesh out, mesh clay in: the clay keeps its place and the mesh's volume, and the clay's own volume
// when the mesh is written to keep it.
TEST_F(InteropTest, MeshRoundTripKeepsPlaceAndVolume)
{
    const double vs = 0.1;
    writeText(file("sphere.obj"), sphereObj({{0.3, -0.2, 0.5}}, 0.95, 24, 48));
    const MassGridPtr ball = makeClay(*loadMesh(file("sphere.obj"), vs), 1000);
    setClayTransform(*ball, vs, UpAxis::Y);
    writeSurfaceMesh(file("ball.obj"), *ball, 1000);
    const double meshVolume = objVolumeOf(file("ball.obj")) / (vs * vs * vs);
    const MassGridPtr back = makeClay(*loadMesh(file("ball.obj"), vs), 1000);
    const double before = double(totalMass(*ball)) / 1000, after = double(totalMass(*back)) / 1000;
    std::printf("ball clay %.3f voxels, its mesh %.3f, mesh clay %.3f (%+.3f %% of the clay)\n", before,
                meshVolume, after, 100 * (after - before) / before);
    EXPECT_NEAR(after, meshVolume, 0.0005 * meshVolume);
    // Written to keep the clay's volume, the mesh gives it back within 0.5 %: smooth clay and a box
    // of whole cells (whose edges marching cubes cuts).
    writeSurfaceMesh(file("kept.obj"), *ball, 1000, 0.5, /*keepClayVolume=*/true);
    const double kept = double(totalMass(*makeClay(*loadMesh(file("kept.obj"), vs), 1000))) / 1000;
    EXPECT_NEAR(kept, before, 0.005 * before);
    const MassGridPtr box = boxClay(Coord(-3, 2, 5), Coord(16, 11, 14), 1000, vs);
    writeSurfaceMesh(file("box.obj"), *box, 1000, 0.5, true);
    const double boxBack = double(totalMass(*makeClay(*loadMesh(file("box.obj"), vs), 1000))) / 1000;
    EXPECT_NEAR(boxBack, 2000, 0.005 * 2000);
    std::printf("kept volume: ball %.3f -> %.3f (%+.3f %%), box 2000 -> %.3f (%+.3f %%)\n", before, kept,
                100 * (kept - before) / before, boxBack, 100 * (boxBack - 2000) / 2000);
    // Same place: the same centre of mass, to a hundredth of a voxel.
    auto centre = [](const MassGrid& g) {
        Vec3 c{{0, 0, 0}};
        double m = 0;
        for (auto it = g.cbeginValueOn(); it; ++it) {
            for (int i = 0; i < 3; ++i)
                c[i] += double(*it) * it.getCoord()[i];
            m += *it;
        }
        return Vec3{{c[0] / m, c[1] / m, c[2] / m}};
    };
    const Vec3 a = centre(*ball), b = centre(*back);
    const Vec3 c = centre(*box), d = centre(*makeClay(*loadMesh(file("box.obj"), vs), 1000));
    for (int i = 0; i < 3; ++i) {
        EXPECT_NEAR(a[i], b[i], 0.01) << "axis " << i;
        EXPECT_NEAR(c[i], d[i], 0.01) << "box, axis " << i;
    }
}

// ---- Import: PLY meshes, fog volumes --------------------------------------------------------------

// PLY: what `vdbclay mesh` writes, and ordinary ASCII / binary little-endian files with other
// properties and elements; others are refused naming the file and what is wrong.
TEST_F(InteropTest, PlyMeshesAreRead)
{
    const double vs = 0.5;
    const MassGridPtr clay = boxClay(Coord(-3, 2, 5), Coord(6, 11, 9), 1000, vs);
    writeSurfaceMesh(file("box.ply"), *clay, 1000);
    writeSurfaceMesh(file("box.obj"), *clay, 1000);
    EXPECT_EQ(contentHash(*makeClay(*loadMesh(file("box.ply"), vs), 1000)),
              contentHash(*makeClay(*loadMesh(file("box.obj"), vs), 1000)));

    // Binary little endian: a 16-unit cube, vertices with normals, quads with a uchar count and
    // int indices, then an element the reader skips.
    std::string bin = "ply\nformat binary_little_endian 1.0\ncomment test\nelement vertex 8\n"
                      "property float x\nproperty float y\nproperty double z\nproperty uchar red\n"
                      "element face 6\nproperty list uchar int vertex_indices\nproperty float quality\n"
                      "element edge 1\nproperty int vertex1\nproperty int vertex2\nend_header\n";
    auto put = [&bin](const auto v) { bin.append(reinterpret_cast<const char*>(&v), sizeof v); };
    for (int c = 0; c < 8; ++c) {
        put(float((c & 1) ? 8 : -8));
        put(float((c & 2) ? 8 : -8));
        put(double((c & 4) ? 8 : -8));
        put(uint8_t(200));
    }
    const int q[6][4] = {{0, 2, 3, 1}, {4, 5, 7, 6}, {0, 1, 5, 4}, {2, 6, 7, 3}, {0, 4, 6, 2}, {1, 3, 7, 5}};
    for (const auto& f : q) {
        put(uint8_t(4));
        for (int i : f)
            put(int32_t(i));
        put(0.5f);
    }
    put(int32_t(0));
    put(int32_t(1));
    writeText(file("cube.ply"), bin);
    const MassGridPtr cube = makeClay(*loadMesh(file("cube.ply")), 1000);
    EXPECT_EQ(totalMass(*cube), int64_t(4096) * 1000);
    EXPECT_EQ(cube->tree().getValue(Coord(8, 8, 8)), 125);

    struct Bad {
        const char* text;
        const char* part;
    };
    for (
        const Bad& b :
        {Bad{"ply\nformat binary_big_endian 1.0\nelement vertex 0\nend_header\n", "binary_big_endian"},
         Bad{"ply\nformat ascii 1.0\nelement vertex 3\nproperty float x\nproperty float y\nelement face 1\n"
             "property list uchar int vertex_indices\nend_header\n0 0\n1 0\n0 1\n3 0 1 2\n",
             "element \"vertex\" has no scalar properties x, y and z"},
         Bad{"ply\nformat ascii 1.0\nelement vertex 3\nproperty float x\nproperty float y\nproperty float z\n"
             "end_header\n0 0 0\n1 0 0\n0 1 0\n",
             "no element \"face\""},
         Bad{"ply\nformat ascii 1.0\nelement vertex 3\nproperty float x\nproperty float y\nproperty float z\n"
             "element face 1\nproperty list uchar int vertex_indices\nend_header\n0 0 0\n1 0 0\n0 1 0\n3 0 1 "
             "7\n",
             "element \"face\" item 0: vertex index 7 out of range"},
         Bad{"ply\nformat ascii 1.0\nelement vertex 3\nproperty float x\nproperty float y\nproperty float z\n"
             "element face 1\nproperty list uchar int vertex_indices\nend_header\n0 0 0\n1 0 0\n",
             "element \"vertex\" ends after 2 of 3 items"}}) {
        writeText(file("bad.ply"), b.text);
        const std::string e = errorOf([&] { loadMesh(file("bad.ply")); });
        EXPECT_TRUE(contains(e, "bad.ply") && contains(e, b.part)) << e;
    }
}

// Fog volumes (a FloatGrid of class fog volume, density 1 = a full cell): round(density x M) per
// voxel, tiles included, voxel for voxel at the grid's voxel size; what is not a fog volume, or
// holds a negative density, is refused naming the file and the grid.
TEST_F(InteropTest, FogVolumesImportAsClay)
{
    auto fog = openvdb::FloatGrid::create(0.f);
    fog->setName("smoke");
    fog->setGridClass(openvdb::GRID_FOG_VOLUME);
    fog->setTransform(openvdb::math::Transform::createLinearTransform(0.25));
    fog->tree().setValue(Coord(1, 2, 3), 0.25f);
    fog->tree().setValue(Coord(-4, 0, 0), 1.5f);        // overfull
    fog->tree().setValue(Coord(5, 0, 0), 0.0004f);      // rounds to no clay
    fog->tree().addTile(1, Coord(64, 0, 0), 1.f, true); // an 8^3 tile of full cells
    openvdb::io::File(file("fog.vdb")).write({fog});
    EXPECT_EQ(fogGridToImport(file("fog.vdb"), ""), "smoke");
    const FogClay c = readFogAsClay(file("fog.vdb"), "smoke", 1000);
    EXPECT_EQ(c.voxelSize, 0.25);
    EXPECT_EQ(c.mass->tree().getValue(Coord(1, 2, 3)), 250);
    EXPECT_EQ(c.mass->tree().getValue(Coord(-4, 0, 0)), 1500);
    EXPECT_EQ(c.mass->tree().getValue(Coord(70, 7, 7)), 1000);
    EXPECT_EQ(clayVoxelCount(*c.mass), uint64_t(2 + 512));
    EXPECT_EQ(totalMass(*c.mass), int64_t(250 + 1500 + 512 * 1000));
    EXPECT_TRUE(contains(c.note, "fog volume") && contains(c.note, "smoke") &&
                contains(c.note, "round(density x 1000)"))
        << c.note;
    // 2D: the z = 0 layer only.
    EXPECT_EQ(totalMass(*readFogAsClay(file("fog.vdb"), "smoke", 1000, 2).mass), int64_t(1500 + 64 * 1000));

    // A clay file: its surface level set comes first; its density, asked for, is the clay again.
    const MassGridPtr clay = boxClay(Coord(0, 0, 0), Coord(3, 3, 3), 700, 1.0);
    clay->tree().setValue(Coord(1, 1, 1), 1234);
    ClayMeta meta;
    writeClayFile(file("clay.vdb"), *clay, meta);
    EXPECT_EQ(fogGridToImport(file("clay.vdb"), ""), "");
    EXPECT_EQ(fogGridToImport(file("clay.vdb"), "density"), "density");
    EXPECT_EQ(contentHash(*readFogAsClay(file("clay.vdb"), "density", 1000).mass), contentHash(*clay));

    fog->tree().setValue(Coord(0, 0, 0), -0.5f);
    openvdb::io::File(file("neg.vdb")).write({fog});
    std::string e = errorOf([&] { readFogAsClay(file("neg.vdb"), "smoke", 1000); });
    EXPECT_TRUE(contains(e, "neg.vdb") && contains(e, "\"smoke\"") && contains(e, "-0.5")) << e;
    e = errorOf([&] { readFogAsClay(file("clay.vdb"), "surface", 1000); });
    EXPECT_TRUE(contains(e, "clay.vdb") && contains(e, "\"surface\"") && contains(e, "level set")) << e;
    e = errorOf([&] { readFogAsClay(file("clay.vdb"), "mass", 1000); });
    EXPECT_TRUE(contains(e, "\"mass\"") && contains(e, "expected a FloatGrid fog volume")) << e;
}

// `render` and `mesh` take any .vdb: the clay grid "mass", else the first fog
// volume, else the first level set (readAsClay), in the file's world units; a note names the grid.
TEST_F(InteropTest, RenderAndMeshReadFogVolumesAndLevelSets)
{
    auto ball =
        openvdb::tools::createLevelSetSphere<openvdb::FloatGrid>(5.f, openvdb::Vec3f(2.f, 1.f, 0.f), 0.5f);
    ball->setName("ball");
    openvdb::io::File(file("ls.vdb")).write({ball});
    std::string note;
    const ClayFile ls = readAsClay(file("ls.vdb"), note);
    EXPECT_TRUE(contains(note, "level set \"ball\"")) << note;
    EXPECT_EQ(ls.meta.voxelSize, 0.5);
    const double want = 4.0 / 3.0 * M_PI * 1000; // radius 10 voxels
    EXPECT_NEAR(double(totalMass(*ls.mass)) / 1000, want, 0.005 * want);
    writeSurfaceMesh(file("ls.obj"), *ls.mass, ls.meta.rule.threshold);
    Vec3 lo, hi;
    objBounds(file("ls.obj"), lo, hi);
    EXPECT_NEAR(lo[0], 2 - 5, 0.1); // world units: the ball's own place and size
    EXPECT_NEAR(hi[0], 2 + 5, 0.1);
    EXPECT_NEAR(lo[1], 1 - 5, 0.1);

    auto fog = openvdb::FloatGrid::create(0.f);
    fog->setName("smoke");
    fog->setGridClass(openvdb::GRID_FOG_VOLUME);
    fog->setTransform(openvdb::math::Transform::createLinearTransform(2.0));
    fog->tree().fill(openvdb::CoordBBox(Coord(0, 0, 0), Coord(3, 3, 3)), 0.5f, true);
    openvdb::io::File(file("fog.vdb")).write({ball, fog}); // a fog volume comes before a level set
    const ClayFile f = readAsClay(file("fog.vdb"), note);
    EXPECT_TRUE(contains(note, "fog volume \"smoke\"")) << note;
    EXPECT_EQ(totalMass(*f.mass), int64_t(64) * 500);
    EXPECT_EQ(f.mass->transform().indexToWorld(openvdb::Vec3d(1, 0, 0)), openvdb::Vec3d(2, 0, 0));

    const MassGridPtr clay = boxClay(Coord(0, 0, 0), Coord(3, 3, 3), 700, 1.0);
    writeClayFile(file("clay.vdb"), *clay, ClayMeta());
    EXPECT_EQ(contentHash(*readAsClay(file("clay.vdb"), note).mass), contentHash(*clay));
    EXPECT_EQ(note, "");

    auto other = openvdb::Int32Grid::create(0);
    other->setName("counts");
    openvdb::io::File(file("other.vdb")).write({other});
    const std::string e = errorOf([&] { readAsClay(file("other.vdb"), note); });
    EXPECT_TRUE(contains(e, "other.vdb") && contains(e, "no clay grid \"mass\", fog volume or level set") &&
                contains(e, "\"counts\""))
        << e;
}

namespace {

/// A fog volume named "smoke" with @a xform, density 1 in voxels lo..hi, written to @a path.
void writeFog(const std::string& path, openvdb::math::Transform::Ptr xform, Coord lo, Coord hi,
              openvdb::GridClass cls = openvdb::GRID_FOG_VOLUME)
{
    auto fog = openvdb::FloatGrid::create(0.f);
    fog->setName("smoke");
    fog->setGridClass(cls);
    fog->setTransform(xform);
    fog->tree().fill(openvdb::CoordBBox(lo, hi), 1.f, true);
    fog->tree().voxelizeActiveTiles();
    openvdb::io::File(path).write({fog});
}

/// Where @a grid's active voxels lie in the world: (min, max) of their centres.
std::pair<openvdb::Vec3d, openvdb::Vec3d> worldCentres(const openvdb::GridBase& grid)
{
    const openvdb::CoordBBox b = grid.evalActiveVoxelBoundingBox();
    openvdb::Vec3d lo(1e300), hi(-1e300);
    for (int c = 0; c < 8; ++c) {
        const openvdb::Vec3d w = grid.transform().indexToWorld(
            openvdb::Vec3d(c & 1 ? b.max().x() : b.min().x(), c & 2 ? b.max().y() : b.min().y(),
                           c & 4 ? b.max().z() : b.min().z()));
        lo = openvdb::math::minComponent(lo, w);
        hi = openvdb::math::maxComponent(hi, w);
    }
    return {lo, hi};
}

} // namespace

// A fog volume keeps its place in the world: its translation (whole voxels exactly, a fraction
// rounded and said), a quarter turn of its axes, and vdbclay's own z-up density its up axis.
TEST_F(InteropTest, FogVolumeKeepsItsTransform)
{
    // At x 5 (world), voxel size 1: the clay's voxels lie at x 5 .. 8 as the fog's do.
    auto xf = openvdb::math::Transform::createLinearTransform(1.0);
    xf->postTranslate(openvdb::Vec3d(5, 0, 0));
    writeFog(file("moved.vdb"), xf, Coord(0, 0, 0), Coord(3, 3, 3));
    FogClay c = readFogAsClay(file("moved.vdb"), "smoke", 1000);
    EXPECT_EQ(c.up, UpAxis::Y);
    EXPECT_EQ(c.mass->evalActiveVoxelBoundingBox(), openvdb::CoordBBox(Coord(5, 0, 0), Coord(8, 3, 3)));
    EXPECT_EQ(totalMass(*c.mass), 64 * 1000);
    EXPECT_FALSE(contains(c.note, "rounded")) << c.note;
    // Written and read back as clay: the same world place.
    ClayMeta meta;
    meta.voxelSize = c.voxelSize;
    meta.up = c.up;
    writeClayFile(file("moved-clay.vdb"), *c.mass, meta);
    const ClayFile back = readClayFile(file("moved-clay.vdb"));
    auto fogGrid = openvdb::io::File(file("moved.vdb"));
    fogGrid.open();
    const auto fogWorld = worldCentres(*fogGrid.readGrid("smoke"));
    fogGrid.close();
    const auto clayWorld = worldCentres(*back.mass);
    EXPECT_EQ(clayWorld.first, fogWorld.first);
    EXPECT_EQ(clayWorld.second, fogWorld.second);

    // Voxel size 0.5 at x 1.3: 2.6 voxels, rounded to 3 and said so.
    xf = openvdb::math::Transform::createLinearTransform(0.5);
    xf->postTranslate(openvdb::Vec3d(1.3, 0, 0));
    writeFog(file("frac.vdb"), xf, Coord(0, 0, 0), Coord(1, 1, 1));
    c = readFogAsClay(file("frac.vdb"), "smoke", 1000);
    EXPECT_EQ(c.mass->evalActiveVoxelBoundingBox(), openvdb::CoordBBox(Coord(3, 0, 0), Coord(4, 1, 1)));
    EXPECT_TRUE(contains(c.note, "0.4 voxel off the clay's grid, rounded")) << c.note;

    // vdbclay's own z-up file: its density is read back z up, voxel for voxel.
    const MassGridPtr clay = boxClay(Coord(0, 0, 0), Coord(3, 5, 3), 1000, 1.0);
    ClayMeta zmeta;
    zmeta.up = UpAxis::Z;
    zmeta.voxelSize = 0.25;
    writeClayFile(file("z.vdb"), *clay, zmeta);
    c = readFogAsClay(file("z.vdb"), "density", 1000);
    EXPECT_EQ(c.up, UpAxis::Z);
    EXPECT_EQ(c.voxelSize, 0.25);
    EXPECT_EQ(contentHash(*c.mass), contentHash(*clay));
    EXPECT_TRUE(contains(c.note, "(z up)")) << c.note;
    // Asked for y up, the same voxels in the same world place: index (x, y, z) of the file is world
    // (x, -z, y) x 0.25, so they land at (x, -z, y).
    c = readFogAsClay(file("z.vdb"), "density", 1000, 3, false, UpAxis::Y);
    EXPECT_EQ(c.up, UpAxis::Y);
    EXPECT_EQ(totalMass(*c.mass), totalMass(*clay));
    EXPECT_EQ(c.mass->evalActiveVoxelBoundingBox(), openvdb::CoordBBox(Coord(0, -3, 0), Coord(3, 0, 5)));

    // A fog turned by 45 degrees is not voxel for voxel: refused.
    xf = openvdb::math::Transform::createLinearTransform(1.0);
    xf->postRotate(M_PI / 4, openvdb::math::Y_AXIS);
    writeFog(file("turned.vdb"), xf, Coord(0, 0, 0), Coord(1, 1, 1));
    const std::string e = errorOf([&] { readFogAsClay(file("turned.vdb"), "smoke", 1000); });
    EXPECT_TRUE(contains(e, "turned.vdb") && contains(e, "\"smoke\"") &&
                contains(e, "other than by quarter turns"))
        << e;
}

// A FloatGrid of class unknown is neither a level set nor a fog volume: refused with the way to ask
// for it as density, and read as density when asked.
TEST_F(InteropTest, UnknownFloatGridReadsAsDensityWhenAsked)
{
    writeFog(file("unknown.vdb"), openvdb::math::Transform::createLinearTransform(0.1), Coord(0, 0, 0),
             Coord(1, 2, 3), openvdb::GRID_UNKNOWN);
    std::string e = errorOf([&] { fogGridToImport(file("unknown.vdb"), ""); });
    EXPECT_TRUE(contains(e, "grid \"smoke\" is a FloatGrid of class unknown") && contains(e, "--as density"))
        << e;
    e = errorOf([&] { fogGridToImport(file("unknown.vdb"), "smoke"); });
    EXPECT_TRUE(contains(e, "--as density")) << e;
    EXPECT_EQ(fogGridToImport(file("unknown.vdb"), "", true), "smoke");
    EXPECT_EQ(fogGridToImport(file("unknown.vdb"), "smoke", true), "smoke");
    e = errorOf([&] { readFogAsClay(file("unknown.vdb"), "smoke", 1000); });
    EXPECT_TRUE(contains(e, "not a FloatGrid fog volume (class unknown)")) << e;
    const FogClay c = readFogAsClay(file("unknown.vdb"), "smoke", 1000, 3, true);
    EXPECT_EQ(totalMass(*c.mass), 24 * 1000);
    EXPECT_EQ(c.voxelSize, 0.1);
    EXPECT_TRUE(contains(c.note, "read as density (class unknown)")) << c.note;
    // A level set is not density, even when asked.
    const MassGridPtr clay = boxClay(Coord(0, 0, 0), Coord(3, 3, 3), 1000, 1.0);
    writeClayFile(file("clay.vdb"), *clay, ClayMeta());
    e = errorOf([&] { fogGridToImport(file("clay.vdb"), "surface", true); });
    EXPECT_TRUE(contains(e, "grid \"surface\" is a level set") && contains(e, "without --as density")) << e;
    EXPECT_EQ(fogGridToImport(file("clay.vdb"), "", true), "density");
}

// Meshes: the box of a file's vertices in its own units (import --resolution divides it), and the
// surface written as binary STL that loadMesh reads back onto the same voxels.
TEST_F(InteropTest, MeshBoundsAndStlSurface)
{
    {
        std::ofstream o(file("tri.obj"));
        o << "v -1 0 0.5\nv 2 0 0.5\nv 0 3 -4\nv 0 0 1\nf 1 2 3\nf 1 2 4\nf 1 3 4\nf 2 3 4\n";
    }
    const std::array<Vec3, 2> b = meshFileBounds(file("tri.obj"));
    EXPECT_EQ(b[0], (Vec3{{-1, 0, -4}}));
    EXPECT_EQ(b[1], (Vec3{{2, 3, 1}}));
    EXPECT_TRUE(contains(errorOf([&] { meshFileBounds(file("missing.obj")); }), "missing.obj"));

    const MassGridPtr clay = boxClay(Coord(0, 0, 0), Coord(9, 9, 9), 1000, 0.5);
    writeSurfaceMesh(file("s.stl"), *clay, 1000);
    writeSurfaceMesh(file("s.obj"), *clay, 1000);
    std::ifstream in(file("s.stl"), std::ios::binary);
    std::string data((std::istreambuf_iterator<char>(in)), std::istreambuf_iterator<char>());
    ASSERT_GE(data.size(), 84u);
    EXPECT_EQ(data.compare(0, 8, "vdbclay "), 0);
    uint32_t n = 0;
    std::memcpy(&n, data.data() + 80, 4);
    EXPECT_GT(n, 0u);
    EXPECT_EQ(data.size(), 84 + 50 * size_t(n));
    // The STL and the OBJ are the same surface: the same clay from both.
    const MassGridPtr fromStl = makeClay(*loadMesh(file("s.stl"), 0.5), 1000);
    const MassGridPtr fromObj = makeClay(*loadMesh(file("s.obj"), 0.5), 1000);
    EXPECT_EQ(contentHash(*fromStl), contentHash(*fromObj));
    EXPECT_EQ(fromStl->evalActiveVoxelBoundingBox(), openvdb::CoordBBox(Coord(0, 0, 0), Coord(9, 9, 9)));
    EXPECT_TRUE(
        contains(errorOf([&] { writeSurfaceMesh(file("s.fbx"), *clay, 1000); }), "use .obj, .ply or .stl"));
}
