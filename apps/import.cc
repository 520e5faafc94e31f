// vdbclay import: a mesh (OBJ/STL/PLY), a level set or a fog volume .vdb turned into clay.
#include "cli.h"

#include "vdbclay/IO.h"
#include "vdbclay/MemoryEstimate.h"
#include "vdbclay/Metrics.h"
#include "vdbclay/Scene.h"
#include "vdbclay/Shapes.h"

#include <openvdb/io/File.h>
#include <openvdb/openvdb.h>

#include <climits>
#include <cstdio>
#include <memory>
#include <string>

namespace vdbclay_cli {
namespace {

struct ImportArgs {
    std::string in, out, grid, budget;
    int64_t mass = 0;
    double voxelSize = 0; ///< 0: the level set's own voxel size, or 1 for meshes
    int dims = 3;
    std::string up = "y";
};

bool isVdbName(const std::string& path)
{
    return path.size() > 4 && path.compare(path.size() - 4, 4, ".vdb") == 0;
}

/// Writes @a clay to the output, with its dimensions, voxel size and up axis.
void writeImported(const ImportArgs& a, const vdbclay::MassGrid& clay, double voxelSize)
{
    vdbclay::ClayMeta meta;
    meta.dimensions = a.dims;
    meta.voxelSize = voxelSize;
    meta.up = upOption(a.up);
    gWriting.store(true);
    vdbclay::writeClayFile(a.out, clay, meta);
}

/// The line that says what was written.
void printWrote(const ImportArgs& a, const vdbclay::MassGrid& clay)
{
    std::printf("wrote %s: %llu voxels, mass %lld\n", a.out.c_str(),
                (unsigned long long)vdbclay::clayVoxelCount(clay), (long long)vdbclay::totalMass(clay));
}

/// A fog volume: round(density x M) per voxel, voxel for voxel at its own voxel size.
int importFog(const ImportArgs& a, const std::string& fogGrid)
{
    const vdbclay::FogClay fog = vdbclay::readFogAsClay(a.in, fogGrid, int32_t(a.mass), a.dims);
    if (a.voxelSize != 0 && a.voxelSize != fog.voxelSize) {
        throw vdbclay::Error("--voxel-size: fog volume \"" + fogGrid + "\" in " + a.in +
                             " is taken voxel for voxel at its own voxel size " +
                             std::to_string(fog.voxelSize) + "; leave --voxel-size out");
    }
    writeImported(a, *fog.mass, fog.voxelSize);
    std::printf("note: %s\n", fog.note.c_str());
    printWrote(a, *fog.mass);
    return 0;
}

/// The voxel size of the level set import reads from a .vdb (--grid, else its first level set).
double levelSetVoxelSize(const ImportArgs& a)
{
    // loadLevelSet checks the file before OpenVDB reads it.
    vdbclay::loadLevelSet(a.in, 1.0, a.grid, upOption(a.up));
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
int importShape(const ImportArgs& a, bool isVdb)
{
    double voxelSize = a.voxelSize;
    if (voxelSize == 0 && isVdb) voxelSize = levelSetVoxelSize(a);
    if (voxelSize == 0) voxelSize = 1.0;
    const uint64_t budget =
        a.budget.empty() ? 0 // the default
                         : parsedOption("--memory-budget", [&] { return vdbclay::parseByteSize(a.budget); });
    const vdbclay::ShapePtr shape =
        isVdb ? vdbclay::loadLevelSet(a.in, voxelSize, a.grid, upOption(a.up))
              : vdbclay::loadMesh(a.in, voxelSize, upOption(a.up), vdbclay::Placement(), budget);
    checkImportMemory(a, shape, isVdb, budget);
    const vdbclay::MassGridPtr clay = vdbclay::makeClay(*shape, int32_t(a.mass), a.dims);
    writeImported(a, *clay, voxelSize);
    if (shape->describe().find("winding number") != std::string::npos) {
        std::printf("note: %s\n", shape->describe().c_str()); // open or non-manifold: how it was filled
    }
    printWrote(a, *clay);
    return 0;
}

int import(const ImportArgs& a)
{
    checkOutputs({{"-o", a.out}}, {{{"the input file", a.in}, {}}});
    const bool isVdb = isVdbName(a.in);
    if (!isVdb && !a.grid.empty()) throw vdbclay::Error("--grid: only for a .vdb, not " + a.in);
    const std::string fogGrid = isVdb ? vdbclay::fogGridToImport(a.in, a.grid) : std::string();
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
    imp->add_option("--voxel-size", a->voxelSize,
                    "world units per voxel (default: a level set's own voxel size; 1 for meshes)")
        ->check(finiteIn(vdbclay::kMinVoxelSize, vdbclay::kMaxVoxelSize));
    imp->add_option(
        "--grid", a->grid,
        ".vdb: the level set or fog volume to import (default: the first level set, else the first fog "
        "volume)");
    imp->add_option("--dims", a->dims, "2 (keep the z = 0 layer) or 3")->check(integerIn(2, 3));
    imp->add_option("--up", a->up, "y or z: the input's up axis, also written into the clay's transform");
    imp->add_option("--memory-budget", a->budget,
                    "refuse a shape estimated to need more (default: 3/4 of memory)")
        ->check(nonEmpty("a size"));
    return {imp, [a] { return import(*a); }};
}

} // namespace vdbclay_cli
