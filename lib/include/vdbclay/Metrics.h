/// @file Metrics.h
/// @brief Whole-grid measurements: total mass, overload, a content hash.
#pragma once

#include "vdbclay/Fwd.h"

#include <cstdint>

namespace vdbclay {

/// Sum of all voxel values (active or not), in 64 bits.
/// @throw Error if it does not fit (a grid read from a damaged file can hold such tiles).
int64_t totalMass(const MassGrid& mass);

/// Sum over cells not in @a obstacles (may be null) of max(0, m - threshold).
int64_t residualOverload(const MassGrid& mass, int32_t threshold, const ObstacleGrid* obstacles);

/// Number of voxels holding nonzero mass.
uint64_t clayVoxelCount(const MassGrid& mass);

/// A 64-bit hash of the grid's content: every nonzero voxel's coordinate and value. Two grids with
/// the same nonzero voxels hash alike whatever their tree layout or active states.
uint64_t contentHash(const MassGrid& mass);

} // namespace vdbclay
