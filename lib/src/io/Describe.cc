// describeVdb: a description of any .vdb for `vdbclay info`, read with the checks of VdbFile.h.
// Grids of types whose trees core/VdbCheck.h cannot walk are listed, not read; Int32 grids get
// their total mass and content hash, and those that record Tc the accuracy metrics of Metrics.h.
#include "vdbclay/IO.h"

#include "vdbclay/Metrics.h"

#include "io/ClayFileMeta.h"
#include "io/VdbFile.h"

#include <openvdb/io/File.h>
#include <openvdb/openvdb.h>

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <memory>
#include <ostream>
#include <sstream>
#include <vector>

namespace vdbclay {

using namespace io_internal;

namespace {

/// Reads every grid of an open file, turning any failure into an Error naming the file.
openvdb::GridPtrVecPtr readAllGrids(openvdb::io::File& file, const std::string& path)
{
    try {
        return file.getGrids();
    } catch (const std::exception& e) {
        throw Error(damaged(path) + reason(e));
    }
}

/// For an Int32 grid that records Tc (vdbclay_threshold), the accuracy metrics of Metrics.h, in
/// the dimensions it records (3 without vdbclay_dimensions).
/// Tiles of clay (in voxels) up to which describeVdb hashes and measures a grid.
constexpr uint64_t kDescribeTileVoxelsMax = uint64_t(1) << 28;

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

} // namespace

std::string describeVdb(const std::string& path)
{
    openvdb::initialize();
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
            std::string value = it->second->str();
            if (it->first == kMetaChangedClay) { // six integers a box: their count, not thousands of them
                const size_t numbers = size_t(std::count(value.begin(), value.end(), ' ')) + !value.empty();
                value = std::to_string(numbers / 6) + " boxes";
            }
            s << indent << printableText(it->first) << " (" << printableText(it->second->typeName())
              << ") = " << printableText(value) << "\n";
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
              << "] .. [" << box.max().x() << ", " << box.max().y() << ", " << box.max().z()
              << "]\n"; // Where its voxels lie in the world: the faces of the outermost voxels (half a voxel
            // beyond the index bbox's voxel centres), through the grid's transform (any rotation).
            openvdb::Vec3d lo(HUGE_VAL), hi(-HUGE_VAL);
            for (int c = 0; c < 8; ++c) {
                const openvdb::Vec3d corner((c & 1 ? box.max().x() : box.min().x()) + (c & 1 ? 0.5 : -0.5),
                                            (c & 2 ? box.max().y() : box.min().y()) + (c & 2 ? 0.5 : -0.5),
                                            (c & 4 ? box.max().z() : box.min().z()) + (c & 4 ? 0.5 : -0.5));
                const openvdb::Vec3d w = g->transform().indexToWorld(corner);
                lo = openvdb::math::minComponent(lo, w);
                hi = openvdb::math::maxComponent(hi, w);
            }
            s << "  world bounds: [" << lo.x() << ", " << lo.y() << ", " << lo.z() << "] .. [" << hi.x()
              << ", " << hi.y() << ", " << hi.z() << "] (the outer faces of its voxels)\n";
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
                // The hash and the metrics walk a tile's voxels (or its faces): info stays quick on any
                // file by leaving them out for tiles of more than 2^28 voxels (run --stats hashes them).
                uint64_t tileVoxels = 0;
                auto tile = ig->tree().cbeginValueAll();
                tile.setMaxDepth(tile.getLeafDepth() - 1);
                for (; tile && tileVoxels <= kDescribeTileVoxelsMax; ++tile)
                    if (*tile != 0) tileVoxels += tile.getVoxelCount();
                if (tileVoxels > kDescribeTileVoxelsMax) {
                    s << "  content hash: none (the grid holds tiles of more than 2^28 voxels of clay; "
                         "`vdbclay run --stats` hashes them)\n";
                } else {
                    try {
                        const uint64_t h = contentHash(*ig);
                        char hash[32];
                        std::snprintf(hash, sizeof hash, "%016llx", (unsigned long long)h);
                        s << "  content hash: " << hash << " (equal hashes: equal clay, voxel for voxel)\n";
                    } catch (const Error& e) {
                        s << "  content hash: none (" << e.what() << ")\n";
                    }
                    describeClayMetrics(s, *ig, path);
                }
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

} // namespace vdbclay
