// Clay files (.vdb): written atomically, read with checks; and the other .vdb files vdbclay reads.
//
// A clay file holds three grids: "mass" (the exact Int32 clay, with the vdbclay_* metadata of
// ClayFileMeta.h, among them its largest cell, vdbclay_max_mass: the memory estimate reads it
// without the voxels, and a file whose voxels exceed it is refused on reading), "density" (m / Tc, a
// fog volume, with the same metadata for readers that load only FloatGrids) and "surface" (the level
// set where a cell is half full), the last two for other tools (Houdini, Blender, vdb_view) to look
// at; output/Surface.h derives both from the mass. The grids' transform is the clay's voxel size,
// rotated when the world's up axis is z. Every write goes to a temporary file beside the target that
// is renamed over it (core/AtomicFile.h).
//
// Every read opens the file through openChecked (VdbFile.h): its layout is checked byte by byte
// (core/VdbCheck.h) before OpenVDB reads it, grids are read in full, and a grid read as clay goes
// through the one definition of the clay in a file (normalizeClay). The folder: ClayFile.cc (clay
// files), Import.cc (fog volumes and level sets as clay), Describe.cc (describeVdb), VdbFile.cc (what
// the readers share). It stands on output/ (density and surface), shapes/ (level sets and makeClay,
// for import), metrics/ (describe) and core/.
#include "vdbclay/IO.h"

#include "core/AtomicFile.h"
#include "io/ClayFileMeta.h"
#include "io/VdbFile.h"
#include "output/Surface.h"

#include <openvdb/io/Archive.h>
#include <openvdb/io/File.h>
#include <openvdb/openvdb.h>

#include <tbb/blocked_range.h>
#include <tbb/parallel_reduce.h>

#include <algorithm>
#include <climits>
#include <cmath>
#include <ostream>
#include <sstream>
#include <utility>
#include <vector>

#ifndef VDBCLAY_VERSION
#define VDBCLAY_VERSION "unknown"
#endif

namespace vdbclay {

using namespace io_internal;

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

/// @a voxelSize world units per voxel, then for UpAxis::Z a rotation of +90 degrees about x (index
/// y becomes world z). @throw Error if voxelSize is not positive and finite.
openvdb::math::Transform::Ptr clayTransform(double voxelSize, UpAxis up)
{
    if (!(voxelSize > 0) || !std::isfinite(voxelSize)) {
        throw Error("the voxel size must be positive and finite");
    }
    if (up == UpAxis::Y) return openvdb::math::Transform::createLinearTransform(voxelSize);
    // Rx(+90 deg) exactly (no rounding in sin and cos): (x, y, z) -> (x, -z, y), then scaled.
    // OpenVDB maps row vectors (world = index * M): row i is the image of index axis i.
    const double v = voxelSize;
    return openvdb::math::Transform::createLinearTransform(
        openvdb::Mat4d(v, 0., 0., 0., /**/ 0., 0., v, 0., /**/ 0., -v, 0., 0., /**/ 0., 0., 0., 1.));
}

/// Whether the surface level set of clay of @a voxelSize world units per voxel is stored as half floats
/// (16 bits: OpenVDB converts them back to 32-bit floats on reading; Houdini, Blender and pyopenvdb read
/// them as any other FloatGrid). Its values lie within the band, +-3 voxels: for voxel sizes from 2^-10
/// to 2^14 world units each is read back within 2^-11 of its magnitude (within 2^-25 below 2^-14), under
/// 1/600 of a voxel, and the band's +-3 voxels stay finite (under 65504). Outside that range the
/// surface is stored as 32-bit floats.
bool surfaceSavedAsHalf(double voxelSize)
{
    return voxelSize >= std::ldexp(1.0, -10) && voxelSize <= std::ldexp(1.0, 14);
}

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

} // namespace

ClayGrids clayGridsOf(const std::vector<std::string>& names)
{
    if (names.empty()) throw Error("no grid named: expected at least one of mass, density, surface");
    ClayGrids g{false, false, false};
    for (const std::string& name : names) {
        bool* slot = name == "mass"      ? &g.mass
                     : name == "density" ? &g.density
                     : name == "surface" ? &g.surface
                                         : nullptr;
        if (!slot) throw Error("\"" + name + "\" is not a grid of a clay file (mass, density or surface)");
        if (*slot) throw Error("grid \"" + name + "\" is named twice");
        *slot = true;
    }
    return g;
}

ClayGrids parseClayGrids(const std::string& list)
{
    std::vector<std::string> names;
    for (size_t start = 0;;) {
        const size_t comma = list.find(',', start);
        names.push_back(list.substr(start, comma == std::string::npos ? std::string::npos : comma - start));
        if (comma == std::string::npos) break;
        start = comma + 1;
    }
    try {
        return clayGridsOf(names);
    } catch (const Error& e) {
        throw Error(e.what() + (names.size() > 1 ? " in \"" + list + "\"" : std::string()));
    }
}

