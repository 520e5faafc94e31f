// Clay files, meshes, clay from shapes and pictures: round trips, atomic writes, refused input.
#include <vdbclay/AtomicWrite.h>
#include <vdbclay/Automaton.h>
#include <vdbclay/IO.h>
#include <vdbclay/Metrics.h>
#include <vdbclay/Render.h>
#include <vdbclay/Shapes.h>
#include <vdbclay/SurfaceMesh.h>

#include <openvdb/io/File.h>
#include <openvdb/openvdb.h>

#include <gtest/gtest.h>

#include "TempDirTest.h"
#include "output/Surface.h"

#include <png.h>

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <iterator>
#include <set>
#include <sstream>
#include <string>
#include <thread>
#include <vector>

#include <sys/stat.h>
#include <unistd.h>

using namespace vdbclay;
using openvdb::Coord;
namespace fs = std::filesystem;

namespace {

/// A sphere for makeClay, independent of Shapes.cc.
class TestSphere : public Shape {
public:
    TestSphere(const Vec3& c, double r) : c_(c), r_(r) {}
    double distance(const Vec3& p) const override
    {
        const double dx = p[0] - c_[0], dy = p[1] - c_[1], dz = p[2] - c_[2];
        return std::sqrt(dx * dx + dy * dy + dz * dz) - r_;
    }
    Vec3 normal(const Vec3&) const override { return Vec3{{0, 1, 0}}; }
    Box bounds() const override
    {
        Box b;
        for (int a = 0; a < 3; ++a) {
            b.min[a] = int32_t(std::floor(c_[a] - r_));
            b.max[a] = int32_t(std::ceil(c_[a] + r_));
        }
        return b;
    }
    std::string describe() const override { return "test sphere"; }

private:
    Vec3 c_;
    double r_;
};

class IOTest : public vdbclay_test::TempDirTest {
protected:
    /// Names in the test directory, to prove no temporary file is left behind.
    std::set<std::string> listing() const
    {
        std::set<std::string> names;
        for (const auto& e : fs::directory_iterator(dir))
            names.insert(e.path().filename().string());
        return names;
    }
};

std::string slurp(const std::string& path)
{
    std::ifstream in(path, std::ios::binary);
    return std::string(std::istreambuf_iterator<char>(in), std::istreambuf_iterator<char>());
}

void spit(const std::string& path, const std::string& bytes)
{
    std::ofstream out(path, std::ios::binary | std::ios::trunc);
    out.write(bytes.data(), std::streamsize(bytes.size()));
}

/// The message of the Error @a fn throws ("" if it throws nothing, "other" for another exception).
template <typename Fn> std::string errorOf(Fn&& fn)
{
    try {
        fn();
    } catch (const Error& e) {
        return e.what();
    } catch (...) {
        return "other exception";
    }
    return "";
}

bool contains(const std::string& s, const std::string& part)
{
    return s.find(part) != std::string::npos;
}

/// A lump with varied masses: a ball of full cells, some overloaded, some partial, some tiny.
MassGridPtr sampleClay(int32_t tc = 1000)
{
    auto g = openvdb::Int32Grid::create(0);
    auto acc = g->getAccessor();
    for (int x = -6; x <= 6; ++x)
        for (int y = -6; y <= 6; ++y)
            for (int z = -6; z <= 6; ++z) {
                const int r2 = x * x + y * y + z * z;
                if (r2 > 36) continue;
                int32_t m = tc;
                if (r2 > 25) m = 1 + (x * 7 + y * 13 + z * 29 + 300) % tc; // partial rim
                if (r2 < 4) m = 3 * tc + x;                                // overloaded core
                acc.setValueOn(Coord(x, y, z), m);
            }
    return g;
}

ClayMeta sampleMeta()
{
    ClayMeta m;
    m.dimensions = 3;
    m.rule.rule = Rule::Sorted;
    m.rule.threshold = 1000;
    m.rule.alpha = 0.25;
    m.seed = 0xFEDCBA9876543210ull;
    m.steps = 12345;
    m.frames = 67;
    m.voxelSize = 0.5;
    return m;
}

openvdb::GridBase::Ptr readGrid(const std::string& path, const std::string& name)
{
    openvdb::io::File f(path);
    f.open(false);
    auto g = f.readGrid(name);
    f.close();
    return g;
}

/// PNG facts read straight from the bytes (signature, IHDR) and through libpng (the pixels).
struct PngInfo {
    bool signature = false;
    uint32_t width = 0, height = 0;
    size_t distinctColours = 0;
    std::vector<uint8_t> rgb;
};

PngInfo inspectPng(const std::string& path)
{
    PngInfo info;
    const std::string bytes = slurp(path);
    static const unsigned char sig[8] = {137, 80, 78, 71, 13, 10, 26, 10};
    info.signature =
        bytes.size() > 33 && std::memcmp(bytes.data(), sig, 8) == 0 && bytes.compare(12, 4, "IHDR") == 0;
    if (!info.signature) return info;
    auto be32 = [&](size_t at) {
        return uint32_t(uint8_t(bytes[at])) << 24 | uint32_t(uint8_t(bytes[at + 1])) << 16 |
               uint32_t(uint8_t(bytes[at + 2])) << 8 | uint32_t(uint8_t(bytes[at + 3]));
    };
    info.width = be32(16);
    info.height = be32(20);

    png_image image;
    std::memset(&image, 0, sizeof(image));
    image.version = PNG_IMAGE_VERSION;
    if (!png_image_begin_read_from_file(&image, path.c_str())) return info;
    image.format = PNG_FORMAT_RGB;
    info.rgb.resize(PNG_IMAGE_SIZE(image));
    if (!png_image_finish_read(&image, nullptr, info.rgb.data(), 0, nullptr)) {
        info.rgb.clear();
        return info;
    }
    std::set<uint32_t> colours;
    for (size_t i = 0; i + 2 < info.rgb.size(); i += 3) {
        colours.insert(uint32_t(info.rgb[i]) << 16 | uint32_t(info.rgb[i + 1]) << 8 | info.rgb[i + 2]);
    }
    info.distinctColours = colours.size();
    return info;
}

// ---------------------------------------------------------------------------------------------
// Clay files

TEST_F(IOTest, RoundTripIsExactWithMetadata)
{
    auto clay = sampleClay();
    const ClayMeta meta = sampleMeta();
    const std::string path = file("clay.vdb");
    writeClayFile(path, *clay, meta);

    const ClayFile back = readClayFile(path);
    ASSERT_TRUE(back.mass);
    EXPECT_EQ(contentHash(*back.mass), contentHash(*clay));
    EXPECT_EQ(totalMass(*back.mass), totalMass(*clay));
    EXPECT_EQ(clayVoxelCount(*back.mass), clayVoxelCount(*clay));
    EXPECT_TRUE(back.hasMeta);
    EXPECT_EQ(back.meta.dimensions, 3);
    EXPECT_EQ(back.meta.rule.rule, Rule::Sorted);
    EXPECT_EQ(back.meta.rule.threshold, 1000);
    EXPECT_EQ(back.meta.rule.alpha, 0.25);
    EXPECT_EQ(back.meta.seed, 0xFEDCBA9876543210ull);
    EXPECT_EQ(back.meta.steps, 12345u);
    EXPECT_EQ(back.meta.frames, 67u);
    EXPECT_EQ(back.meta.voxelSize, 0.5);
    EXPECT_FALSE(back.meta.version.empty());
    EXPECT_EQ(back.mass->voxelSize()[0], 0.5);
    EXPECT_EQ(listing(), std::set<std::string>{"clay.vdb"});

    // The caller's grid is not changed by writing (name, metadata, transform).
    EXPECT_EQ(clay->metaCount(), openvdb::Int32Grid::create(0)->metaCount());
    EXPECT_EQ(clay->voxelSize()[0], 1.0);
}

TEST_F(IOTest, AFileHoldsTheGridsNamedEachAsInTheFullFile)
{
    auto clay = sampleClay();
    const ClayMeta meta = sampleMeta();
    const std::string full = file("full.vdb");
    writeClayFile(full, *clay, meta);
    auto gridNames = [](const std::string& path) {
        openvdb::io::File f(path);
        f.open();
        std::vector<std::string> names;
        const openvdb::GridPtrVecPtr grids = f.readAllGridMetadata();
        for (const auto& g : *grids)
            names.push_back(g->getName());
        std::sort(names.begin(), names.end());
        return names;
    };
    EXPECT_EQ(gridNames(full), (std::vector<std::string>{"density", "mass", "surface"}));
    // Each grid as the full file holds it, value for value.
    auto sameFloatGrid = [&](const std::string& path, const std::string& name) {
        auto a = openvdb::gridPtrCast<openvdb::FloatGrid>(readGrid(path, name));
        auto b = openvdb::gridPtrCast<openvdb::FloatGrid>(readGrid(full, name));
        ASSERT_TRUE(a && b) << path << " " << name;
        EXPECT_EQ(a->getGridClass(), b->getGridClass());
        EXPECT_TRUE(a->tree().hasSameTopology(b->tree())) << path << " " << name;
        auto bAcc = b->getConstAccessor();
        for (auto it = a->cbeginValueAll(); it; ++it)
            ASSERT_EQ(*it, bAcc.getValue(it.getCoord())) << path << " " << name << " " << it.getCoord();
    };
    const std::string massOnly = file("mass.vdb");
    writeClayFile(massOnly, *clay, meta, parseClayGrids("mass"));
    EXPECT_EQ(gridNames(massOnly), std::vector<std::string>{"mass"});
    const ClayFile back = readClayFile(massOnly);
    EXPECT_EQ(contentHash(*back.mass), contentHash(*clay));
    EXPECT_EQ(back.meta.seed, meta.seed);

    const std::string fog = file("density.vdb");
    writeClayFile(fog, *clay, meta, parseClayGrids("density"));
    EXPECT_EQ(gridNames(fog), std::vector<std::string>{"density"});
    sameFloatGrid(fog, "density");
    EXPECT_EQ(readGrid(fog, "density")->metaValue<int32_t>("vdbclay_threshold"), 1000);
    EXPECT_TRUE(
        contains(errorOf([&] { readClayFile(fog); }), "has no grid named \"mass\" (grids: \"density\")"))
        << errorOf([&] { readClayFile(fog); });

    // The surface alone (swept from a density not kept) carries the clay's metadata itself.
    const std::string level = file("surface.vdb");
    writeClayFile(level, *clay, meta, parseClayGrids("surface"));
    EXPECT_EQ(gridNames(level), std::vector<std::string>{"surface"});
    sameFloatGrid(level, "surface");
    EXPECT_EQ(readGrid(level, "surface")->metaValue<int32_t>("vdbclay_threshold"), 1000);

    const std::string two = file("two.vdb");
    writeClayFile(two, *clay, meta, parseClayGrids("surface,mass"));
    EXPECT_EQ(gridNames(two), (std::vector<std::string>{"mass", "surface"}));
    sameFloatGrid(two, "surface");
    EXPECT_FALSE(readGrid(two, "surface")->getMetadata<openvdb::Int32Metadata>("vdbclay_threshold"));

    // None named: refused, nothing written.
    const std::string none = file("none.vdb");
    EXPECT_EQ(errorOf([&] {
                  writeClayFile(none, *clay, meta, ClayGrids{false, false, false});
              }),
              "cannot write " + none + ": no grid named (mass, density or surface)");
    EXPECT_FALSE(fs::exists(none));
}

TEST_F(IOTest, GridNamesAreParsedAndEveryWrongOneIsNamed)
{
    const ClayGrids g = parseClayGrids("density,mass");
    EXPECT_TRUE(g.mass && g.density && !g.surface);
    EXPECT_EQ(clayGridsName(g), "mass,density");
    EXPECT_EQ(clayGridsName(ClayGrids()), "mass,density,surface");
    EXPECT_EQ(errorOf([] { parseClayGrids("fog"); }),
              "\"fog\" is not a grid of a clay file (mass, density or surface)");
    EXPECT_EQ(errorOf([] { parseClayGrids("mass,,surface"); }),
              "\"\" is not a grid of a clay file (mass, density or surface) in \"mass,,surface\"");
    EXPECT_EQ(errorOf([] { parseClayGrids(""); }),
              "\"\" is not a grid of a clay file (mass, density or surface)");
    EXPECT_EQ(errorOf([] { parseClayGrids("mass,surface,mass"); }),
              "grid \"mass\" is named twice in \"mass,surface,mass\"");
}

TEST_F(IOTest, FileWithoutMetadataReadsWithDefaults)
{
    auto g = sampleClay();
    g->setName("mass");
    const std::string path = file("plain.vdb");
    openvdb::io::File(path).write({g});
    const ClayFile back = readClayFile(path);
    EXPECT_FALSE(back.hasMeta);
    EXPECT_EQ(contentHash(*back.mass), contentHash(*g));
    EXPECT_EQ(back.meta.rule.threshold, ClayMeta().rule.threshold);
}

TEST_F(IOTest, DensityIsMassOverThreshold)
{
    auto clay = sampleClay(800);
    ClayMeta meta = sampleMeta();
    meta.rule.threshold = 800;
    const std::string path = file("d.vdb");
    writeClayFile(path, *clay, meta);

    auto density = openvdb::gridPtrCast<openvdb::FloatGrid>(readGrid(path, "density"));
    ASSERT_TRUE(density);
    EXPECT_EQ(density->getGridClass(), openvdb::GRID_FOG_VOLUME);
    EXPECT_EQ(density->voxelSize()[0], 0.5);
    EXPECT_EQ(density->activeVoxelCount(), clayVoxelCount(*clay));
    auto dacc = density->getConstAccessor();
    size_t checked = 0;
    for (auto it = clay->cbeginValueOn(); it; ++it) {
        ASSERT_TRUE(dacc.isValueOn(it.getCoord()));
        EXPECT_EQ(dacc.getValue(it.getCoord()), float(double(*it) / 800.0)) << it.getCoord();
        ++checked;
    }
    EXPECT_EQ(checked, clayVoxelCount(*clay));
    EXPECT_EQ(dacc.getValue(Coord(40, 40, 40)), 0.f);
}

TEST_F(IOTest, SurfaceIsNegativeInsidePositiveOutside)
{
    // Full cells in a ball of radius 8 (index space), voxel size 0.5.
    auto g = openvdb::Int32Grid::create(0);
    auto acc = g->getAccessor();
    for (int x = -8; x <= 8; ++x)
        for (int y = -8; y <= 8; ++y)
            for (int z = -8; z <= 8; ++z)
                if (x * x + y * y + z * z <= 64) acc.setValueOn(Coord(x, y, z), 1000);
    const std::string path = file("s.vdb");
    writeClayFile(path, *g, sampleMeta());

    auto surface = openvdb::gridPtrCast<openvdb::FloatGrid>(readGrid(path, "surface"));
    ASSERT_TRUE(surface);
    EXPECT_EQ(surface->getGridClass(), openvdb::GRID_LEVEL_SET);
    EXPECT_EQ(surface->voxelSize()[0], 0.5);
    auto sacc = surface->getConstAccessor();
    EXPECT_LT(sacc.getValue(Coord(0, 0, 0)), 0.f);
    EXPECT_LT(sacc.getValue(Coord(6, 0, 0)), 0.f);
    EXPECT_LT(sacc.getValue(Coord(0, -7, 0)), 0.f);
    EXPECT_GT(sacc.getValue(Coord(10, 0, 0)), 0.f);
    EXPECT_GT(sacc.getValue(Coord(0, 0, -10)), 0.f);
    EXPECT_GT(sacc.getValue(Coord(30, 30, 30)), 0.f);
    for (int x = -6; x <= 6; ++x)
        EXPECT_LT(sacc.getValue(Coord(x, 1, -1)), 0.f) << x;
}

TEST_F(IOTest, SurfaceLiesWhereCellsAreHalfFull)
{
    // A box of full cells -6..6: its faces at density 0.5 lie at +-6.5 voxels. Voxel size 0.5,
    // so distances (world units) are half the voxel distances.
    auto g = openvdb::Int32Grid::create(0);
    g->tree().fill(openvdb::CoordBBox(Coord(-6), Coord(6)), 1000, true);
    const std::string path = file("box.vdb");
    writeClayFile(path, *g, sampleMeta());
    auto surface = openvdb::gridPtrCast<openvdb::FloatGrid>(readGrid(path, "surface"));
    ASSERT_TRUE(surface);
    auto sacc = surface->getConstAccessor();
    EXPECT_NEAR(sacc.getValue(Coord(6, 0, 0)), -0.25f, 0.02f);
    EXPECT_NEAR(sacc.getValue(Coord(7, 0, 0)), 0.25f, 0.02f);
    EXPECT_NEAR(sacc.getValue(Coord(0, -6, 2)), -0.25f, 0.02f);
    EXPECT_NEAR(sacc.getValue(Coord(0, -8, 2)), 0.75f, 0.02f);
    EXPECT_NEAR(sacc.getValue(Coord(0, 0, 4)), -1.25f, 0.02f);

    // 2D clay is a slab one voxel thick: inside at z = 0, outside above and below.
    auto flat = openvdb::Int32Grid::create(0);
    flat->tree().fill(openvdb::CoordBBox(Coord(0, 0, 0), Coord(19, 19, 0)), 1000, true);
    ClayMeta meta = sampleMeta();
    meta.dimensions = 2;
    meta.voxelSize = 1;
    writeClayFile(path, *flat, meta);
    surface = openvdb::gridPtrCast<openvdb::FloatGrid>(readGrid(path, "surface"));
    ASSERT_TRUE(surface);
    sacc = surface->getConstAccessor();
    EXPECT_NEAR(sacc.getValue(Coord(10, 10, 0)), -0.5f, 0.02f);
    EXPECT_NEAR(sacc.getValue(Coord(10, 10, 1)), 0.5f, 0.02f);
    EXPECT_NEAR(sacc.getValue(Coord(10, 10, -1)), 0.5f, 0.02f);
    EXPECT_EQ(readClayFile(path).meta.dimensions, 2);
}

TEST_F(IOTest, TheSurfaceIsStoredAsHalfFloatsAndReadsBackWithinTheirPrecision)
{
    // A ball of full cells (voxel size 0.5): the surface in the file is the one computed, each value
    // rounded to a half float; density and mass stay exact.
    auto g = openvdb::Int32Grid::create(0);
    auto acc = g->getAccessor();
    for (int x = -12; x <= 12; ++x)
        for (int y = -12; y <= 12; ++y)
            for (int z = -12; z <= 12; ++z)
                if (x * x + y * y + z * z <= 140) acc.setValueOn(Coord(x, y, z), 700 + (x & 3) * 100);
    const std::string path = file("half.vdb");
    writeClayFile(path, *g, sampleMeta());
    EXPECT_TRUE(contains(describeVdb(path), "is_saved_as_half_float (bool) = true")) << describeVdb(path);
    EXPECT_EQ(contentHash(*readClayFile(path).mass), contentHash(*g));
    auto surface = openvdb::gridPtrCast<openvdb::FloatGrid>(readGrid(path, "surface"));
    auto density = openvdb::gridPtrCast<openvdb::FloatGrid>(readGrid(path, "density"));
    ASSERT_TRUE(surface && density);
    EXPECT_TRUE(surface->saveFloatAsHalf());
    EXPECT_FALSE(density->saveFloatAsHalf());
    EXPECT_EQ(surface->getGridClass(), openvdb::GRID_LEVEL_SET);
    EXPECT_EQ(surface->background(), 1.5f); // 3 voxels of 0.5
    const auto exact = io_internal::surfaceLevelSet(*io_internal::densityGrid(*g, 1000, 0.5), 0.5);
    EXPECT_EQ(surface->activeVoxelCount(), exact->activeVoxelCount());
    EXPECT_GT(surface->activeVoxelCount(), 1000u);
    auto e = exact->getConstAccessor();
    size_t differ = 0;
    for (auto it = surface->cbeginValueOn(); it; ++it) {
        const float want = e.getValue(it.getCoord());
        EXPECT_TRUE(e.isValueOn(it.getCoord()));
        EXPECT_LE(std::abs(*it - want), std::abs(want) * 0x1p-11f + 0x1p-25f) << it.getCoord();
        EXPECT_EQ(*it < 0, want < 0) << it.getCoord();
        differ += *it != want;
    }
    EXPECT_GT(differ, 0u); // rounded: this test sees half floats
    for (auto it = density->cbeginValueOn(); it; ++it)
        EXPECT_EQ(*it, float(double(g->tree().getValue(it.getCoord())) / 1000.0));

    // Voxel sizes whose band would leave the half floats' range keep 32-bit floats.
    for (double vs : {1e-4, 1e5}) {
        ClayMeta meta = sampleMeta();
        meta.voxelSize = vs;
        writeClayFile(path, *g, meta);
        surface = openvdb::gridPtrCast<openvdb::FloatGrid>(readGrid(path, "surface"));
        EXPECT_FALSE(surface->saveFloatAsHalf()) << vs;
        EXPECT_EQ(surface->background(), float(3 * vs)) << vs;
    }
}

TEST_F(IOTest, HalfFloatGridsOfAnyCompressionPassTheLayoutCheck)
{
    // OpenVDB writes no block at all for a node with no value to store as half floats (HalfWriter);
    // the check before OpenVDB reads a file follows it. A leaf, an inactive tile (a node with no active
    // value) and an active tile, under every compression.
    auto ls = openvdb::FloatGrid::create(3.f);
    ls->setName("ls");
    ls->setGridClass(openvdb::GRID_LEVEL_SET);
    ls->tree().setValue(Coord(1, 2, 3), 0.5f);
    ls->tree().addTile(1, Coord(64, 0, 0), -3.f, false);
    ls->tree().addTile(1, Coord(128, 0, 0), 1.25f, true);
    ls->setSaveFloatAsHalf(true);
    const std::string path = file("half.vdb");
    using namespace openvdb::io;
    for (uint32_t c :
         std::vector<uint32_t>{COMPRESS_NONE, COMPRESS_ZIP, COMPRESS_BLOSC, COMPRESS_ACTIVE_MASK,
                               COMPRESS_ZIP | COMPRESS_ACTIVE_MASK, COMPRESS_BLOSC | COMPRESS_ACTIVE_MASK}) {
        File out(path);
        out.setCompression(c);
        out.write({ls});
        std::string text;
        EXPECT_NO_THROW(text = describeVdb(path)) << c;
        EXPECT_TRUE(contains(text, "active voxels: 513")) << c << ": " << text;
        auto back = openvdb::gridPtrCast<openvdb::FloatGrid>(readGrid(path, "ls"));
        ASSERT_TRUE(back) << c;
        EXPECT_EQ(back->tree().getValue(Coord(1, 2, 3)), 0.5f) << c;
        EXPECT_EQ(back->tree().getValue(Coord(70, 1, 1)), -3.f) << c;
        EXPECT_EQ(back->tree().getValue(Coord(130, 1, 1)), 1.25f) << c;
    }
}

TEST_F(IOTest, WriteIntoMissingDirectoryThrowsAndLeavesNothing)
{
    auto clay = sampleClay();
    const std::string path = file("no/such/dir/clay.vdb");
    const std::string msg = errorOf([&] { writeClayFile(path, *clay, sampleMeta()); });
    EXPECT_TRUE(contains(msg, path)) << msg;
    EXPECT_TRUE(contains(msg, "No such file or directory")) << msg;
    EXPECT_TRUE(listing().empty());
    EXPECT_FALSE(fs::exists(file("no")));
}

TEST_F(IOTest, WriteOverExistingFileReplacesItWholly)
{
    const std::string path = file("clay.vdb");
    auto big = sampleClay();
    writeClayFile(path, *big, sampleMeta());
    const auto bigSize = fs::file_size(path);

    auto small = openvdb::Int32Grid::create(0);
    small->tree().setValue(Coord(100, 2, 3), 77);
    ClayMeta meta = sampleMeta();
    meta.steps = 1;
    writeClayFile(path, *small, meta);
    EXPECT_LT(fs::file_size(path), bigSize);
    const ClayFile back = readClayFile(path);
    EXPECT_EQ(contentHash(*back.mass), contentHash(*small));
    EXPECT_EQ(totalMass(*back.mass), 77);
    EXPECT_EQ(back.meta.steps, 1u);
    EXPECT_EQ(listing(), std::set<std::string>{"clay.vdb"});
}

TEST_F(IOTest, WriteOverTheFileTheClayWasReadFrom)
{
    const std::string path = file("clay.vdb");
    writeClayFile(path, *sampleClay(), sampleMeta());
    ClayFile c = readClayFile(path);
    c.mass->tree().setValue(Coord(0, 0, 0), 4321);
    c.meta.frames += 1;
    writeClayFile(path, *c.mass, c.meta);
    const ClayFile back = readClayFile(path);
    EXPECT_EQ(contentHash(*back.mass), contentHash(*c.mass));
    EXPECT_EQ(back.meta.frames, 68u);
    EXPECT_EQ(listing(), std::set<std::string>{"clay.vdb"});
}

TEST_F(IOTest, FailedWriteLeavesExistingFileUntouched)
{
    const std::string path = file("clay.vdb");
    writeClayFile(path, *sampleClay(), sampleMeta());
    const std::string before = slurp(path);
    ClayMeta bad = sampleMeta();
    bad.rule.threshold = 0;
    EXPECT_TRUE(contains(errorOf([&] { writeClayFile(path, *sampleClay(), bad); }), path));
    bad = sampleMeta();
    bad.voxelSize = -1;
    EXPECT_TRUE(contains(errorOf([&] { writeClayFile(path, *sampleClay(), bad); }), path));
    EXPECT_EQ(slurp(path), before);
    EXPECT_EQ(listing(), std::set<std::string>{"clay.vdb"});
    // A directory in the way is refused, not replaced.
    fs::create_directory(file("adir"));
    EXPECT_TRUE(
        contains(errorOf([&] { writeClayFile(file("adir"), *sampleClay(), sampleMeta()); }), "directory"));
    EXPECT_TRUE(fs::is_directory(file("adir")));
}

// ---------------------------------------------------------------------------------------------
// Refused input

TEST_F(IOTest, ReadMissingFile)
{
    const std::string path = file("missing.vdb");
    const std::string msg = errorOf([&] { readClayFile(path); });
    EXPECT_TRUE(contains(msg, path) && contains(msg, "no such file")) << msg;
    EXPECT_TRUE(contains(errorOf([&] { describeVdb(path); }), "no such file"));
}

TEST_F(IOTest, ReadEmptyAndTextFiles)
{
    const std::string empty = file("empty.vdb"), text = file("text.vdb");
    spit(empty, "");
    spit(text, "this is not a volume\nat all\n");
    for (const std::string& p : {empty, text}) {
        const std::string msg = errorOf([&] { readClayFile(p); });
        EXPECT_TRUE(contains(msg, p) && contains(msg, "not a .vdb file or is truncated")) << msg;
        EXPECT_TRUE(contains(errorOf([&] { describeVdb(p); }), "not a .vdb file")) << p;
    }
}

TEST_F(IOTest, ReadTruncatedFile)
{
    const std::string good = file("good.vdb");
    writeClayFile(good, *sampleClay(), sampleMeta());
    const std::string bytes = slurp(good);
    // Cut in half, and at other places: in the header, in "mass", in the last grid, its last byte.
    for (size_t keep : {bytes.size() / 2, size_t(20), bytes.size() / 10, bytes.size() * 9 / 10,
                        bytes.size() - 100, bytes.size() - 1}) {
        const std::string cut = file("cut.vdb");
        spit(cut, bytes.substr(0, keep));
        const std::string msg = errorOf([&] { readClayFile(cut); });
        EXPECT_TRUE(contains(msg, cut) && contains(msg, "not a .vdb file or is truncated"))
            << keep << " of " << bytes.size() << ": " << msg;
        // OpenVDB quotes the garbage it read; the message stays short and printable.
        EXPECT_LT(msg.size(), 400u) << msg;
        for (char c : msg)
            EXPECT_TRUE(c >= 32 && c < 127) << int(c);
        EXPECT_TRUE(contains(errorOf([&] { describeVdb(cut); }), "truncated"));
    }
}

TEST_F(IOTest, ReadWrongGridTypeAndMissingGrid)
{
    const std::string floats = file("floats.vdb");
    auto f = openvdb::FloatGrid::create(0.f);
    f->setName("mass");
    f->tree().setValue(Coord(1, 2, 3), 1.5f);
    openvdb::io::File(floats).write({f});
    std::string msg = errorOf([&] { readClayFile(floats); });
    EXPECT_EQ(msg, "grid \"mass\" in " + floats + " is a float grid, expected an Int32Grid");

    const std::string other = file("other.vdb");
    auto a = openvdb::Int32Grid::create(0);
    a->setName("clay");
    auto b = openvdb::FloatGrid::create(0.f);
    b->setName("density");
    openvdb::io::File(other).write({a, b});
    msg = errorOf([&] { readClayFile(other); });
    EXPECT_EQ(msg, other + " has no grid named \"mass\" (grids: \"clay\", \"density\")");
    EXPECT_NO_THROW(readClayFile(other, "clay"));
}

TEST_F(IOTest, NegativeMassIsRefused)
{
    auto g = openvdb::Int32Grid::create(0);
    g->setName("mass");
    g->tree().setValue(Coord(1, 2, 3), 10);
    g->tree().setValue(Coord(-4, 5, 6), -3);
    const std::string path = file("neg.vdb");
    openvdb::io::File(path).write({g});
    const std::string msg = errorOf([&] { readClayFile(path); });
    EXPECT_TRUE(contains(msg, path) && contains(msg, "negative") && contains(msg, "(-4, 5, 6)")) << msg;
}

TEST_F(IOTest, AClayFileRecordsItsLargestCellAndAFileThatExceedsItIsRefused)
{
    // writeClayFile records the largest cell (vdbclay_max_mass, int64) on "mass" (and
    // "density"), for the memory estimate, which reads it without the voxels.
    const auto clay = sampleClay(); // its largest cell: the overloaded core, 3 Tc + 1 at x = 1
    const std::string path = file("clay.vdb");
    writeClayFile(path, *clay, sampleMeta());
    for (const char* grid : {"mass", "density"}) {
        const auto g = readGrid(path, grid);
        const auto m = g->getMetadata<openvdb::Int64Metadata>("vdbclay_max_mass");
        ASSERT_TRUE(m) << grid;
        EXPECT_EQ(m->value(), 3001) << grid;
    }
    const ClayFile back = readClayFile(path); // round-trips, checked against the record
    EXPECT_EQ(contentHash(*back.mass), contentHash(*clay));
    // Written back from what was read (a checkpoint of a resumed run): the same record.
    writeClayFile(path, *back.mass, back.meta);
    EXPECT_EQ(readGrid(path, "mass")->getMetadata<openvdb::Int64Metadata>("vdbclay_max_mass")->value(), 3001);
    // A tile counts as its cells (an 8^3 tile of 4000 over leaves of at most 3001), and an inactive
    // cell as any other.
    const auto tiled = clay->deepCopy();
    tiled->tree().addTile(1, Coord(64, 0, 0), 4000, true);
    writeClayFile(file("tiled.vdb"), *tiled, sampleMeta());
    EXPECT_EQ(
        readGrid(file("tiled.vdb"), "mass")->getMetadata<openvdb::Int64Metadata>("vdbclay_max_mass")->value(),
        4000);
    const auto offCell = clay->deepCopy();
    offCell->tree().setValueOff(Coord(3, 2, 1), 3500);
    writeClayFile(file("off.vdb"), *offCell, sampleMeta());
    EXPECT_EQ(
        readGrid(file("off.vdb"), "mass")->getMetadata<openvdb::Int64Metadata>("vdbclay_max_mass")->value(),
        3500);
    // Empty clay records 0.
    writeClayFile(file("empty.vdb"), *openvdb::Int32Grid::create(0), sampleMeta());
    EXPECT_EQ(
        readGrid(file("empty.vdb"), "mass")->getMetadata<openvdb::Int64Metadata>("vdbclay_max_mass")->value(),
        0);

    // A file whose voxels exceed its record (edited by another tool): one error naming the file,
    // the voxel and both values.
    auto g = openvdb::gridPtrCast<openvdb::Int32Grid>(readGrid(path, "mass"));
    ASSERT_TRUE(g);
    g->tree().setValueOn(Coord(2, -3, 4), 5000);
    const std::string forged = file("forged.vdb");
    openvdb::io::File(forged).write({g});
    const std::string msg = errorOf([&] { readClayFile(forged); });
    EXPECT_TRUE(contains(msg, forged) && contains(msg, "(2, -3, 4)") && contains(msg, "5000") &&
                contains(msg, "3001") && contains(msg, "vdbclay_max_mass"))
        << msg;
    // The record must be an int64.
    g->tree().setValueOn(Coord(2, -3, 4), 1000);
    g->removeMeta("vdbclay_max_mass");
    g->insertMeta("vdbclay_max_mass", openvdb::StringMetadata("big"));
    openvdb::io::File(forged).write({g});
    const std::string typed = errorOf([&] { readClayFile(forged); });
    EXPECT_TRUE(contains(typed, forged) && contains(typed, "vdbclay_max_mass") && contains(typed, "int64"))
        << typed;
    // A file with no record of its largest cell reads.
    g->removeMeta("vdbclay_max_mass");
    openvdb::io::File(forged).write({g});
    EXPECT_EQ(errorOf([&] { readClayFile(forged); }), "");
}

// Found by tests/fuzz/fuzz_vdb: OpenVDB trusts a block's recorded size and copies that many bytes
// into the node's buffer (a heap overflow), or allocates whatever a length asks for. The layout
// check refuses both before OpenVDB reads the file.
namespace {
/// One leaf of 6 active voxels, zip-compressed: its 24 bytes of values do not shrink, so they are
/// stored raw, as the last 8 + 24 bytes of the file (size -24, then the values).
std::string oneLeafZipFile(const std::string& path)
{
    auto g = openvdb::Int32Grid::create(0);
    g->setName("mass");
    for (int x = 0; x < 3; ++x) {
        for (int y = 0; y < 2; ++y)
            g->tree().setValueOn(Coord(x, y, 0), 40 + 10 * x + y);
    }
    openvdb::io::File f(path);
    f.setCompression(openvdb::io::COMPRESS_ZIP | openvdb::io::COMPRESS_ACTIVE_MASK);
    f.write({g});
    f.close();
    std::ifstream in(path, std::ios::binary);
    return std::string(std::istreambuf_iterator<char>(in), {});
}
void patchInt64(std::string& bytes, size_t at, int64_t v)
{
    std::memcpy(&bytes[at], &v, 8);
}
int64_t int64At(const std::string& bytes, size_t at)
{
    int64_t v = 0;
    std::memcpy(&v, &bytes[at], 8);
    return v;
}
} // namespace

TEST_F(IOTest, DamagedBlockSizesAreRefusedBeforeOpenVDBReads)
{
    const std::string good = file("leaf.vdb");
    std::string bytes = oneLeafZipFile(good);
    ASSERT_EQ(readClayFile(good).mass->activeVoxelCount(), 6);
    const size_t sizeAt = bytes.size() - 32;
    ASSERT_EQ(int64At(bytes, sizeAt), -24); // the layout this test relies on

    const std::string bad = file("bad.vdb");
    patchInt64(bytes, sizeAt, -4096); // "4096 raw bytes follow": OpenVDB would copy them into 24
    spit(bad, bytes);
    std::string msg = errorOf([&] { readClayFile(bad); });
    EXPECT_TRUE(contains(msg, bad) && contains(msg, "an uncompressed block of 4096 bytes where 24 belong"))
        << msg;
    EXPECT_TRUE(contains(errorOf([&] { describeVdb(bad); }), "where 24 belong"));

    patchInt64(bytes, sizeAt, int64_t(1) << 40); // "a terabyte of zip data follows"
    spit(bad, bytes);
    msg = errorOf([&] { readClayFile(bad); });
    EXPECT_TRUE(contains(msg, "needs 1099511627776 bytes but the file ends 24 bytes later")) << msg;
}

TEST_F(IOTest, DamagedLengthsAreRefusedBeforeOpenVDBAllocates)
{
    const std::string good = file("leaf.vdb");
    std::string bytes = oneLeafZipFile(good);
    // Header (57 bytes), file metadata count (0), grid count (1), then the first grid's name.
    uint32_t count = 0, nameLength = 0;
    std::memcpy(&count, &bytes[57], 4);
    std::memcpy(&nameLength, &bytes[65], 4);
    ASSERT_EQ(count, 0u);
    ASSERT_EQ(nameLength, 4u);         // "mass"
    const uint32_t huge = 0xfffffff0u; // OpenVDB would allocate and fill 4 GB for the name
    std::memcpy(&bytes[65], &huge, 4);
    const std::string bad = file("bad.vdb");
    spit(bad, bytes);
    const std::string msg = errorOf([&] { describeVdb(bad); });
    EXPECT_TRUE(contains(msg, "grid 1's name (4294967280 bytes long) needs 4294967280 bytes")) << msg;
}

TEST_F(IOTest, TotalMassThatOverflowsIsAnError)
{
    // A file can hold a tile of 4096^3 voxels of 2^31 - 1 each: about 2^67 in all.
    auto g = openvdb::Int32Grid::create(0);
    g->setName("mass");
    g->tree().addTile(3, Coord(0), 2147483647, true);
    EXPECT_TRUE(contains(errorOf([&] { totalMass(*g); }), "the total mass exceeds"));
    const std::string path = file("tile.vdb");
    openvdb::io::File(path).write({g});
    const std::string text = describeVdb(path);
    EXPECT_TRUE(contains(text, "total mass: more than 64 bits count")) << text;
    EXPECT_TRUE(contains(text, "content hash: none (the grid holds tiles")) << text;
}

TEST_F(IOTest, DescribeNamesGridsAndTotalMass)
{
    auto clay = sampleClay();
    const std::string path = file("clay.vdb");
    writeClayFile(path, *clay, sampleMeta());
    const std::string text = describeVdb(path);
    for (const char* part : {"\"mass\"", "\"density\"", "\"surface\"", "int32", "float", "fog volume",
                             "level set", "vdbclay_threshold", "vdbclay_rule", "sorted", "voxel size: 0.5"}) {
        EXPECT_TRUE(contains(text, part)) << part << "\n" << text;
    }
    EXPECT_TRUE(contains(text, "total mass: " + std::to_string(totalMass(*clay)))) << text;
    std::ostringstream voxels;
    voxels << "active voxels: " << clay->activeVoxelCount();
    EXPECT_TRUE(contains(text, voxels.str())) << text;
}

// ---------------------------------------------------------------------------------------------
// Meshes

struct MeshCounts {
    size_t vertices = 0, faces = 0;
    double signedVolume = 0;
    bool indicesValid = true;
};

double tetVolume(const std::array<double, 3>& a, const std::array<double, 3>& b,
                 const std::array<double, 3>& c)
{
    return (a[0] * (b[1] * c[2] - b[2] * c[1]) - a[1] * (b[0] * c[2] - b[2] * c[0]) +
            a[2] * (b[0] * c[1] - b[1] * c[0])) /
           6.0;
}

MeshCounts parseObj(const std::string& path)
{
    MeshCounts m;
    std::vector<std::array<double, 3>> v;
    std::ifstream in(path);
    std::string line;
    while (std::getline(in, line)) {
        std::istringstream s(line);
        std::string tag;
        s >> tag;
        if (tag == "v") {
            std::array<double, 3> p;
            s >> p[0] >> p[1] >> p[2];
            v.push_back(p);
        } else if (tag == "f") {
            std::vector<long> idx;
            long i;
            while (s >> i)
                idx.push_back(i);
            for (long j : idx)
                m.indicesValid &= j >= 1 && size_t(j) <= v.size();
            if (!m.indicesValid || idx.size() < 3) return m;
            for (size_t k = 1; k + 1 < idx.size(); ++k) {
                m.signedVolume +=
                    tetVolume(v[size_t(idx[0] - 1)], v[size_t(idx[k] - 1)], v[size_t(idx[k + 1] - 1)]);
            }
            ++m.faces;
        }
    }
    m.vertices = v.size();
    return m;
}

MeshCounts parsePly(const std::string& path)
{
    MeshCounts m;
    std::ifstream in(path);
    std::string line;
    std::getline(in, line);
    if (line != "ply") return MeshCounts{0, 0, 0, false};
    size_t nv = 0, nf = 0;
    while (std::getline(in, line) && line != "end_header") {
        std::istringstream s(line);
        std::string a, b;
        s >> a >> b;
        if (a == "format" && b != "ascii") return MeshCounts{0, 0, 0, false};
        if (a == "element" && b == "vertex") s >> nv;
        if (a == "element" && b == "face") s >> nf;
    }
    std::vector<std::array<double, 3>> v(nv);
    for (auto& p : v)
        in >> p[0] >> p[1] >> p[2];
    for (size_t f = 0; f < nf; ++f) {
        size_t n;
        in >> n;
        std::vector<long> idx(n);
        for (auto& i : idx)
            in >> i;
        if (!in) return m;
        for (long j : idx)
            m.indicesValid &= j >= 0 && size_t(j) < nv;
        if (!m.indicesValid) return m;
        for (size_t k = 1; k + 1 < n; ++k) {
            m.signedVolume += tetVolume(v[size_t(idx[0])], v[size_t(idx[k])], v[size_t(idx[k + 1])]);
        }
        ++m.faces;
    }
    m.vertices = nv;
    return m;
}

TEST_F(IOTest, SurfaceMeshObjAndPly)
{
    auto g = openvdb::Int32Grid::create(0);
    auto acc = g->getAccessor();
    int n = 0;
    for (int x = -5; x <= 5; ++x)
        for (int y = -5; y <= 5; ++y)
            for (int z = -5; z <= 5; ++z)
                if (x * x + y * y + z * z <= 25) {
                    acc.setValueOn(Coord(x, y, z), 500);
                    ++n;
                }
    const std::string obj = file("clay.obj"), ply = file("clay.PLY");
    writeSurfaceMesh(obj, *g, 500);
    writeSurfaceMesh(ply, *g, 500);
    const MeshCounts o = parseObj(obj), p = parsePly(ply);
    EXPECT_TRUE(o.indicesValid);
    EXPECT_TRUE(p.indicesValid);
    EXPECT_GT(o.vertices, 0u);
    EXPECT_GT(o.faces, 0u);
    EXPECT_EQ(o.vertices, p.vertices);
    EXPECT_EQ(o.faces, p.faces);
    // Outward faces enclose about one unit of volume per full voxel.
    EXPECT_GT(o.signedVolume, 0.8 * n);
    EXPECT_LT(o.signedVolume, 1.2 * n);
    EXPECT_NEAR(p.signedVolume, o.signedVolume, 1e-6 * n);
    EXPECT_EQ(listing(), (std::set<std::string>{"clay.PLY", "clay.obj"}));

    EXPECT_TRUE(contains(errorOf([&] { writeSurfaceMesh(file("clay.fbx"), *g, 500); }), "clay.fbx"));
    EXPECT_TRUE(contains(errorOf([&] { writeSurfaceMesh(file("clay"), *g, 500); }), "unknown"));
    auto none = openvdb::Int32Grid::create(0);
    EXPECT_TRUE(contains(errorOf([&] { writeSurfaceMesh(file("e.obj"), *none, 500); }), "no clay"));
    EXPECT_FALSE(errorOf([&] { writeSurfaceMesh(file("x/e.obj"), *g, 500); }).empty());
    EXPECT_EQ(listing(), (std::set<std::string>{"clay.PLY", "clay.obj"}));
}

// ---------------------------------------------------------------------------------------------
// Clay from a shape

TEST_F(IOTest, MakeClayFillsExactlyTheCentresInside)
{
    const Vec3 c{{3.3, -2.1, 4.7}};
    const double r = 5.2;
    const TestSphere sphere(c, r);
    uint64_t expected3 = 0, expected2 = 0;
    for (int x = -10; x <= 15; ++x)
        for (int y = -15; y <= 10; ++y)
            for (int z = -10; z <= 15; ++z) {
                const double dx = x - c[0], dy = y - c[1], dz = z - c[2];
                if (dx * dx + dy * dy + dz * dz < r * r) {
                    ++expected3;
                    if (z == 0) ++expected2;
                }
            }
    ASSERT_GT(expected2, 0u);

    auto clay = makeClay(sphere, 700);
    EXPECT_EQ(clayVoxelCount(*clay), expected3);
    EXPECT_EQ(totalMass(*clay), int64_t(expected3) * 700);
    for (auto it = clay->cbeginValueOn(); it; ++it)
        ASSERT_EQ(*it, 700);

    auto flat = makeClay(sphere, 9, 2);
    EXPECT_EQ(clayVoxelCount(*flat), expected2);
    EXPECT_EQ(totalMass(*flat), int64_t(expected2) * 9);
    const openvdb::CoordBBox fb = flat->evalActiveVoxelBoundingBox();
    EXPECT_EQ(fb.min().z(), 0);
    EXPECT_EQ(fb.max().z(), 0);

    EXPECT_TRUE(contains(errorOf([&] { makeClay(sphere, 0); }), "mass per voxel"));
    EXPECT_TRUE(contains(errorOf([&] { makeClay(sphere, -5); }), "mass per voxel"));
    EXPECT_FALSE(errorOf([&] { makeClay(sphere, 1, 4); }).empty());
    // A sphere too small to hold a voxel centre, and one away from the z = 0 layer.
    EXPECT_TRUE(contains(errorOf([&] { makeClay(TestSphere({{0.5, 0.5, 0.5}}, 0.3), 1); }), "test sphere"));
    EXPECT_TRUE(contains(errorOf([&] { makeClay(TestSphere({{0, 0, 20}}, 3), 1, 2); }), "z = 0"));
}

// ---------------------------------------------------------------------------------------------
// Pictures

TEST_F(IOTest, Render2dDensityMap)
{
    // A 2D pile: an overloaded column spreads for a while; some cells are still over Tc.
    auto mass = openvdb::Int32Grid::create(0);
    auto acc = mass->getAccessor();
    for (int x = 0; x < 40; ++x)
        for (int y = 0; y < 40; ++y)
            acc.setValueOn(Coord(x, y, 0), (x >= 15 && x < 25) ? 3000 : 600);
    AutomatonOptions opt;
    opt.dimensions = 2;
    opt.rule.rule = Rule::Prorata;
    opt.rule.threshold = 1000;
    Automaton a(mass, opt);
    a.run(25);
    ASSERT_GT(residualOverload(*mass, 1000, nullptr), 0);

    RenderOptions ro;
    ro.width = 640;
    const std::string path = file("map.png");
    renderPng(path, *mass, 1000, 2, ro);
    const PngInfo info = inspectPng(path);
    EXPECT_TRUE(info.signature);
    EXPECT_LE(info.width, 640u);
    EXPECT_GE(info.width, 320u);
    EXPECT_GT(info.height, 0u);
    ASSERT_EQ(info.rgb.size(), size_t(info.width) * info.height * 3);
    EXPECT_GT(info.distinctColours, 10u);
    bool red = false;
    for (size_t i = 0; i + 2 < info.rgb.size(); i += 3) {
        red |= info.rgb[i] == 215 && info.rgb[i + 1] == 25 && info.rgb[i + 2] == 28;
    }
    EXPECT_TRUE(red);
    fs::copy_file(path, "/tmp/vdbclay-render-2d.png", fs::copy_options::overwrite_existing);
    EXPECT_EQ(listing(), std::set<std::string>{"map.png"});
}

TEST_F(IOTest, Render3dSurface)
{
    // A lump and a column settle a little under gravity-free repartition: a shaded surface.
    auto mass = openvdb::Int32Grid::create(0);
    auto acc = mass->getAccessor();
    for (int x = -10; x <= 10; ++x)
        for (int y = 0; y <= 6; ++y)
            for (int z = -10; z <= 10; ++z)
                acc.setValueOn(Coord(x, y, z), 1000);
    for (int x = -3; x <= 3; ++x)
        for (int y = 7; y <= 16; ++y)
            for (int z = -3; z <= 3; ++z)
                if (x * x + z * z <= 9) acc.setValueOn(Coord(x, y, z), 2500);
    AutomatonOptions opt;
    opt.rule.threshold = 1000;
    Automaton a(mass, opt);
    a.run(10);

    RenderOptions ro;
    ro.width = 320;
    ro.height = 240;
    const std::string path = file("clay.png");
    renderPng(path, *mass, 1000, 3, ro);
    const PngInfo info = inspectPng(path);
    EXPECT_TRUE(info.signature);
    EXPECT_EQ(info.width, 320u);
    EXPECT_EQ(info.height, 240u);
    EXPECT_GT(info.distinctColours, 20u);
    // White background in the corners, clay in the middle.
    ASSERT_EQ(info.rgb.size(), size_t(320 * 240 * 3));
    EXPECT_EQ(info.rgb[0], 255);
    const size_t mid = (size_t(120) * 320 + 160) * 3;
    EXPECT_NE(info.rgb[mid] + info.rgb[mid + 1] + info.rgb[mid + 2], 3 * 255);
    fs::copy_file(path, "/tmp/vdbclay-render-3d.png", fs::copy_options::overwrite_existing);
}

TEST_F(IOTest, RenderRefusesBadInput)
{
    auto none = openvdb::Int32Grid::create(0);
    EXPECT_TRUE(contains(errorOf([&] { renderPng(file("a.png"), *none, 1000, 3); }), "no clay"));
    EXPECT_TRUE(contains(errorOf([&] { renderPng(file("a.png"), *none, 1000, 2); }), "no clay"));
    auto g = sampleClay();
    RenderOptions bad;
    bad.width = 0;
    EXPECT_TRUE(contains(errorOf([&] { renderPng(file("a.png"), *g, 1000, 3, bad); }), "size"));
    bad.width = 100;
    bad.height = -1;
    EXPECT_TRUE(contains(errorOf([&] { renderPng(file("a.png"), *g, 1000, 3, bad); }), "size"));
    EXPECT_TRUE(contains(errorOf([&] { renderPng(file("x/a.png"), *g, 1000, 3); }), "x/a.png"));
    EXPECT_TRUE(contains(errorOf([&] { renderPng(file("x/a.png"), *g, 1000, 2); }), "x/a.png"));
    // Clay only away from z = 0 has nothing to show in 2D.
    auto high = openvdb::Int32Grid::create(0);
    high->tree().setValue(Coord(0, 0, 5), 10);
    EXPECT_TRUE(contains(errorOf([&] { renderPng(file("a.png"), *high, 1000, 2); }), "z = 0"));
    EXPECT_TRUE(listing().empty());
}

} // namespace

