// Clay from .vdb files that are not clay files: fog volumes (density x the mass of a full cell,
// voxel for voxel) and level sets (makeClay of the level set as a shape), for `vdbclay import`,
// `render` and `mesh` (readAsClay). The files are opened with the checks of VdbFile.h.
#include "vdbclay/IO.h"

#include "io/VdbFile.h"

#include <openvdb/io/File.h>
#include <openvdb/openvdb.h>

#include <climits>
#include <cmath>
#include <iomanip>
#include <sstream>

namespace vdbclay {

using namespace io_internal;

namespace {

std::string num(double v)
{
    std::ostringstream o;
    o << std::setprecision(9) << v;
    return o.str();
}
bool isFog(const openvdb::GridBase& g)
{
    return g.isType<openvdb::FloatGrid>() && g.getGridClass() == openvdb::GRID_FOG_VOLUME;
}
bool isLevelSet(const openvdb::GridBase& g)
{
    return g.isType<openvdb::FloatGrid>() && g.getGridClass() == openvdb::GRID_LEVEL_SET;
}

} // namespace

std::string fogGridToImport(const std::string& path, const std::string& gridName)
{
    openvdb::initialize();
    openvdb::io::File file(path);
    openChecked(file, path);
    openvdb::GridPtrVecPtr grids;
    try {
        grids = file.readAllGridMetadata();
    } catch (const std::exception& e) {
        throw Error(damaged(path) + reason(e));
    }
    file.close();
    if (!gridName.empty()) {
        for (const auto& g : *grids)
            if (g->getName() == gridName) return isFog(*g) ? gridName : std::string();
        return ""; // the level set reader says it is missing
    }
    for (const auto& g : *grids)
        if (isLevelSet(*g)) return ""; // a level set first
    for (const auto& g : *grids)
        if (isFog(*g)) return g->getName();
    return "";
}

FogClay readFogAsClay(const std::string& path, const std::string& gridName, int32_t fullMass, int dimensions)
{
    openvdb::initialize();
    if (fullMass <= 0) throw Error("the mass per voxel must be > 0, not " + std::to_string(fullMass));
    openvdb::io::File file(path);
    const auto layout = openChecked(file, path);
    const std::string what = path + ": grid \"" + gridName + "\"";
    if (!file.hasGrid(gridName)) {
        throw Error(path + " has no grid named \"" + gridName + "\" (grids: " + gridNames(file) + ")");
    }
    for (const auto& g : layout) {
        if (g.baseName() == gridName && g.type != "Tree_float_5_4_3") {
            throw Error(what + " is a " + valueTypeOf(g.type) + " grid, expected a FloatGrid fog volume");
        }
    }
    openvdb::FloatGrid::Ptr fog;
    try {
        fog = openvdb::gridPtrCast<openvdb::FloatGrid>(file.readGrid(gridName));
    } catch (const std::exception& e) {
        throw Error(damaged(path) + reason(e));
    }
    file.close();
    if (!fog || !isFog(*fog)) {
        throw Error(what + " is not a FloatGrid fog volume (class " +
                    (fog ? openvdb::GridBase::gridClassToString(fog->getGridClass()) : std::string("?")) +
                    ")");
    }
    const openvdb::Vec3d vs = fog->voxelSize();
    if (!fog->transform().isLinear() || !(vs[0] > 0) || vs[0] != vs[1] || vs[0] != vs[2]) {
        throw Error(what +
                    ": a fog volume is taken voxel for voxel, which needs a linear transform with "
                    "cubic voxels (voxel size " +
                    num(vs[0]) + " x " + num(vs[1]) + " x " + num(vs[2]) + ")");
    }
    if (fog->background() != 0.f) {
        throw Error(what + " has background density " + num(fog->background()) +
                    ", expected 0 (a non-zero background fills all of space)");
    }
    FogClay out;
    out.voxelSize = vs[0];
    out.mass = openvdb::Int32Grid::create(0);
    out.mass->setName("mass");
    auto acc = out.mass->getAccessor();
    for (auto it = fog->tree().cbeginValueOn(); it; ++it) {
        const double d = *it;
        if (!std::isfinite(d) || d < 0) {
            throw Error(what + " holds density " + num(d) + " at voxel " + coordText(it.getCoord()) +
                        ", expected a finite value >= 0");
        }
        const double m = std::round(d * fullMass);
        if (m > double(INT32_MAX)) {
            throw Error(what + ": density " + num(d) + " at voxel " + coordText(it.getCoord()) + " x " +
                        std::to_string(fullMass) + " does not fit a cell (int32)");
        }
        if (m <= 0) continue;
        if (!it.isVoxelValue() && dimensions == 3) { // uniform clay stays a tile
            acc.addTile(it.getLevel(), it.getCoord(), int32_t(m), true);
            continue;
        }
        openvdb::CoordBBox box;
        it.getBoundingBox(box);
        if (dimensions == 2) {
            if (box.min().z() > 0 || box.max().z() < 0) continue;
            box.min().setZ(0);
            box.max().setZ(0);
        }
        for (auto c = box.begin(); c; ++c)
            acc.setValueOn(*c, int32_t(m));
    }
    if (out.mass->activeVoxelCount() == 0) {
        throw Error(what + ": no voxel" + (dimensions == 2 ? " of the z = 0 layer" : "") +
                    " holds enough density for a unit of mass (" + std::to_string(fullMass) +
                    " per full voxel)");
    }
    normalizeClay(*out.mass, path, gridName);
    out.note = "grid \"" + gridName + "\" is a fog volume (class " +
               openvdb::GridBase::gridClassToString(fog->getGridClass()) +
               "): each voxel holds round(density x " + std::to_string(fullMass) +
               "), voxel for voxel at its voxel size " + num(vs[0]);
    return out;
}

ClayFile readAsClay(const std::string& path, std::string& note)
{
    openvdb::initialize();
    note.clear();
    openvdb::GridPtrVecPtr grids;
    {
        openvdb::io::File file(path);
        openChecked(file, path);
        try {
            grids = file.readAllGridMetadata();
        } catch (const std::exception& e) {
            throw Error(damaged(path) + reason(e));
        }
        file.close();
    }
    std::string fog, levelSet, names;
    double levelSetVoxel = 1;
    for (const auto& g : *grids) {
        if (g->getName() == "mass") return readClayFile(path);
        if (fog.empty() && isFog(*g)) fog = g->getName();
        if (levelSet.empty() && isLevelSet(*g)) {
            levelSet = g->getName();
            levelSetVoxel = g->voxelSize()[0];
        }
        names += (names.empty() ? "" : ", ") + ("\"" + g->getName() + "\"");
    }
    ClayFile out;
    if (!fog.empty()) {
        FogClay c = readFogAsClay(path, fog, out.meta.rule.threshold);
        openvdb::io::File file(path);
        file.open(false);
        c.mass->setTransform(file.readGridMetadata(fog)->transform().copy());
        file.close();
        out.mass = c.mass;
        out.meta.voxelSize = c.voxelSize;
        note = "no clay grid \"mass\" in " + path + ": using fog volume \"" + fog +
               "\" as density (1 = a full cell)";
        return out;
    }
    if (!levelSet.empty()) {
        const ShapePtr shape = loadLevelSet(path, levelSetVoxel, levelSet);
        out.mass = makeClay(*shape, out.meta.rule.threshold);
        setClayTransform(*out.mass, levelSetVoxel, UpAxis::Y);
        out.meta.voxelSize = levelSetVoxel;
        note = "no clay grid \"mass\" in " + path + ": using level set \"" + levelSet +
               "\" (inside = full clay, boundary voxels by the part they cover)";
        return out;
    }
    throw Error(path + ": no clay grid \"mass\", fog volume or level set among its " +
                std::to_string(grids->size()) + " grid(s)" +
                (names.empty() ? std::string() : " (" + names + ")"));
}

} // namespace vdbclay
