// vdbclay import: a mesh (OBJ/STL/PLY), a level set or a fog volume .vdb turned into clay.
#include "cli.h"

#include "vdbclay/IO.h"
#include "vdbclay/MemoryEstimate.h"
#include "vdbclay/Metrics.h"
#include "vdbclay/Scene.h"
#include "vdbclay/Shapes.h"

#include <openvdb/io/File.h>
#include <openvdb/openvdb.h>

#include <algorithm>
#include <array>
#include <climits>
#include <cstdio>
#include <memory>
#include <optional>
#include <string>

namespace vdbclay_cli {
namespace {

struct ImportArgs {
    std::string in, out, grid, budget;
    int64_t mass = 0;
    double voxelSize = 0;   ///< 0: the level set's own voxel size, or 1 for meshes
    int64_t resolution = 0; ///< --resolution: voxels across the mesh's longest side (0: not given)
    int dims = 3;
    std::string up; ///< empty: y (a fog volume: its own)
    std::string as; ///< --as: "density" reads a FloatGrid of any class as a fog volume
};

/// Fewer voxels than this across a mesh imported at the default voxel size earns a warning.
constexpr int64_t kFewVoxelsAcross = 32;

vdbclay::UpAxis upOf(const ImportArgs& a)
{
    return a.up.empty() ? vdbclay::UpAxis::Y : upOption(a.up);
}

bool isVdbName(const std::string& path)
{
    return path.size() > 4 && path.compare(path.size() - 4, 4, ".vdb") == 0;
}

/// Writes @a clay to the output, with its dimensions, voxel size and up axis.
void writeImported(const ImportArgs& a, const vdbclay::MassGrid& clay, double voxelSize, vdbclay::UpAxis up)
{
    vdbclay::ClayMeta meta;
    meta.dimensions = a.dims;
    meta.voxelSize = voxelSize;
    meta.up = up;
    gWriting.store(true);
    vdbclay::writeClayFile(a.out, clay, meta);
}

/// The line that says what was written.
void printWrote(const ImportArgs& a, const vdbclay::MassGrid& clay)
{
    std::printf("wrote %s: %llu voxels, mass %lld\n", a.out.c_str(),
                (unsigned long long)vdbclay::clayVoxelCount(clay), (long long)vdbclay::totalMass(clay));
}

/// A fog volume: round(density x M) per voxel, voxel for voxel at its own voxel size and place.
int importFog(const ImportArgs& a, const std::string& fogGrid)
{
    if (a.resolution) {
        throw vdbclay::Error("--resolution: fog volume \"" + fogGrid + "\" in " + a.in +
                             " is taken voxel for voxel at its own voxel size; leave --resolution out");
    }
    std::optional<vdbclay::UpAxis> up;
    if (!a.up.empty()) up = upOption(a.up);
    const vdbclay::FogClay fog =
        vdbclay::readFogAsClay(a.in, fogGrid, int32_t(a.mass), a.dims, a.as == "density", up);
    if (a.voxelSize != 0 && a.voxelSize != fog.voxelSize) {
        throw vdbclay::Error("--voxel-size: fog volume \"" + fogGrid + "\" in " + a.in +
                             " is taken voxel for voxel at its own voxel size " +
                             std::to_string(fog.voxelSize) + "; leave --voxel-size out");
    }
    writeImported(a, *fog.mass, fog.voxelSize, fog.up);
    std::printf("note: %s\n", fog.note.c_str());
    printWrote(a, *fog.mass);
    return 0;
}

/// The voxel size of the level set import reads from a .vdb (--grid, else its first level set).
double levelSetVoxelSize(const ImportArgs& a)
{
    // loadLevelSet checks the file before OpenVDB reads it.
    vdbclay::loadLevelSet(a.in, 1.0, a.grid, upOf(a));
    openvdb::io::File f(a.in);
    f.open(false);
    std::string name = a.grid;
    if (name.empty()) {
        // Held: a range-for over *f.readAllGridMetadata() would read a freed vector.
        const openvdb::GridPtrVecPtr grids = f.readAllGridMetadata();
        for (const auto& g : *grids) {
            if (g->getGridClass() == openvdb::GRID_LEVEL_SET && g->isType<openvdb::FloatGrid>()) {
                name = g->getName();
                break;
            }
        }
    }
    const double voxelSize = f.readGridMetadata(name)->voxelSize()[0];
    f.close();
    return voxelSize;
}

/// The clay makeClay builds from @a shape must fit the memory budget (@a budget; 0: the default).
void checkImportMemory(const ImportArgs& a, const vdbclay::ShapePtr& shape, bool isVdb, uint64_t budget)
{
    vdbclay::Scene sc;
    sc.source = "import " + a.in;
    sc.dimensions = a.dims;
    vdbclay::ClaySpec c;
    c.shape.kind = isVdb ? "levelset" : "mesh";
    c.shape.field = "import";
    c.shape.shape = shape;
    c.mass = int32_t(a.mass);
    sc.clay.push_back(c);
    sc.memoryBudget = budget;
    vdbclay::checkMemoryBudget(sc);
}

/// A mesh or a level set: M per voxel whose centre is inside.
/// --resolution N: the voxel size that puts N voxels across the mesh's longest side.
double resolutionVoxelSize(const ImportArgs& a, uint64_t budget)
{
    const std::array<vdbclay::Vec3, 2> b = vdbclay::meshFileBounds(a.in, budget);
    const double longest = std::max({b[1][0] - b[0][0], b[1][1] - b[0][1], b[1][2] - b[0][2]});
    const double voxelSize = longest / double(a.resolution);
    if (!(voxelSize >= vdbclay::kMinVoxelSize) || !(voxelSize <= vdbclay::kMaxVoxelSize)) {
        char msg[160];
        std::snprintf(msg, sizeof msg,
                      "%g world units across its longest side, divided by %lld, is a voxel size of %g, "
                      "outside [%g, %g]",
                      longest, (long long)a.resolution, voxelSize, vdbclay::kMinVoxelSize,
                      vdbclay::kMaxVoxelSize);
        throw vdbclay::Error("--resolution " + std::to_string(a.resolution) + ": " + a.in + " is " + msg);
    }
    return voxelSize;
}

/// A mesh or a level set: M per voxel whose centre is inside.
int importShape(const ImportArgs& a, bool isVdb)
{
    if (!a.as.empty()) {
        throw vdbclay::Error("--as " + a.as + ": only for a .vdb's float grid, not " +
                             (isVdb ? "a level set (import it without --as)" : "a mesh"));
    }
    if (isVdb && a.resolution) {
        throw vdbclay::Error("--resolution: for meshes; a level set is read at its own voxel size or "
                             "--voxel-size");
    }
    const uint64_t budget =
        a.budget.empty() ? 0 // the default
                         : parsedOption("--memory-budget", [&] { return vdbclay::parseByteSize(a.budget); });
    double voxelSize = a.voxelSize;
    if (voxelSize == 0 && isVdb) voxelSize = levelSetVoxelSize(a);
    if (voxelSize == 0 && a.resolution) voxelSize = resolutionVoxelSize(a, budget);
    const bool defaultSize = voxelSize == 0;
    if (voxelSize == 0) voxelSize = 1.0;
    const vdbclay::ShapePtr shape =
        isVdb ? vdbclay::loadLevelSet(a.in, voxelSize, a.grid, upOf(a))
              : vdbclay::loadMesh(a.in, voxelSize, upOf(a), vdbclay::Placement(), budget);
    checkImportMemory(a, shape, isVdb, budget);
    const vdbclay::MassGridPtr clay = vdbclay::makeClay(*shape, int32_t(a.mass), a.dims);
    if (defaultSize) {
        const openvdb::CoordBBox b = clay->evalActiveVoxelBoundingBox();
        const int64_t across = clay->empty() ? 0 : int64_t(std::max({b.dim().x(), b.dim().y(), b.dim().z()}));
        if (across < kFewVoxelsAcross) {
            std::fprintf(stderr,
                         "vdbclay: warning: %s is only %lld voxels across at the default voxel size 1; give "
                         "--resolution N (voxels across its longest side) or --voxel-size\n",
                         printable(a.in).c_str(), (long long)across);
        }
    }
    writeImported(a, *clay, voxelSize, upOf(a));
    if (shape->describe().find("winding number") != std::string::npos) {
        std::printf("note: %s\n", shape->describe().c_str()); // open or non-manifold: how it was filled
    }
    printWrote(a, *clay);
    return 0;
}

int import(const ImportArgs& a)
{
    checkOutputs({{"-o", a.out}}, {{{"the input file", a.in}, {}}});
    checkFormatName({"-o", a.out}, ".vdb", "a clay .vdb (OpenVDB)");
    const bool isVdb = isVdbName(a.in);
    if (!isVdb && !a.grid.empty()) throw vdbclay::Error("--grid: only for a .vdb, not " + a.in);
    if (!a.as.empty() && a.as != "density") {
        throw vdbclay::Error("--as: expected density, got \"" + a.as + "\"");
    }
    const std::string fogGrid =
        isVdb ? vdbclay::fogGridToImport(a.in, a.grid, a.as == "density") : std::string();
    if (!fogGrid.empty()) return importFog(a, fogGrid);
    return importShape(a, isVdb);
}

} // namespace

Subcommand addImportCommand(CLI::App& app)
{
    auto a = std::make_shared<ImportArgs>();
    CLI::App* imp =
        app.add_subcommand("import", "Turn a mesh (OBJ/STL/PLY), a level set or a fog volume .vdb into clay");
    imp->add_option("file", a->in, "MESH.obj, MESH.stl, MESH.ply, LEVELSET.vdb or FOG.vdb")
        ->required()
        ->check(fileName());
    imp->add_option("-o,--output", a->out, "CLAY.vdb")->required()->check(fileName());
    imp->add_option("--mass", a->mass, "clay per voxel inside the shape (a fog volume: per unit of density)")
        ->required()
        ->check(integerIn(1, INT32_MAX));
    CLI::Option* vs =
        imp->add_option("--voxel-size", a->voxelSize,
                        "world units per voxel (default: a level set's own voxel size; 1 for meshes)")
            ->check(finiteIn(vdbclay::kMinVoxelSize, vdbclay::kMaxVoxelSize));
    imp->add_option("--resolution", a->resolution,
                    "meshes: voxels across the longest side of the mesh's box (instead of --voxel-size)")
        ->check(integerIn(1, 1 << 20))
        ->excludes(vs);
    imp->add_option("--as", a->as,
                    "density: read a .vdb's FloatGrid of any class (e.g. unknown) as a fog volume "
                    "(density 1 = a full cell)");
    imp->add_option(
        "--grid", a->grid,
        ".vdb: the level set or fog volume to import (default: the first level set, else the first fog "
        "volume)");
    imp->add_option("--dims", a->dims, "2 (keep the z = 0 layer) or 3")->check(integerIn(2, 3));
    imp->add_option("--up", a->up,
                    "y or z: the input's up axis, also written into the clay's transform (default y; a fog "
                    "volume: its own)");
    imp->add_option("--memory-budget", a->budget,
                    "refuse a shape estimated to need more (default: 3/4 of memory)")
        ->check(nonEmpty("a size"));
    return {imp, [a] { return import(*a); }};
}

} // namespace vdbclay_cli
