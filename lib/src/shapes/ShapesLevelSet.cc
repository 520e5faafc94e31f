// Level sets read from .vdb files as shapes (LevelSetShape.h samples them).
// Level sets and meshes sample an openvdb::FloatGrid (trilinear, BoxSampler) in world space.

#include "vdbclay/Shapes.h"

#include "shapes/LevelSetShape.h"
#include "core/InputFile.h"
#include "core/VdbCheck.h"

#include <openvdb/io/File.h>
#include <openvdb/openvdb.h>

#include <vector>

namespace vdbclay {

using namespace shapes_internal;

ShapePtr loadLevelSet(const std::string& path, double voxelSize, const std::string& gridName, UpAxis up)
{
    requireVoxelSize(voxelSize, "loadLevelSet(" + path + ")");
    io_internal::requireSeekableFile(path, "a level set .vdb");
    openvdb::initialize();
    // OpenVDB trusts the sizes a file records: check them first (VdbCheck.h).
    std::vector<io_internal::VdbGridLayout> layout;
    try {
        layout = io_internal::checkVdbLayout(path);
    } catch (const Error& e) {
        throw Error("cannot read level set from " + path + ": " + e.what());
    }
    // Only trees the check walked are read (a float level set always is).
    for (const auto& g : layout) {
        if (!gridName.empty() && g.baseName() == gridName && g.type != "Tree_float_5_4_3") {
            throw Error(path + ": grid \"" + gridName + "\" is not a FloatGrid level set (type " + g.type +
                        ")");
        }
    }
    openvdb::FloatGrid::Ptr grid;
    try {
        openvdb::io::File file(path);
        file.open(false);
        openvdb::GridBase::Ptr base;
        if (!gridName.empty()) {
            if (!file.hasGrid(gridName)) {
                throw Error(path + ": no grid named \"" + gridName + "\"");
            }
            base = file.readGrid(gridName);
            if (!isFloatLevelSet(*base)) {
                throw Error(path + ": grid \"" + gridName + "\" is not a FloatGrid level set (type " +
                            base->type() + ", class " +
                            openvdb::GridBase::gridClassToString(base->getGridClass()) + ")");
            }
        } else {
            openvdb::GridPtrVecPtr meta = file.readAllGridMetadata();
            for (const auto& g : *meta) {
                if (isFloatLevelSet(*g)) {
                    base = file.readGrid(g->getName());
                    break;
                }
            }
            if (!base) {
                throw Error(path + ": no FloatGrid level set among its " + std::to_string(meta->size()) +
                            " grid(s)");
            }
        }
        file.close();
        grid = openvdb::gridPtrCast<openvdb::FloatGrid>(base);
    } catch (const Error&) {
        throw;
    } catch (const std::exception& e) {
        throw Error("cannot read level set from " + path + ": " + e.what());
    }
    if (!grid) throw Error("cannot read level set from " + path);
    const std::string what = "level set \"" + grid->getName() + "\" from " + path;
    return std::make_shared<LevelSet>(grid, voxelSize, what, up);
}

} // namespace vdbclay