std::string clayGridsName(const ClayGrids& grids)
{
    std::string out;
    for (const auto& [on, name] : {std::pair<bool, const char*>{grids.mass, "mass"},
                                   {grids.density, "density"},
                                   {grids.surface, "surface"}})
        if (on) out += (out.empty() ? "" : ",") + std::string(name);
    return out;
}

void writeClayFile(const std::string& path, const MassGrid& mass, const ClayMeta& meta,
                   const ClayGrids& grids)
{
    openvdb::initialize();
    validateMeta(meta, path);
    if (!grids.mass && !grids.density && !grids.surface) {
        throw Error("cannot write " + path + ": no grid named (mass, density or surface)");
    }

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
    if (meta.massAdded != 0) clayMeta.insertMeta(kMetaMassAdded, openvdb::Int64Metadata(meta.massAdded));
    if (meta.massRemoved != 0)
        clayMeta.insertMeta(kMetaMassRemoved, openvdb::Int64Metadata(meta.massRemoved));
    if (!meta.changedClay.empty()) {
        std::string boxes;
        for (const Box& b : meta.changedClay)
            for (const int32_t v : {b.min[0], b.min[1], b.min[2], b.max[0], b.max[1], b.max[2]})
                boxes += (boxes.empty() ? "" : " ") + std::to_string(v);
        clayMeta.insertMeta(kMetaChangedClay, openvdb::StringMetadata(boxes));
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

    const auto xform = clayTransform(meta.voxelSize, meta.up);
    // Shares the caller's tree (read only) with a fresh name, metadata and transform.
    openvdb::GridBase::ConstPtr massOut = mass.copyGridReplacingMetadataAndTransform(massMeta, xform);

    // The surface is swept from the density: built for either, kept for those named.
    openvdb::FloatGrid::Ptr density, surface;
    if (grids.density || grids.surface) {
        try {
            density = densityGrid(mass, meta.rule.threshold, meta.voxelSize);
            density->setTransform(xform->copy());
            if (grids.surface) {
                surface = surfaceLevelSet(*density, 0.5);
                surface->setSaveFloatAsHalf(surfaceSavedAsHalf(meta.voxelSize));
            }
        } catch (const Error& e) {
            throw Error("cannot write " + path + ": " + e.what());
        } catch (const std::exception& e) {
            throw Error("cannot write " + path + ": building the density and surface failed: " + reason(e));
        }
        if (!grids.density) density.reset(); // its memory back before the file is written
    }
    openvdb::FloatGrid* described = density ? density.get() : grids.mass ? nullptr : surface.get();
    if (described)
        for (auto it = clayMeta.beginMeta(); it != clayMeta.endMeta(); ++it)
            described->insertMeta(it->first, *it->second);

    openvdb::GridCPtrVec out;
    if (grids.mass) out.push_back(massOut);
    if (density) out.push_back(density);
    if (surface) out.push_back(surface);
    writeAtomically(path, [&](std::ostream& os) { StreamArchive().writeTo(os, out); });
}

ClayFile readClayFile(const std::string& path, const std::string& gridName)
{
    openvdb::initialize();
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
    if (readMeta<int64_t, openvdb::Int64Metadata>(g, kMetaMassAdded, i64, path, "int64")) {
        if (i64 < 0) throw Error(path + ": invalid vdbclay metadata: " + kMetaMassAdded + " is negative");
        m.massAdded = i64;
        any = true;
    }
    if (readMeta<int64_t, openvdb::Int64Metadata>(g, kMetaMassRemoved, i64, path, "int64")) {
        if (i64 < 0) throw Error(path + ": invalid vdbclay metadata: " + kMetaMassRemoved + " is negative");
        m.massRemoved = i64;
        any = true;
    }
    if (readMeta<std::string, openvdb::StringMetadata>(g, kMetaChangedClay, str, path, "string")) {
        // Six integers a box, each box inside one leaf slot.
        std::istringstream in(str);
        std::vector<int64_t> v;
        for (int64_t x = 0; in >> x;)
            v.push_back(x);
        const bool whole = in.eof() && v.size() % 6 == 0;
        for (size_t i = 0; whole && i < v.size(); i += 6) {
            Box b;
            bool ok = true;
            for (int a = 0; a < 3; ++a) {
                ok = ok && v[i + size_t(a)] >= INT32_MIN && v[i + 3 + size_t(a)] <= INT32_MAX &&
                     v[i + size_t(a)] <= v[i + 3 + size_t(a)] &&
                     (v[i + size_t(a)] >> 3) == (v[i + 3 + size_t(a)] >> 3);
                b.min[size_t(a)] = int32_t(v[i + size_t(a)]);
                b.max[size_t(a)] = int32_t(v[i + 3 + size_t(a)]);
            }
            if (!ok)
                throw Error(path + ": invalid vdbclay metadata: " + kMetaChangedClay +
                            " holds a box outside one leaf slot");
            m.changedClay.push_back(b);
        }
        if (!whole)
            throw Error(path + ": invalid vdbclay metadata: " + kMetaChangedClay +
                        " is not boxes of six integers");
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

void setClayTransform(MassGrid& mass, double voxelSize, UpAxis up)
{
    mass.setTransform(clayTransform(voxelSize, up));
}

} // namespace vdbclay