TEST_F(IOTest, OutputGridsFollowTheClayNotTheSpanBetweenLumps)
{
    // Two 4^3 lumps 1e9 voxels apart: the density and surface grids hold exactly twice the voxels
    // and leaves of one lump's (the output is built from the clay's leaves, not over the span).
    auto one = openvdb::Int32Grid::create(0);
    one->tree().fill(openvdb::CoordBBox(Coord(0), Coord(3)), 1000, true);
    one->tree().voxelizeActiveTiles();
    auto two = one->deepCopy();
    two->tree().fill(openvdb::CoordBBox(Coord(1000000000, 0, 0), Coord(1000000003, 3, 3)), 1000, true);
    two->tree().voxelizeActiveTiles();
    const std::string p1 = file("one.vdb"), p2 = file("two.vdb");
    writeClayFile(p1, *one, sampleMeta());
    writeClayFile(p2, *two, sampleMeta());
    for (const char* name : {"density", "surface"}) {
        auto g1 = openvdb::gridPtrCast<openvdb::FloatGrid>(readGrid(p1, name));
        auto g2 = openvdb::gridPtrCast<openvdb::FloatGrid>(readGrid(p2, name));
        ASSERT_TRUE(g1 && g2) << name;
        EXPECT_GT(g1->tree().activeVoxelCount(), 0u) << name;
        EXPECT_EQ(g2->tree().activeVoxelCount(), 2 * g1->tree().activeVoxelCount()) << name;
        EXPECT_EQ(g2->tree().leafCount(), 2 * g1->tree().leafCount()) << name;
    }
    auto density = openvdb::gridPtrCast<openvdb::FloatGrid>(readGrid(p2, "density"));
    EXPECT_EQ(density->tree().activeVoxelCount(), 128u);
    // Every non-zero value is clay, active or not (one definition everywhere): an inactive voxel
    // holding mass has its density too.
    two->tree().setValueOff(Coord(-500000000, 7, 7), 400);
    writeClayFile(p2, *two, sampleMeta());
    density = openvdb::gridPtrCast<openvdb::FloatGrid>(readGrid(p2, "density"));
    EXPECT_EQ(density->tree().activeVoxelCount(), 129u);
    EXPECT_FLOAT_EQ(density->tree().getValue(Coord(-500000000, 7, 7)), 0.4f);
}

