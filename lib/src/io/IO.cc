// Clay files (.vdb), surface meshes and clay from shapes.
//
// A clay file holds three grids: "mass" (the exact Int32 clay, with the vdbclay_* metadata, among
// them its largest cell, vdbclay_max_mass: the memory estimate reads it without the voxels, and a
// file whose voxels exceed it is refused on reading; round 7),
// "density" (m / Tc, a fog volume) and "surface" (the level set where a cell is half full), the
// last two for other tools (Houdini, Blender, vdb_view) to look at. Every write goes to a temporary
// file beside the target that is renamed over it (AtomicFile.h).
#include "vdbclay/IO.h"

#include "vdbclay/Metrics.h"

#include "core/AtomicFile.h"
#include "io/ClayFileMeta.h"
#include "shapes/Rasterize.h"
#include "output/Surface.h"
#include "io/VdbCheck.h"

#include <openvdb/io/Archive.h>
#include <openvdb/io/File.h>
#include <openvdb/io/GridDescriptor.h>
#include <openvdb/io/io.h>
#include <openvdb/openvdb.h>

#include <tbb/blocked_range.h>
#include <tbb/parallel_reduce.h>

#include <fcntl.h>
#include <sys/stat.h>
#include <unistd.h>

#include <array>
#include <cerrno>
#include <climits>
#include <cmath>
#include <cstring>
#include <fstream>
#include <memory>
#include <new>
#include <algorithm>
#include <cstdio>
#include <iomanip>
#include <limits>
#include <ostream>
#include <sstream>

#ifndef VDBCLAY_VERSION
#define VDBCLAY_VERSION "unknown"
#endif

