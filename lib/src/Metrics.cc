#include "vdbclay/Metrics.h"

#include "RulesImpl.h"

#include <openvdb/openvdb.h>

#include <limits>
#include <string>

namespace vdbclay {

int64_t totalMass(const MassGrid& mass)
{
    int64_t sum = 0;
    for (auto it = mass.tree().cbeginValueAll(); it; ++it) {
        if (*it == 0) continue;
        // A tile of 4096^3 voxels holding 2^31 each is ~2^67: a file can ask for that.
        int64_t part = 0;
        if (__builtin_mul_overflow(int64_t(*it), int64_t(it.getVoxelCount()), &part) ||
            __builtin_add_overflow(sum, part, &sum)) {
            throw Error("totalMass: the total mass exceeds " +
                        std::to_string(std::numeric_limits<int64_t>::max()));
        }
    }
    return sum;
}

int64_t residualOverload(const MassGrid& mass, int32_t threshold, const ObstacleGrid* obstacles)
{
    int64_t sum = 0;
    openvdb::MaskGrid::ConstAccessor* oacc = nullptr;
    std::unique_ptr<openvdb::MaskGrid::ConstAccessor> holder;
    if (obstacles) {
        holder = std::make_unique<openvdb::MaskGrid::ConstAccessor>(obstacles->getConstAccessor());
        oacc = holder.get();
    }
    for (auto it = mass.tree().cbeginValueAll(); it; ++it) {
        if (*it <= threshold) continue;
        if (!it.isVoxelValue()) {
            throw Error("residualOverload: the grid holds an over-threshold tile; voxelize it first");
        }
        if (oacc && oacc->isValueOn(it.getCoord())) continue;
        sum += int64_t(*it) - threshold;
    }
    return sum;
}

uint64_t clayVoxelCount(const MassGrid& mass)
{
    uint64_t n = 0;
    for (auto it = mass.tree().cbeginValueAll(); it; ++it) {
        if (*it != 0) n += it.getVoxelCount();
    }
    return n;
}

uint64_t contentHash(const MassGrid& mass)
{
    // Order-independent: a sum of per-voxel hashes, so the tree's layout does not matter.
    uint64_t h = 0, count = 0;
    for (auto it = mass.tree().cbeginValueAll(); it; ++it) {
        if (*it == 0) continue;
        if (!it.isVoxelValue()) {
            throw Error("contentHash: the grid holds a nonzero tile; voxelize it first");
        }
        const openvdb::Coord c = it.getCoord();
        BlockKey k;
        k.x = c.x();
        k.y = c.y();
        k.z = c.z();
        k.step = uint64_t(uint32_t(*it));
        h += rules_internal::hashKey(k);
        ++count;
    }
    return rules_internal::mix64(h ^ rules_internal::mix64(count));
}

} // namespace vdbclay
