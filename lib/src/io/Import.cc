// Clay from .vdb files that are not clay files: fog volumes (density x the mass of a full cell,
// voxel for voxel) and level sets (makeClay of the level set as a shape), for `vdbclay import`,
// `render` and `mesh` (readAsClay). The files are opened with the checks of VdbFile.h.
#include "vdbclay/IO.h"

#include "io/VdbFile.h"

#include <openvdb/io/File.h>
#include <openvdb/openvdb.h>

#include <algorithm>
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
/// A FloatGrid that is neither a fog volume nor a level set: density only when asked for.
bool isOtherFloat(const openvdb::GridBase& g)
{
    return g.isType<openvdb::FloatGrid>() && !isFog(g) && !isLevelSet(g);
}
std::string otherFloatRefused(const std::string& path, const openvdb::GridBase& g)
{
    return path + ": grid \"" + g.getName() + "\" is a FloatGrid of class " +
           openvdb::GridBase::gridClassToString(g.getGridClass()) +
           ", neither a level set nor a fog volume; to read it as density (1 = a full cell), ask for it "
           "(vdbclay import --as density)";
}

/// Where a fog's voxels go in the clay's index space: clay = signed permutation of the fog's index
/// + offset, the clay's transform clayTransform(voxel size, up).
struct FogPlacement {
    int axis[3] = {0, 1, 2}; ///< clay axis i takes fog axis axis[i]
    int sign[3] = {1, 1, 1};
    openvdb::Coord offset;
    double rounded = 0; ///< the largest distance (voxels) the offset was rounded by
    bool ok = false;
    bool identity() const
    {
        return axis[0] == 0 && axis[1] == 1 && axis[2] == 2 && sign[0] > 0 && sign[1] > 0 && sign[2] > 0;
    }
    openvdb::Coord map(const openvdb::Coord& f) const
    {
        openvdb::Coord c;
        for (int i = 0; i < 3; ++i)
            c[i] = sign[i] * f[axis[i]] + offset[i];
        return c;
    }
};

FogPlacement placeFog(const openvdb::math::Transform& fog, const openvdb::math::Transform& clay)
{
    FogPlacement p;
    auto to = [&](double x, double y, double z) {
        return clay.worldToIndex(fog.indexToWorld(openvdb::Vec3d(x, y, z)));
    };
    const openvdb::Vec3d o = to(0, 0, 0);
    bool used[3] = {false, false, false};
    for (int f = 0; f < 3; ++f) {
        const openvdb::Vec3d col = to(f == 0, f == 1, f == 2) - o;
        int hit = -1;
        for (int i = 0; i < 3; ++i) {
            const bool unit = std::abs(std::abs(col[i]) - 1.0) < 1e-6;
            const bool zero = std::abs(col[i]) < 1e-6;
            if (unit && hit < 0) {
                hit = i;
            } else if (!zero) {
                return p; // not a quarter-turn mapping
            }
        }
        if (hit < 0 || used[hit]) return p;
        used[hit] = true;
        p.axis[hit] = f;
        p.sign[hit] = col[hit] > 0 ? 1 : -1;
    }
    for (int i = 0; i < 3; ++i) {
        const double r = std::round(o[i]);
        p.offset[i] = int32_t(r);
        p.rounded = std::max(p.rounded, std::abs(o[i] - r));
    }
    p.ok = true;
    return p;
}

} // namespace

