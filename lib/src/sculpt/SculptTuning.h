// The Sculptor's tuning constants (Sculpt.cc) that the memory estimate (MemoryEstimate.cc) must follow:
// the sweep's sub-steps, the global layer's reach and the automaton's try before it; and growBox,
// which both use to grow the push's region by the reach.
#pragma once

#include "vdbclay/Types.h"

#include <algorithm>
#include <climits>
#include <cstdint>

namespace vdbclay {
namespace sculpt_internal {

/// Scene::sweep: at most this many sub-steps per frame.
constexpr int kMaxSweepSubsteps = 256;
/// Scene::transport global: the reach (plastic zone) in contact sizes of the push.
constexpr double kReachPerContact = 1.0;
/// Scene::transport global, the automaton's try before the layer (Sculptor::Impl::settleBounded).
/// Measured on the 48^3 press at 0.8 Tc (surface push): its frames need up to ~200 visited blocks
/// per block of the clay (~600 steps); with 256 and 4096 every frame settles in the try (as local);
/// with 64 or 128 two or three frames gave up and the layer made the run 2x slower. Mean density
/// (mass / (Tc x voxels with clay)) after each push: that press 0.817-0.920, the 64^3 press at Tc
/// (surface push) 0.968-0.995, which skips the try; the 0.95 Tc stroke 0.95.
constexpr uint64_t kTryChunk = 16;
constexpr uint64_t kTrySteps = 4096;
constexpr double kTryWork = 256;
constexpr double kTrySaturated = 0.96;

/// @a b grown by @a by voxels on every side (2D: x and y only), clamped to the int32 range.
inline Box growBox(Box b, int64_t by, int dims)
{
    if (b.empty()) return b;
    for (int a = 0; a < (dims == 2 ? 2 : 3); ++a) {
        b.min[a] = int32_t(std::max<int64_t>(INT32_MIN, int64_t(b.min[a]) - by));
        b.max[a] = int32_t(std::min<int64_t>(INT32_MAX, int64_t(b.max[a]) + by));
    }
    return b;
}

} // namespace sculpt_internal
} // namespace vdbclay