// ---- One definition of the clay in a file; coordinates; outputs that are not files --------------

namespace {

/// Writes @a grid as a plain OpenVDB file (no vdbclay metadata), as another tool would.
void writePlainVdb(const std::string& path, openvdb::Int32Grid::Ptr grid)
{
    grid->setName("mass");
    openvdb::io::File out(path);
    out.write({grid});
    out.close();
}

} // namespace

TEST_F(IOTest, ClayInAFileIsEveryNonZeroValueForEveryCommand)
{
    // An inactive 8^3 tile at 700 beside active voxels, and one inactive voxel holding mass: clay
    // for every command alike, read as active (the tile stays a tile: uniform clay).
    auto g = openvdb::Int32Grid::create(0);
    g->tree().addTile(1, Coord(64, 0, 0), 700, false);
    g->tree().setValueOn(Coord(0, 0, 0), 900);
    g->tree().setValueOff(Coord(3, 0, 0), 300);
    const int64_t expected = 512 * 700 + 900 + 300;
    ASSERT_EQ(totalMass(*g), expected);
    writePlainVdb(file("tile.vdb"), g);
    const ClayFile f = readClayFile(file("tile.vdb"));
    EXPECT_EQ(totalMass(*f.mass), expected);
    EXPECT_EQ(f.mass->activeVoxelCount(), 514u);
    EXPECT_EQ(clayVoxelCount(*f.mass), 514u);
    EXPECT_EQ(f.mass->tree().activeTileCount(), 1u);
    EXPECT_EQ(contentHash(*f.mass), contentHash(*g));
    EXPECT_TRUE(contains(describeVdb(file("tile.vdb")), "total mass: " + std::to_string(expected)));
}

