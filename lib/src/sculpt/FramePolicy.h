// The frame policy: every decision a Sculptor takes for a frame from the scene (and, where it needs
// one, the frame's push report), each in one function here. The Sculptor (Sculpt.cc) runs them and the
// memory estimate (MemoryEstimate.cc) bounds what they can lead to by calling the same functions, so a
// change of policy here changes both. No OpenVDB: plain values in, a decision out.
//
// A frame (Sculptor::runFrame):
// 1. The push, split into sweepSubsteps() sub-steps with Scene::sweep; placing the tools marks their
//    cells as obstacles near the clay, or over their whole bounds (toolCellsOverWholeBounds()).
// 2. With the global transport (usesGlobalLayer(), layerRuns()): first the automaton's bounded try
//    (tryAfterPush(), trySaturated(), tryWork(), tryChunkEnd(), tryGivesUp()) on the clay near the
//    push (tryNear()); if it did not end the frame, the global layer with layerOptions(): its seeds
//    in the push's region, its reach from the contact size (layerReach()).
// 3. The automaton settles the rest within the scene's step budget.
#pragma once

#include "vdbclay/Push.h"
#include "vdbclay/Scene.h"
#include "vdbclay/Transport.h"
#include "vdbclay/Types.h"

#include <cstdint>

namespace vdbclay {
namespace frame_policy {

/// Scene::sweep: at most this many sub-steps per frame.
constexpr int kMaxSweepSubsteps = 256;
/// The global layer's reach (its plastic zone) in contact sizes of the push.
constexpr double kReachPerContact = 1.0;
/// The automaton's try before the global layer: chunks of kTryChunk steps, given up at kTrySteps
/// steps or once the blocks it visited pass kTryWork per 2x2x2 block (2x2 in 2D) of the clay near
/// the push; skipped where that clay's mean density (mass / (Tc x voxels with clay)) is at least
/// kTrySaturated. Measured on the 48^3 press at 0.8 Tc (surface push): its frames need up to ~200
/// visited blocks per block of the clay (~600 steps); with 256 and 4096 every frame settles in the try
/// (as local); with 64 or 128 two or three frames gave up and the layer made the run 2x slower. Mean
/// densities after each push: that press 0.817-0.920, the 64^3 press at Tc (surface push)
/// 0.968-0.995, which skips the try; the 0.95 Tc stroke 0.95.
constexpr uint64_t kTryChunk = 16;
constexpr uint64_t kTrySteps = 4096;
constexpr double kTryWork = 256;
constexpr double kTrySaturated = 0.96;

/// Whether the scene moves displaced clay with the global layer (Scene::transport global): the one
/// place the Sculptor and the estimate read Scene::transport.
bool usesGlobalLayer(const Scene& scene);

/// Whether the global layer runs after frame @a frame's push @a push (1-based): when the scene uses
/// it and a tool touched clay (push.contactSize > 0), or on the scene's first frame (clay that
/// starts over Tc). A frame whose tools touch no clay later leaves what an unsettled frame left to
/// the automaton, as with the local transport. By the scene's frame number, so a run resumed from a
/// checkpoint does what the unbroken run did.
bool layerRuns(const Scene& scene, uint64_t frame, const PushReport& push);

/// The layer's reach (face steps) for a push of contact size @a contactSize: ceil(kReachPerContact x
/// contact) + 2; 0 (the whole body) when no tool touched clay.
int64_t layerReach(double contactSize);

/// The global layer's options after @a push, on @a threads: the reach (layerReach()), and the seeds
/// in the push's region when a tool touched clay (the overload the push made lies there: a frame costs
/// the tool's region, not the model's size); every over cell otherwise. The overload the try carried
/// out of that region is left to the automaton's cleanup: the try runs only where the clay within
/// the reach is unsaturated, where the automaton settles overload cheaply, and seeds that far would
/// make the layer (and the estimate's bound of it) cover thousands of voxels around the tool.
GlobalTransportOptions layerOptions(const PushReport& push, int threads);

/// The face steps within which an over cell the layer moves finds room, after a try of @a trySteps
/// steps: a tool entering the clay from its surface has room around it within its extent (the
/// largest tool's diagonal, toolExtent(): around the tool to where it sticks out, or to the cells
/// it left), and each step of the try moves clay a voxel (three face steps) further, the layer's
/// seeds staying in the push's region (maxSearch + 2 voxels past the tool) whatever the try's steps
/// (GlobalTransportOptions::roomWithin; the memory estimate's bound of the layer's domain).
int64_t roomWithin(const Scene& scene, uint64_t trySteps);
/// The diagonal of @a bounds' voxels (their outer faces), rounded up: no pose of a shape with these
/// bounds is wider along any line.
int64_t diagonalOf(const Box& bounds);
/// The largest diagonalOf() a tool's shape's bounds: any pose's extent.
int64_t toolExtent(const Scene& scene);

/// The clay whose density decides the try (the push's region grown by the reach: the plastic zone),
/// or an empty box for the whole body (no tool touched clay).
Box tryNear(const GlobalTransportOptions& layer);

/// Whether the try runs at all: after a surface push only. The compress push leaves overload only where
/// the clay ahead of the tool had no room, and global + compress is the setting for clay at Tc: its
/// results are those of the layer alone.
bool tryAfterPush(const Scene& scene);
/// Whether clay holding @a clay units over @a voxels voxels is saturated on average
/// (kTrySaturated): saturated clay has room only at its surface, where the automaton's random walk
/// would not settle it, so the try is skipped.
bool trySaturated(const Scene& scene, int64_t clay, uint64_t voxels);
/// The blocks the try may visit on clay of @a voxels voxels: kTryWork per 2x2x2 block (2x2 in 2D),
/// about what the global layer costs a frame on it.
double tryWork(const Scene& scene, uint64_t voxels);
/// The frame step the try's next chunk ends at, @a frameSteps steps into the frame: kTryChunk
/// further, within the scene's step budget.
uint64_t tryChunkEnd(const Scene& scene, uint64_t frameSteps);
/// Whether the try gives up (the layer runs on what is left) after a chunk that did not end the frame,
/// at @a frameSteps steps into it, having visited @a blocksVisited blocks of at most @a work.
bool tryGivesUp(uint64_t frameSteps, uint64_t blocksVisited, double work);
/// The most steps the try can have run when the global layer runs after it, under a step budget of
/// @a maxSteps per frame: its chunks end at multiples of kTryChunk (tryChunkEnd()), it gives up at the
/// first one at or past kTrySteps, and a chunk that reaches @a maxSteps ends the frame without the
/// layer. So none when @a maxSteps <= kTryChunk.
uint64_t tryStepsBeforeLayer(uint64_t maxSteps);

/// The push's sub-steps for frame @a frame (1-based): 1, or with Scene::sweep the most a corner of any
/// tool's bounds moves from frame - 1 to frame, in quarter voxels (at most kMaxSweepSubsteps).
int sweepSubsteps(const Scene& scene, uint64_t frame);

/// Whether placing the tools marks their cells over their whole bounds, rather than only where the
/// clay can reach them: with the global layer, which moves clay far in one call.
bool toolCellsOverWholeBounds(const Scene& scene);

/// @a b grown by @a by voxels on every side (2D, @a dims 2: x and y only), clamped to the int32
/// range: the layer's plastic zone around the push's region, and the estimate's boxes.
Box growBox(Box b, int64_t by, int dims);

} // namespace frame_policy
} // namespace vdbclay
