// The memory estimate's parts used inside the library and by its tests (MemoryEstimate.cc): the budget
// check with an estimate already computed, and the count of the global layer's domain bound.
#pragma once

#include "vdbclay/MemoryEstimate.h"

#include <cstdint>

namespace vdbclay {

/// checkMemoryBudget(scene) with estimateSceneMemory(scene) at hand (Sculptor's constructor keeps it).
/// @throw Error as checkMemoryBudget(scene).
void checkMemoryBudget(const Scene& scene, const MemoryEstimate& e);

namespace memory_internal {

/// Rows (x, y) voxelsWithinFaceSteps counts before it gives up: ~10 ms.
constexpr int64_t kFaceStepRowsMax = int64_t(1) << 23;

/// The voxels of @a within (2D, @a dims 2: of its z = 0 plane) at most @a r face steps from @a b
/// (the L1 distance to the box: an octahedron's corners, not a cube's), one z run per row (x, y); or
/// UINT64_MAX when that is more than kFaceStepRowsMax rows. The global layer's domain bound
/// (estimateSceneMemory).
uint64_t voxelsWithinFaceSteps(const Box& b, int64_t r, Box within, int dims);

} // namespace memory_internal
} // namespace vdbclay
