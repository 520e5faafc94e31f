// The frame policy (FramePolicy.h): the Sculptor's per-frame decisions, shared with the memory estimate.
#include "sculpt/FramePolicy.h"

#include <algorithm>
#include <climits>
#include <cmath>

namespace vdbclay {
namespace frame_policy {

bool usesGlobalLayer(const Scene& scene)
{
    return scene.transport == Transport::Global;
}

bool layerRuns(const Scene& scene, uint64_t frame, const PushReport& push)
{
    return usesGlobalLayer(scene) && (push.contactSize > 0 || frame == 1);
}

int64_t layerReach(double contactSize)
{
    return contactSize > 0 ? int64_t(std::ceil(kReachPerContact * contactSize)) + 2 : 0;
}

GlobalTransportOptions layerOptions(const PushReport& push, int threads)
{
    GlobalTransportOptions go;
    go.threads = threads;
    go.reach = layerReach(push.contactSize);
    if (push.contactSize > 0) go.seedRegion = push.region;
    return go;
}

int64_t diagonalOf(const Box& bounds)
{
    if (bounds.empty()) return 0;
    double d2 = 0;
    for (int a = 0; a < 3; ++a) {
        const double side = double(int64_t(bounds.max[a]) - bounds.min[a] + 1);
        d2 += side * side;
    }
    return int64_t(std::ceil(std::sqrt(d2)));
}

int64_t toolExtent(const Scene& scene)
{
    int64_t most = 0;
    for (const ToolSpec& t : scene.tools)
        most = std::max(most, diagonalOf(t.shape.shape->bounds()));
    return most;
}

int64_t roomWithin(const Scene& scene, uint64_t trySteps)
{
    // The layer's seeds lie in the push's region, within maxSearch + 2 of the tool, whatever the try did.
    const uint64_t steps = std::min<uint64_t>(trySteps, uint64_t(PushOptions().maxSearch) + 2);
    return toolExtent(scene) + 3 * int64_t(steps);
}

Box tryNear(const GlobalTransportOptions& layer)
{
    return layer.reach > 0 ? growBox(layer.seedRegion, layer.reach, 3) : Box();
}

bool tryAfterPush(const Scene& scene)
{
    return scene.push == PushMode::Surface;
}

bool trySaturated(const Scene& scene, int64_t clay, uint64_t voxels)
{
    return double(clay) >= kTrySaturated * double(scene.rule.threshold) * double(voxels);
}

double tryWork(const Scene& scene, uint64_t voxels)
{
    return kTryWork * double(voxels) / (scene.dimensions == 2 ? 4.0 : 8.0);
}

uint64_t tryChunkEnd(const Scene& scene, uint64_t frameSteps)
{
    return std::min<uint64_t>(scene.settle.maxSteps, frameSteps + kTryChunk);
}

bool tryGivesUp(uint64_t frameSteps, uint64_t blocksVisited, double work)
{
    return frameSteps >= kTrySteps || double(blocksVisited) > work;
}

uint64_t tryStepsBeforeLayer(uint64_t maxSteps)
{
    if (maxSteps == 0) return 0;
    const uint64_t giveUp = (kTrySteps + kTryChunk - 1) / kTryChunk * kTryChunk;
    return std::min(giveUp, (maxSteps - 1) / kTryChunk * kTryChunk);
}

int sweepSubsteps(const Scene& scene, uint64_t frame)
{
    if (!scene.sweep || frame == 0) return 1;
    double most = 0;
    for (const ToolSpec& t : scene.tools) {
        const Pose a = t.poseAt(frame - 1), b = t.poseAt(frame);
        const Box bb = t.shape.shape->bounds();
        if (bb.empty()) continue;
        for (int corner = 0; corner < 8; ++corner) {
            const Vec3 p{{double(corner & 1 ? bb.max[0] : bb.min[0]),
                          double(corner & 2 ? bb.max[1] : bb.min[1]),
                          double(corner & 4 ? bb.max[2] : bb.min[2])}};
            const Vec3 pa = a.apply(p), pb = b.apply(p);
            const double d = std::sqrt((pa[0] - pb[0]) * (pa[0] - pb[0]) + (pa[1] - pb[1]) * (pa[1] - pb[1]) +
                                       (pa[2] - pb[2]) * (pa[2] - pb[2]));
            most = std::max(most, d);
        }
    }
    const int substeps = int(std::min(std::ceil(most * 4), double(kMaxSweepSubsteps)));
    return std::max(substeps, 1);
}

bool toolCellsOverWholeBounds(const Scene& scene)
{
    return usesGlobalLayer(scene);
}

Box growBox(Box b, int64_t by, int dims)
{
    if (b.empty()) return b;
    for (int a = 0; a < (dims == 2 ? 2 : 3); ++a) {
        b.min[a] = int32_t(std::max<int64_t>(INT32_MIN, int64_t(b.min[a]) - by));
        b.max[a] = int32_t(std::min<int64_t>(INT32_MAX, int64_t(b.max[a]) + by));
    }
    return b;
}

} // namespace frame_policy
} // namespace vdbclay
