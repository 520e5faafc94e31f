// The memory estimate's part that the Sculptor uses (MemoryEstimate.cc): the budget check with an
// estimate already computed.
#pragma once

#include "vdbclay/Sculpt.h"

namespace vdbclay {

/// checkMemoryBudget(scene) with estimateSceneMemory(scene) at hand (Sculptor's constructor keeps it).
/// @throw Error as checkMemoryBudget(scene).
void checkMemoryBudget(const Scene& scene, const MemoryEstimate& e);

} // namespace vdbclay