namespace vdbclay {

using io_internal::writeAtomically;

namespace {

/// An archive that writes a seekable .vdb (like openvdb::io::File) into a caller's stream, so the
/// caller controls the file: its name, flushing, fsync and errors.
class StreamArchive : public openvdb::io::Archive {
public:
    void writeTo(std::ostream& os, const openvdb::GridCPtrVec& grids) const
    {
        openvdb::io::Archive::write(os, grids, /*seekable=*/true);
    }
};

void initOpenVDB()
{
    openvdb::initialize();
}

/// An exception's text fit for a message: OpenVDB's errors on damaged files quote whatever bytes
/// it read (a "grid type" of garbage and kilobytes of blanks), so keep printable characters,
/// collapse runs of blanks and cut it short.
std::string reason(const std::exception& e)
{
    if (dynamic_cast<const std::bad_alloc*>(&e)) return "it records a size larger than the memory available";
    std::string out;
    const char* p = e.what();
    for (; *p && out.size() < 200; ++p) {
        const unsigned char c = static_cast<unsigned char>(*p);
        const char ch = (c >= 32 && c < 127) ? char(c) : ' ';
        if (ch == ' ' && (out.empty() || out.back() == ' ')) continue;
        out += ch;
    }
    while (!out.empty() && out.back() == ' ')
        out.pop_back();
    if (*p) out += "...";
    return out.empty() ? "unreadable data" : out;
}

/// The start of every message about a file OpenVDB could not read.
std::string damaged(const std::string& path)
{
    return path + " is not a .vdb file or is truncated or damaged: ";
}

using io_internal::kMetaAlpha;
using io_internal::kMetaDimensions;
using io_internal::kMetaFrames;
using io_internal::kMetaFrameSteps;
using io_internal::kMetaMaxMass;
using io_internal::kMetaRule;
using io_internal::kMetaSeed;
using io_internal::kMetaSteps;
using io_internal::kMetaThreshold;
using io_internal::kMetaUp;
using io_internal::kMetaVersion;
using io_internal::kMetaVoxelSize;

void validateMeta(const ClayMeta& meta, const std::string& path)
{
    try {
        validate(meta.rule);
    } catch (const Error& e) {
        throw Error("cannot write " + path + ": " + e.what());
    }
    if (meta.dimensions != 2 && meta.dimensions != 3) {
        throw Error("cannot write " + path + ": dimensions must be 2 or 3, not " +
                    std::to_string(meta.dimensions));
    }
    if (!(meta.voxelSize > 0) || !std::isfinite(meta.voxelSize)) {
        throw Error("cannot write " + path + ": the voxel size must be positive and finite");
    }
}

/// "int32" for "Tree_int32_5_4_3": the value type, as openvdb::GridBase::valueType() names it.
std::string valueTypeOf(const std::string& treeType)
{
    std::string t = treeType;
    if (t.rfind("Tree_", 0) == 0) t = t.substr(5);
    const auto cut = t.find("_5_4_3");
    return cut == std::string::npos ? t : t.substr(0, cut);
}

/// Opens @a path for reading with every check readClayFile promises; grids are read in full
/// (no delayed loading), so the file may be replaced afterwards. OpenVDB trusts the sizes a file
/// records (a damaged one makes it allocate gigabytes or overrun a buffer), so the layout is
/// checked byte by byte first (VdbCheck.h). @return the grids the check found.
std::vector<io_internal::VdbGridLayout> openChecked(openvdb::io::File& file, const std::string& path)
{
    struct stat st;
    if (::stat(path.c_str(), &st) != 0) {
        const int err = errno;
        throw Error(path + ": " + (err == ENOENT ? std::string("no such file") : std::strerror(err)));
    }
    if (S_ISDIR(st.st_mode)) throw Error(path + " is a directory, not a .vdb file");
    // A .vdb is read by seeking (grid offsets): a device or pipe cannot be, and /dev/zero never ends.
    if (!S_ISREG(st.st_mode)) throw Error(path + " is not a regular file (a .vdb is read by seeking in it)");
    {
        const int fd = ::open(path.c_str(), O_RDONLY | O_CLOEXEC);
        if (fd < 0) {
            const int err = errno;
            throw Error(path + ": cannot open it: " + std::strerror(err));
        }
        ::close(fd);
    }
    const std::string prefix = damaged(path);
    std::vector<io_internal::VdbGridLayout> grids;
    try {
        grids = io_internal::checkVdbLayout(path);
    } catch (const Error& e) {
        throw Error(prefix + e.what());
    }
    try {
        file.open(/*delayLoad=*/false);
    } catch (const std::exception& e) {
        throw Error(prefix + reason(e));
    }
    return grids;
}

std::string gridNames(openvdb::io::File& file)
{
    std::string names;
    for (auto it = file.beginName(); it != file.endName(); ++it) {
        if (!names.empty()) names += ", ";
        names += "\"" + it.gridName() + "\"";
    }
    return names.empty() ? "none" : names;
}

/// Reads every grid of an open file, turning any failure into an Error naming the file.
openvdb::GridPtrVecPtr readAllGrids(openvdb::io::File& file, const std::string& path)
{
    try {
        return file.getGrids();
    } catch (const std::exception& e) {
        throw Error(damaged(path) + reason(e));
    }
}

template <typename T, typename MetaT>
bool readMeta(const openvdb::GridBase& grid, const char* name, T& out, const std::string& path,
              const char* typeName)
{
    const auto m = grid[name];
    if (!m) return false;
    const auto typed = std::dynamic_pointer_cast<const MetaT>(m);
    if (!typed) {
        throw Error(path + ": metadata " + name + " is a " + m->typeName() + ", expected " + typeName);
    }
    out = T(typed->value());
    return true;
}

/// For an Int32 grid that records Tc (vdbclay_threshold), the accuracy metrics of Metrics.h, in
/// the dimensions it records (3 without vdbclay_dimensions).
void describeClayMetrics(std::ostream& s, const openvdb::Int32Grid& g, const std::string& path)
{
    int32_t tc = 0, dims = 3;
    if (!readMeta<int32_t, openvdb::Int32Metadata>(g, kMetaThreshold, tc, path, "int32") || tc <= 0) return;
    readMeta<int32_t, openvdb::Int32Metadata>(g, kMetaDimensions, dims, path, "int32");
    if (dims != 2 && dims != 3) return;
    ClayMetrics m;
    try {
        m = measureClay(g, tc, nullptr, dims);
    } catch (const Error& e) {
        s << "  clay metrics: not measured: " << e.what() << "\n";
        return;
    }
    s << "  clay (Tc " << tc << ", " << dims << "D): " << m.clayVoxels << " voxels holding clay, "
      << m.occupiedVoxels << " at density >= 0.5, largest cell " << m.maxCell << "\n";
    s << "  residual overload: " << m.residualOverload << " (mass above Tc, obstacles not recorded)\n";
    s << "  interior cells: " << m.interiorCells << ", mean density " << m.interiorMeanDensity
      << ", heterogeneity CV " << m.heterogeneityCV << "\n";
    s << "  compaction: " << m.compaction << " (clay voxels / ceil(mass / Tc); 1 = compact)\n";
}

std::string coordText(const openvdb::Coord& c)
{
    std::ostringstream s;
    s << "(" << c.x() << ", " << c.y() << ", " << c.z() << ")";
    return s.str();
}

/// Clay voxels may lie at most this far from the origin along each axis: shapes' bounds (Shapes.h)
/// and the automaton's search margins stay inside int32 from there.
constexpr int32_t kMaxClayCoord = 1 << 30;
/// Tiles of clay are expanded into voxels on reading, up to this many voxels in all.
constexpr uint64_t kMaxTileVoxels = uint64_t(1) << 26;

/// One definition of "the clay in a file", used by every command: every voxel holding a non-zero
/// value, active or not, is clay, as totalMass() and clayVoxelCount() count it. So inactive voxels
/// holding mass become active, tiles become voxels (a file may hold at most kMaxTileVoxels
/// voxels of them), and a non-zero background (clay in all of space) is refused, as is clay
/// outside +-2^30.
void normalizeClay(openvdb::Int32Grid& grid, const std::string& path, const std::string& gridName)
{
    const std::string what = path + ": grid \"" + gridName + "\"";
    if (grid.background() != 0) {
        throw Error(what + " has background value " + std::to_string(grid.background()) +
                    ", expected 0 (a non-zero background puts clay in every voxel of space)");
    }
    uint64_t tileVoxels = 0;
    bool inactive = false;
    for (auto it = grid.tree().cbeginValueAll(); it; ++it) {
        if (*it == 0) continue;
        if (!it.isVoxelValue()) {
            tileVoxels += it.getVoxelCount();
            if (tileVoxels > kMaxTileVoxels) {
                throw Error(what + " holds tiles of clay of more than " + std::to_string(kMaxTileVoxels) +
                            " voxels in all (a tile at " + coordText(it.getCoord()) + " of " +
                            std::to_string(it.getVoxelCount()) + "); vdbclay expands tiles into voxels");
            }
        }
        if (!it.isValueOn()) inactive = true;
    }
    if (inactive) {
        for (auto it = grid.tree().beginValueAll(); it; ++it) {
            if (*it != 0 && !it.isValueOn()) it.setActiveState(true);
        }
    }
    if (tileVoxels > 0) grid.tree().voxelizeActiveTiles();
    const openvdb::CoordBBox box = grid.evalActiveVoxelBoundingBox();
    if (!box.empty()) {
        for (int a = 0; a < 3; ++a) {
            if (box.min()[a] < -kMaxClayCoord || box.max()[a] > kMaxClayCoord) {
                throw Error(what + " holds clay from " + coordText(box.min()) + " to " +
                            coordText(box.max()) +
                            ", outside the coordinate range +-2^30 that vdbclay works in");
            }
        }
    }
}

} // namespace

void writeClayFile(const std::string& path, const MassGrid& mass, const ClayMeta& meta)
{
    initOpenVDB();
    validateMeta(meta, path);

    // The vdbclay_* metadata goes on "mass" (readClayFile's source) and on "density" too: Debian's
    // python3-openvdb (and other FloatGrid-only readers) cannot load Int32 grids, and with Tc there
    // a Python user turns density back into mass (round(density * Tc); docs/INTEROP.md).
    openvdb::MetaMap clayMeta;
    clayMeta.insertMeta(kMetaThreshold, openvdb::Int32Metadata(meta.rule.threshold));
    clayMeta.insertMeta(kMetaRule, openvdb::StringMetadata(ruleName(meta.rule.rule)));
    clayMeta.insertMeta(kMetaAlpha, openvdb::DoubleMetadata(meta.rule.alpha));
    clayMeta.insertMeta(kMetaSeed, openvdb::Int64Metadata(int64_t(meta.seed)));
    clayMeta.insertMeta(kMetaSteps, openvdb::Int64Metadata(int64_t(meta.steps)));
    clayMeta.insertMeta(kMetaFrames, openvdb::Int64Metadata(int64_t(meta.frames)));
    if (meta.frameSteps > 0) {
        clayMeta.insertMeta(kMetaFrameSteps, openvdb::Int64Metadata(int64_t(meta.frameSteps)));
    }
    clayMeta.insertMeta(kMetaDimensions, openvdb::Int32Metadata(meta.dimensions));
    // Every value, tiles included (the background is 0): the leaves' values in parallel, then the
    // tiles above them.
    std::vector<const MassGrid::TreeType::LeafNodeType*> massLeaves;
    massLeaves.reserve(mass.tree().leafCount());
    for (auto it = mass.tree().cbeginLeaf(); it; ++it)
        massLeaves.push_back(&*it);
    int32_t largest = tbb::parallel_reduce(
        tbb::blocked_range<size_t>(0, massLeaves.size()), int32_t(0),
        [&massLeaves](const tbb::blocked_range<size_t>& r, int32_t m) {
            for (size_t i = r.begin(); i != r.end(); ++i) {
                const int32_t* v = massLeaves[i]->buffer().data();
                for (openvdb::Index k = 0; k < MassGrid::TreeType::LeafNodeType::SIZE; ++k)
                    m = std::max(m, v[k]);
            }
            return m;
        },
        [](int32_t a, int32_t b) { return std::max(a, b); });
    auto tile = mass.tree().cbeginValueAll();
    tile.setMaxDepth(tile.getLeafDepth() - 1);
    for (; tile; ++tile)
        largest = std::max(largest, *tile);
    clayMeta.insertMeta(kMetaMaxMass, openvdb::Int64Metadata(largest));
    clayMeta.insertMeta(kMetaVoxelSize, openvdb::DoubleMetadata(meta.voxelSize));
    clayMeta.insertMeta(kMetaVersion, openvdb::StringMetadata(VDBCLAY_VERSION));
    if (meta.up != UpAxis::Y) clayMeta.insertMeta(kMetaUp, openvdb::StringMetadata(upAxisName(meta.up)));

    openvdb::MetaMap massMeta;
    massMeta.insertMeta(openvdb::GridBase::META_GRID_NAME, openvdb::StringMetadata("mass"));
    massMeta.insertMeta(openvdb::GridBase::META_GRID_CLASS,
                        openvdb::StringMetadata(openvdb::GridBase::gridClassToString(openvdb::GRID_UNKNOWN)));
    for (auto it = clayMeta.beginMeta(); it != clayMeta.endMeta(); ++it)
        massMeta.insertMeta(it->first, *it->second);

    const auto xform = io_internal::clayTransform(meta.voxelSize, meta.up);
    // Shares the caller's tree (read only) with a fresh name, metadata and transform.
    openvdb::GridBase::ConstPtr massOut = mass.copyGridReplacingMetadataAndTransform(massMeta, xform);

    openvdb::FloatGrid::Ptr density, surface;
    try {
        density = io_internal::densityGrid(mass, meta.rule.threshold, meta.voxelSize);
        density->setTransform(xform->copy());
        surface = io_internal::surfaceLevelSet(*density, 0.5);
    } catch (const Error& e) {
        throw Error("cannot write " + path + ": " + e.what());
    } catch (const std::exception& e) {
        throw Error("cannot write " + path + ": building the density and surface failed: " + reason(e));
    }
    for (auto it = clayMeta.beginMeta(); it != clayMeta.endMeta(); ++it)
        density->insertMeta(it->first, *it->second);

    openvdb::GridCPtrVec grids{massOut, density, surface};
    writeAtomically(path, [&](std::ostream& os) { StreamArchive().writeTo(os, grids); });
}

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
    initOpenVDB();
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
    initOpenVDB();
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
    uint64_t tileVoxels = 0;
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
        openvdb::CoordBBox box;
        it.getBoundingBox(box);
        if (!it.isVoxelValue()) {
            tileVoxels += it.getVoxelCount();
            if (tileVoxels > kMaxTileVoxels) {
                throw Error(what + " holds tiles of more than " + std::to_string(kMaxTileVoxels) +
                            " voxels in all; vdbclay expands tiles into voxels");
            }
        }
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
    initOpenVDB();
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

ClayFile readClayFile(const std::string& path, const std::string& gridName)
{
    initOpenVDB();
    openvdb::io::File file(path);
    const auto layout = openChecked(file, path);

    if (!file.hasGrid(gridName)) {
        const std::string names = gridNames(file);
        throw Error(path + " has no grid named \"" + gridName + "\" (grids: " + names + ")");
    }
    // Refused before reading: only Int32 trees are read (and only checked trees are ever read).
    for (const auto& g : layout) {
        if (g.baseName() == gridName && g.type != "Tree_int32_5_4_3") {
            throw Error("grid \"" + gridName + "\" in " + path + " is a " + valueTypeOf(g.type) +
                        " grid, expected an Int32Grid");
        }
    }
    openvdb::GridBase::Ptr base;
    try {
        base = file.readGrid(gridName);
    } catch (const std::exception& e) {
        throw Error(damaged(path) + reason(e));
    }
    if (!base) throw Error(path + ": grid \"" + gridName + "\" could not be read");
    file.close();

    ClayFile out;
    out.mass = openvdb::gridPtrCast<openvdb::Int32Grid>(base);
    if (!out.mass) {
        throw Error("grid \"" + gridName + "\" in " + path + " is a " + base->valueType() +
                    " grid, expected an Int32Grid");
    }
    // The largest cell it records (vdbclay_max_mass; the memory estimate trusts it without reading
    // the voxels), checked against every voxel.
    int64_t recordedMax = INT64_MAX;
    readMeta<int64_t, openvdb::Int64Metadata>(*out.mass, kMetaMaxMass, recordedMax, path, "int64");
    for (auto it = out.mass->tree().cbeginValueAll(); it; ++it) {
        if (*it < 0) {
            throw Error(path + ": grid \"" + gridName + "\" holds negative mass " + std::to_string(*it) +
                        " at voxel " + coordText(it.getCoord()));
        }
        if (*it > recordedMax) {
            throw Error(path + ": grid \"" + gridName + "\" holds mass " + std::to_string(*it) +
                        " at voxel " + coordText(it.getCoord()) +
                        ", more than its largest cell recorded in metadata " + kMetaMaxMass + " (" +
                        std::to_string(recordedMax) + ")");
        }
    }
    normalizeClay(*out.mass, path, gridName);

    const openvdb::GridBase& g = *out.mass;
    ClayMeta& m = out.meta;
    m.voxelSize = g.voxelSize()[0];
    bool any = false;
    int32_t i32 = 0;
    int64_t i64 = 0;
    double dbl = 0;
    std::string str;
    if (readMeta<int32_t, openvdb::Int32Metadata>(g, kMetaThreshold, i32, path, "int32")) {
        m.rule.threshold = i32;
        any = true;
    }
    if (readMeta<std::string, openvdb::StringMetadata>(g, kMetaRule, str, path, "string")) {
        try {
            m.rule.rule = parseRule(str);
        } catch (const Error& e) {
            throw Error(path + ": metadata " + kMetaRule + ": " + e.what());
        }
        any = true;
    }
    if (readMeta<double, openvdb::DoubleMetadata>(g, kMetaAlpha, dbl, path, "double")) {
        m.rule.alpha = dbl;
        any = true;
    }
    if (readMeta<int64_t, openvdb::Int64Metadata>(g, kMetaSeed, i64, path, "int64")) {
        m.seed = uint64_t(i64);
        any = true;
    }
    if (readMeta<int64_t, openvdb::Int64Metadata>(g, kMetaSteps, i64, path, "int64")) {
        m.steps = uint64_t(i64);
        any = true;
    }
    if (readMeta<int64_t, openvdb::Int64Metadata>(g, kMetaFrames, i64, path, "int64")) {
        m.frames = uint64_t(i64);
        any = true;
    }
    if (readMeta<int64_t, openvdb::Int64Metadata>(g, kMetaFrameSteps, i64, path, "int64")) {
        if (i64 < 0) throw Error(path + ": invalid vdbclay metadata: " + kMetaFrameSteps + " is negative");
        m.frameSteps = uint64_t(i64);
        any = true;
    }
    if (readMeta<int32_t, openvdb::Int32Metadata>(g, kMetaDimensions, i32, path, "int32")) {
        m.dimensions = i32;
        any = true;
    }
    if (readMeta<double, openvdb::DoubleMetadata>(g, kMetaVoxelSize, dbl, path, "double")) {
        m.voxelSize = dbl;
        any = true;
    }
    if (readMeta<std::string, openvdb::StringMetadata>(g, kMetaVersion, str, path, "string")) {
        m.version = str;
        any = true;
    }
    if (readMeta<std::string, openvdb::StringMetadata>(g, kMetaUp, str, path, "string")) {
        try {
            m.up = parseUpAxis(str);
        } catch (const Error& e) {
            throw Error(path + ": metadata " + kMetaUp + ": " + e.what());
        }
        any = true;
    }
    out.hasMeta = any;
    if (any) {
        try {
            validate(m.rule);
        } catch (const Error& e) {
            throw Error(path + ": invalid vdbclay metadata: " + e.what());
        }
        if (m.dimensions != 2 && m.dimensions != 3) {
            throw Error(path + ": invalid vdbclay metadata: " + kMetaDimensions + " is " +
                        std::to_string(m.dimensions) + ", expected 2 or 3");
        }
    }
    return out;
}

std::string describeVdb(const std::string& path)
{
    initOpenVDB();
    openvdb::io::File file(path);
    const auto layout = openChecked(file, path);
    // Grids of types whose trees vdbclay cannot check first are listed, not read.
    std::vector<std::string> unread;
    openvdb::GridPtrVecPtr grids;
    if (std::all_of(layout.begin(), layout.end(), [](const auto& g) { return g.treeChecked; })) {
        grids = readAllGrids(file, path);
    } else {
        grids = std::make_shared<openvdb::GridPtrVec>();
        for (const auto& g : layout) {
            if (!g.treeChecked) {
                unread.push_back("grid \"" + printableText(g.baseName()) + "\": type " +
                                 printableText(g.type) +
                                 ", not read (vdbclay reads int32, int64, float, double and vec3 "
                                 "grids)\n");
                continue;
            }
            try {
                grids->push_back(file.readGrid(g.baseName()));
            } catch (const std::exception& e) {
                throw Error(damaged(path) + reason(e));
            }
        }
    }
    openvdb::MetaMap::Ptr fileMeta = file.getMetadata();
    const std::string version = file.version();
    file.close();

    std::ostringstream s;
    s << printableText(path) << ": OpenVDB file (format " << printableText(version) << "), " << layout.size()
      << (layout.size() == 1 ? " grid" : " grids") << "\n";
    auto printMeta = [&s](const openvdb::MetaMap& meta, const char* indent) {
        for (auto it = meta.beginMeta(); it != meta.endMeta(); ++it) {
            if (it->first == openvdb::GridBase::META_GRID_NAME) continue;
            s << indent << printableText(it->first) << " (" << printableText(it->second->typeName())
              << ") = " << printableText(it->second->str()) << "\n";
        }
    };
    if (fileMeta && fileMeta->metaCount() > 0) {
        s << "file metadata:\n";
        printMeta(*fileMeta, "  ");
    }
    for (const auto& g : *grids) {
        if (!g) continue;
        s << "grid \"" << printableText(g->getName()) << "\": type " << g->valueType() << ", class "
          << openvdb::GridBase::gridClassToString(g->getGridClass()) << "\n";
        s << "  active voxels: " << g->activeVoxelCount() << "\n";
        const openvdb::CoordBBox box = g->evalActiveVoxelBoundingBox();
        if (box.empty()) {
            s << "  index bbox: empty\n";
        } else {
            s << "  index bbox: [" << box.min().x() << ", " << box.min().y() << ", " << box.min().z()
              << "] .. [" << box.max().x() << ", " << box.max().y() << ", " << box.max().z() << "]\n";
        }
        const openvdb::Vec3d vs = g->voxelSize();
        s << "  voxel size: " << vs[0];
        if (vs[1] != vs[0] || vs[2] != vs[0]) s << " x " << vs[1] << " x " << vs[2];
        s << "\n";
        if (auto ig = openvdb::gridConstPtrCast<openvdb::Int32Grid>(g)) {
            // A damaged or foreign file may hold tiles, or more mass than 64 bits count: say so.
            if (ig->background() != 0) {
                s << "  total mass: none (the background is " << ig->background()
                  << ", not 0: clay in every voxel of space; vdbclay refuses it as clay)\n";
            } else {
                try {
                    const int64_t total = totalMass(*ig);
                    s << "  total mass: " << total << "\n";
                } catch (const Error&) {
                    s << "  total mass: more than 64 bits count\n";
                }
                try {
                    const uint64_t h = contentHash(*ig);
                    char hash[32];
                    std::snprintf(hash, sizeof hash, "%016llx", (unsigned long long)h);
                    s << "  content hash: " << hash << " (equal hashes: equal clay, voxel for voxel)\n";
                } catch (const Error&) {
                    s << "  content hash: none (the grid holds tiles of clay, not voxels)\n";
                }
                describeClayMetrics(s, *ig, path);
            }
        }
        if (g->metaCount() > 1) {
            s << "  metadata:\n";
            printMeta(*g, "    ");
        }
    }
    for (const std::string& u : unread)
        s << u;
    return s.str();
}

namespace {

/// Moves every vertex of @a mesh (index space, outward faces) along its normal by one distance,
/// so that the mesh encloses @a target voxels: marching cubes cuts convex edges and rounds convex
/// surfaces inward. Two Newton steps (volume' = area); the move is at most half a voxel.
void keepVolume(io_internal::SurfaceMesh& mesh, double target)
{
    std::vector<std::array<uint32_t, 3>> tris;
    tris.reserve(mesh.triangles.size() + 2 * mesh.quads.size());
    for (const auto& t : mesh.triangles)
        tris.push_back({{t[0], t[1], t[2]}});
    for (const auto& q : mesh.quads) {
        tris.push_back({{q[0], q[1], q[2]}});
        tris.push_back({{q[0], q[2], q[3]}});
    }
    for (int iteration = 0; iteration < 2; ++iteration) {
        std::vector<openvdb::Vec3d> normals(mesh.points.size(), openvdb::Vec3d(0.0));
        double volume = 0, area = 0;
        for (const auto& t : tris) {
            const openvdb::Vec3d a(mesh.points[t[0]]), b(mesh.points[t[1]]), c(mesh.points[t[2]]);
            const openvdb::Vec3d n = (b - a).cross(c - a); // twice the area, outward
            volume += a.dot(b.cross(c)) / 6;
            area += n.length() / 2;
            for (int i = 0; i < 3; ++i)
                normals[t[i]] += n;
        }
        if (!(area > 0)) return;
        const double shift = std::max(-0.5, std::min(0.5, (target - volume) / area));
        for (size_t i = 0; i < mesh.points.size(); ++i) {
            const double l = normals[i].length();
            if (l > 0)
                mesh.points[i] = openvdb::Vec3s(openvdb::Vec3d(mesh.points[i]) + normals[i] * (shift / l));
        }
    }
}

} // namespace

void writeSurfaceMesh(const std::string& path, const MassGrid& mass, int32_t threshold, double isovalue,
                      bool keepClayVolume)
{
    initOpenVDB();
    const std::string ext = io_internal::extensionOf(path);
    if (ext != ".obj" && ext != ".ply") {
        throw Error("cannot write " + path + ": unknown mesh format \"" + ext + "\" (use .obj or .ply)");
    }
    if (!(isovalue > 0) || !std::isfinite(isovalue)) {
        throw Error("cannot write " + path + ": the isovalue must be positive and finite");
    }
    if (clayVoxelCount(mass) == 0) throw Error("cannot write " + path + ": the grid holds no clay");

    io_internal::SurfaceMesh mesh;
    try {
        auto density = io_internal::densityGrid(mass, threshold, 1.0);
        mesh = io_internal::surfaceMesh(*density, isovalue);
        if (keepClayVolume && !mesh.points.empty()) {
            // The clay's volume: each cell counts for its fill, up to 1.
            double volume = 0;
            for (auto it = mass.cbeginValueOn(); it; ++it)
                volume += std::min(1.0, double(*it) / double(threshold)) * double(it.getVoxelCount());
            keepVolume(mesh, volume);
        }
    } catch (const Error& e) {
        throw Error("cannot write " + path + ": " + e.what());
    }
    if (mesh.points.empty() || (mesh.triangles.empty() && mesh.quads.empty())) {
        throw Error("cannot write " + path + ": no surface at density " + std::to_string(isovalue) +
                    " (no cell is that full)");
    }
    // World units: the vertices go through the grid's transform (voxel size, up axis), so the mesh
    // lies where the .vdb's grids lie in Blender or Houdini, and loadMesh with the same voxel size
    // and up axis puts it back on the same voxels.
    const openvdb::math::Transform& xform = mass.transform();
    for (auto& p : mesh.points)
        p = openvdb::Vec3s(xform.indexToWorld(openvdb::Vec3d(p)));

    // Quads are split into two triangles, so both formats hold triangles only.
    const size_t faces = mesh.triangles.size() + 2 * mesh.quads.size();
    writeAtomically(path, [&](std::ostream& os) {
        os << std::setprecision(9);
        if (ext == ".obj") {
            os << "# vdbclay " << VDBCLAY_VERSION << " clay surface at density " << isovalue
               << " (world units, voxel size " << xform.voxelSize()[0] << ")\n";
            os << "# " << mesh.points.size() << " vertices, " << faces << " triangles\n";
            for (const auto& p : mesh.points)
                os << "v " << p[0] << ' ' << p[1] << ' ' << p[2] << '\n';
            for (const auto& t : mesh.triangles) {
                os << "f " << t[0] + 1 << ' ' << t[1] + 1 << ' ' << t[2] + 1 << '\n';
            }
            for (const auto& q : mesh.quads) {
                os << "f " << q[0] + 1 << ' ' << q[1] + 1 << ' ' << q[2] + 1 << '\n';
                os << "f " << q[0] + 1 << ' ' << q[2] + 1 << ' ' << q[3] + 1 << '\n';
            }
        } else {
            os << "ply\nformat ascii 1.0\n";
            os << "comment vdbclay " << VDBCLAY_VERSION << " clay surface at density " << isovalue
               << " (world units, voxel size " << xform.voxelSize()[0] << ")\n";
            os << "element vertex " << mesh.points.size() << "\n";
            os << "property float x\nproperty float y\nproperty float z\n";
            os << "element face " << faces << "\n";
            os << "property list uchar int vertex_indices\nend_header\n";
            for (const auto& p : mesh.points)
                os << p[0] << ' ' << p[1] << ' ' << p[2] << '\n';
            for (const auto& t : mesh.triangles) {
                os << "3 " << t[0] << ' ' << t[1] << ' ' << t[2] << '\n';
            }
            for (const auto& q : mesh.quads) {
                os << "3 " << q[0] << ' ' << q[1] << ' ' << q[2] << '\n';
                os << "3 " << q[0] << ' ' << q[2] << ' ' << q[3] << '\n';
            }
        }
    });
}

void setClayTransform(MassGrid& mass, double voxelSize, UpAxis up)
{
    mass.setTransform(io_internal::clayTransform(voxelSize, up));
}

MassGridPtr makeClay(const Shape& shape, int32_t massPerVoxel, int dimensions)
{
    initOpenVDB();
    if (massPerVoxel <= 0) {
        throw Error("the mass per voxel must be > 0, not " + std::to_string(massPerVoxel));
    }
    if (dimensions != 2 && dimensions != 3) {
        throw Error("clay: dimensions must be 2 or 3, not " + std::to_string(dimensions));
    }
    auto grid = openvdb::Int32Grid::create(0);
    grid->setName("mass");
    auto acc = grid->getAccessor();
    if (shape.keepsVolume()) {
        // Meshes and level sets: each voxel holds round(m0 x the fraction of it the shape covers)
        // (Coverage.cc), so the clay's mass is the shape's volume x m0. A boundary voxel holding
        // less than Tc is under-full clay, which the automaton may fill like any other.
        forEachVoxelCovered(shape, dimensions, [&](int32_t x, int32_t y, int32_t z, double fraction) {
            const int64_t m = std::llround(double(massPerVoxel) * fraction);
            if (m > 0) acc.setValueOn(openvdb::Coord(x, y, z), int32_t(std::min<int64_t>(m, massPerVoxel)));
        });
        if (grid->activeVoxelCount() == 0) {
            throw Error(shape.describe() + " covers no voxel" +
                        (dimensions == 2 ? " of the z = 0 layer" : "") + " enough to hold a unit of mass (" +
                        std::to_string(massPerVoxel) + " per voxel)");
        }
    } else {
        // The voxels forEachVoxelInside visits, leaf by leaf on every core (Rasterize.h).
        raster_internal::rasterizeInside(grid->tree(), shape, dimensions, massPerVoxel, /*threads=*/0);
    }
    if (grid->activeVoxelCount() == 0) {
        throw Error("no voxel centre lies inside " + shape.describe() +
                    (dimensions == 2 ? " in the z = 0 layer" : ""));
    }
    return grid;
}

} // namespace vdbclay
