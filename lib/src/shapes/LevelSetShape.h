/// @file LevelSetShape.h
/// @brief Private: a Shape sampling an openvdb::FloatGrid level set (level sets and meshes share it).
#pragma once

#include "shapes/ShapeMath.h"

#include <openvdb/openvdb.h>
#include <openvdb/tools/Interpolation.h>

namespace vdbclay {
namespace shapes_internal {

class LevelSet final : public Shape {
public:
    LevelSet(openvdb::FloatGrid::ConstPtr grid, double voxelSize, std::string what, UpAxis up = UpAxis::Y)
        : mGrid(std::move(grid)), mVoxelSize(voxelSize), mUp(up), mWhat(std::move(what)), mSampler(*mGrid)
    {
        // Everything inside the level set lies within its narrow band's active voxels (which enclose
        // the interior) or in inactive negative tiles. One voxel of margin covers interpolation.
        openvdb::CoordBBox bb = mGrid->evalActiveVoxelBoundingBox();
        if (!bb.empty()) bb.expand(1);
        const auto& tree = mGrid->tree();
        auto it = tree.cbeginValueOff();
        it.setMaxDepth(openvdb::FloatTree::ValueOffCIter::LEAF_DEPTH - 1);
        for (; it; ++it) {
            if (*it < 0) {
                openvdb::CoordBBox tb;
                it.getBoundingBox(tb);
                tb.expand(1);
                bb.expand(tb);
            }
        }
        if (bb.empty()) {
            mBounds = Box();
            return;
        }
        Vec3 lo{{1e300, 1e300, 1e300}}, hi{{-1e300, -1e300, -1e300}};
        for (int corner = 0; corner < 8; ++corner) {
            openvdb::Vec3d c;
            for (int i = 0; i < 3; ++i)
                c[i] = ((corner >> i) & 1) ? bb.max()[i] + 0.5 : bb.min()[i] - 0.5;
            const openvdb::Vec3d g = mGrid->indexToWorld(c);
            const Vec3 w = worldToIndex(Vec3{{g[0], g[1], g[2]}}, mVoxelSize, mUp);
            for (int i = 0; i < 3; ++i) {
                lo[i] = std::min(lo[i], w[i]);
                hi[i] = std::max(hi[i], w[i]);
            }
        }
        mBounds = boxOf(lo, hi, describe());
    }
    double distance(const Vec3& p) const override
    {
        const Vec3 w = indexToWorld(p, mVoxelSize, mUp);
        return double(mSampler.wsSample(openvdb::Vec3d(w[0], w[1], w[2]))) / mVoxelSize;
    }
    Box bounds() const override { return mBounds; }
    std::string describe() const override { return mWhat; }
    bool keepsVolume() const override { return true; }

private:
    openvdb::FloatGrid::ConstPtr mGrid;
    double mVoxelSize;
    UpAxis mUp;
    std::string mWhat;
    openvdb::tools::GridSampler<openvdb::FloatGrid, openvdb::tools::BoxSampler> mSampler;
    Box mBounds;
};

inline void requireVoxelSize(double voxelSize, const std::string& what)
{
    if (!std::isfinite(voxelSize) || !(voxelSize > 0.0)) {
        throw Error(what + ": voxelSize must be finite and > 0, got " + num(voxelSize));
    }
}

inline bool isFloatLevelSet(const openvdb::GridBase& g)
{
    return g.isType<openvdb::FloatGrid>() && g.getGridClass() == openvdb::GRID_LEVEL_SET;
}

} // namespace shapes_internal
} // namespace vdbclay