TEST_F(IOTest, NonZeroBackgroundIsRefusedAndNotCountedAsClay)
{
    auto g = openvdb::Int32Grid::create(5);
    g->tree().setValueOn(Coord(0, 0, 0), 900);
    writePlainVdb(file("bg.vdb"), g);
    const std::string m = errorOf([&] { readClayFile(file("bg.vdb")); });
    EXPECT_TRUE(contains(m, "grid \"mass\" has background value 5, expected 0")) << m;
    // describeVdb gives no total for such a file, and says why.
    const std::string d = describeVdb(file("bg.vdb"));
    EXPECT_TRUE(contains(d, "total mass: none (the background is 5")) << d;
}

TEST_F(IOTest, ClayOutsideTheCoordinateRangeIsRefusedOnReading)
{
    for (const int32_t far : {INT32_MAX, INT32_MIN, (1 << 30) + 1}) {
        auto g = openvdb::Int32Grid::create(0);
        g->tree().setValueOn(Coord(0, 0, 0), 900);
        g->tree().setValueOn(Coord(far, 0, 0), 900);
        writePlainVdb(file("far.vdb"), g);
        const std::string m = errorOf([&] { readClayFile(file("far.vdb")); });
        EXPECT_TRUE(contains(m, "outside the coordinate range +-2^30")) << far << ": " << m;
    }
    auto ok = openvdb::Int32Grid::create(0);
    ok->tree().setValueOn(Coord(1 << 30, -(1 << 30), 0), 900);
    writePlainVdb(file("edge.vdb"), ok);
    EXPECT_NO_THROW(readClayFile(file("edge.vdb")));
}