std::string fogGridToImport(const std::string& path, const std::string& gridName, bool asDensity)
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
    if (asDensity) {
        for (const auto& g : *grids) {
            if (gridName.empty() ? (isFog(*g) || isOtherFloat(*g)) : g->getName() == gridName) {
                if (!isFog(*g) && !isOtherFloat(*g)) {
                    throw Error(path + ": grid \"" + gridName + "\" is a " +
                                (g->isType<openvdb::FloatGrid>() ? std::string("level set")
                                                                 : g->valueType() + " grid") +
                                ", not a density FloatGrid; import it without --as density");
                }
                return g->getName();
            }
        }
        if (!gridName.empty()) throw Error(path + " has no grid named \"" + gridName + "\"");
        throw Error(path + ": no FloatGrid other than level sets among its " + std::to_string(grids->size()) +
                    " grid(s) to read as density");
    }
    if (!gridName.empty()) {
        for (const auto& g : *grids) {
            if (g->getName() != gridName) continue;
            if (isOtherFloat(*g)) throw Error(otherFloatRefused(path, *g));
            return isFog(*g) ? gridName : std::string();
        }
        return ""; // the level set reader says it is missing
    }
    for (const auto& g : *grids)
        if (isLevelSet(*g)) return ""; // a level set first
    for (const auto& g : *grids)
        if (isFog(*g)) return g->getName();
    for (const auto& g : *grids)
        if (isOtherFloat(*g)) throw Error(otherFloatRefused(path, *g));
    return "";
}

FogClay readFogAsClay(const std::string& path, const std::string& gridName, int32_t fullMass, int dimensions,
                      bool asDensity, std::optional<UpAxis> up)
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
    if (!fog || !(isFog(*fog) || (asDensity && isOtherFloat(*fog)))) {
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
    // Where it lies: vdbclay's own z-up density says so (vdbclay_up); else the placement without a
    // turn of the axes, else any quarter-turn one.
    const openvdb::StringMetadata::ConstPtr upMeta = fog->getMetadata<openvdb::StringMetadata>("vdbclay_up");
    FogPlacement place;
    for (UpAxis axis : {UpAxis::Y, UpAxis::Z}) {
        if (up && axis != *up) continue;
        setClayTransform(*out.mass, vs[0], axis);
        const FogPlacement p = placeFog(fog->transform(), out.mass->transform());
        if (!p.ok) continue;
        const bool wanted = up || (upMeta ? (upMeta->value() == "z") == (axis == UpAxis::Z) : p.identity());
        if (!place.ok || wanted) {
            place = p;
            out.up = axis;
        }
        if (wanted) break;
    }
    if (!place.ok) {
        throw Error(what +
                    ": its transform turns its voxels other than by quarter turns; a fog volume is taken "
                    "voxel for voxel (resample it to an axis-aligned grid first)");
    }
    setClayTransform(*out.mass, vs[0], out.up);
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
        openvdb::CoordBBox fogBox;
        it.getBoundingBox(fogBox);
        openvdb::CoordBBox box(place.map(fogBox.min()), place.map(fogBox.min()));
        box.expand(place.map(fogBox.max()));
        if (dimensions == 2) {
            if (box.min().z() > 0 || box.max().z() < 0) continue;
            box.min().setZ(0);
            box.max().setZ(0);
        }
        if (it.isVoxelValue()) {
            acc.setValueOn(box.min(), int32_t(m));
        } else { // uniform clay stays tiles where whole nodes fit (fill), leaves elsewhere
            out.mass->tree().fill(box, int32_t(m), true);
            acc.clear();
        }
    }
    if (out.mass->activeVoxelCount() == 0) {
        throw Error(what + ": no voxel" + (dimensions == 2 ? " of the z = 0 layer" : "") +
                    " holds enough density for a unit of mass (" + std::to_string(fullMass) +
                    " per full voxel)");
    }
    normalizeClay(*out.mass, path, gridName);
    out.note = "grid \"" + gridName + "\" is " + (isFog(*fog) ? "a fog volume" : "read as density") +
               " (class " + openvdb::GridBase::gridClassToString(fog->getGridClass()) +
               "): each voxel holds round(density x " + std::to_string(fullMass) +
               "), voxel for voxel at its voxel size " + num(vs[0]) + ", where it lies in the world";
    if (out.up == UpAxis::Z) out.note += " (z up)";
    if (place.rounded > 1e-6) {
        out.note += "; its voxels sit " + num(place.rounded) +
                    " voxel off the clay's grid, rounded to the nearest voxel";
    }
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
        out.mass = c.mass; // in the fog's place, through the clay's transform
        out.meta.voxelSize = c.voxelSize;
        out.meta.up = c.up;
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