TEST_F(IOTest, OutputsThatAreNotRegularFilesAreWrittenThroughNeverReplaced)
{
    // A FIFO: a reader gets every byte, and the FIFO stays a FIFO.
    const std::string fifo = file("pipe");
    ASSERT_EQ(::mkfifo(fifo.c_str(), 0644), 0);
    std::string got;
    std::thread reader([&] { got = slurp(fifo); });
    writeTextFile(fifo, "through the pipe\n");
    reader.join();
    EXPECT_EQ(got, "through the pipe\n");
    struct stat st;
    ASSERT_EQ(::stat(fifo.c_str(), &st), 0);
    EXPECT_TRUE(S_ISFIFO(st.st_mode));
    // A full device: the failure is reported, and the device is not replaced by a regular file.
    if (::access("/dev/full", W_OK) == 0) {
        const std::string m = errorOf([&] { writeClayFile("/dev/full", *sampleClay(), ClayMeta{}); });
        EXPECT_TRUE(contains(m, "cannot write /dev/full: write failed: No space left on device")) << m;
        ASSERT_EQ(::stat("/dev/full", &st), 0);
        EXPECT_TRUE(S_ISCHR(st.st_mode));
    }
    // A symbolic link stays a link; the file it points to gets the new contents.
    spit(file("target.txt"), "old");
    ASSERT_EQ(::symlink("target.txt", file("link.txt").c_str()), 0);
    writeTextFile(file("link.txt"), "new");
    EXPECT_EQ(slurp(file("target.txt")), "new");
    ASSERT_EQ(::lstat(file("link.txt").c_str(), &st), 0);
    EXPECT_TRUE(S_ISLNK(st.st_mode));
    EXPECT_EQ(listing(), (std::set<std::string>{"pipe", "target.txt", "link.txt"}));
    removePendingTempFile(); // nothing pending: does nothing
}

TEST_F(IOTest, FilesThatAreNotVdbFilesAreNamedForWhatTheyAre)
{
    EXPECT_TRUE(contains(errorOf([] { readClayFile("/dev/zero"); }), "/dev/zero is not a regular file"));
    ASSERT_EQ(::symlink("loop-b", file("loop-a").c_str()), 0);
    ASSERT_EQ(::symlink("loop-a", file("loop-b").c_str()), 0);
    const std::string m = errorOf([&] { readClayFile(file("loop-a")); });
    EXPECT_TRUE(contains(m, "Too many levels of symbolic links")) << m;
}
