/// @file Sculpt.h
/// @brief Running a scene: each frame moves the tools, pushes clay out of them, then settles.
#pragma once

#include "vdbclay/Automaton.h"
#include "vdbclay/IO.h"
#include "vdbclay/MemoryEstimate.h"
#include "vdbclay/Metrics.h"
#include "vdbclay/Push.h"
#include "vdbclay/Scene.h"
#include "vdbclay/Transport.h"

#include <cstdint>
#include <vector>
#include <functional>
#include <memory>
#include <string>

namespace vdbclay {

struct FrameReport {
    uint64_t frame = 0; ///< 1-based frame just run
    /// The tools' action this frame: what the push tools moved (and, when an add tool deposited
    /// clay, its region and contact size joined to region and contactSize: the global layer seeds
    /// there). A resumed open frame is past it: empty.
    PushReport push;
    int64_t massAdded = 0;   ///< clay the add tools deposited this frame
    int64_t massRemoved = 0; ///< clay the remove tools took away this frame
    /// Clay the smooth tools and the scene's surface tension moved this frame (Smooth.h).
    int64_t massSmoothed = 0;
    /// Scene "surface_tension": the boxes it smoothed at the frame's end, and the voxels it read
    /// into them (its work: it follows the surface the frame changed, the whole surface in the
    /// scene's first frame).
    uint64_t tensionBoxes = 0;
    uint64_t tensionVoxels = 0;
    double tensionSeconds = 0; ///< the scene's surface tension's wall time this frame (part of seconds)
    /// Scene::transport global: what the global layer did right after the push (once per frame; a
    /// resumed open frame does not repeat it).
    GlobalTransportReport transport;
    /// Scene::transport global: the steps the automaton ran before the global layer (its bounded
    /// try, docs/TRANSPORT.md; counted in settle too). The layer did not run when the try settled
    /// the frame. A resumed open frame is past its try and its layer: 0.
    uint64_t trySteps = 0;
    StepReport settle;
    /// false when a stop request (Sculptor::setStopRequest) cut the frame's settling short: the
    /// frame is still open, and the next runFrame() (or a Sculptor resumed from checkpointMeta())
    /// finishes it exactly as an unbroken run would have.
    bool finished = true;
    /// The frame's wall time: its push, global layer and settling, and collapsing its uniform leaves.
    double seconds = 0;
};

/// Totals of a run, as the CLI prints them and writes to --stats.
struct RunSummary {
    uint64_t frames = 0;
    uint64_t steps = 0;
    double seconds = 0;
    std::vector<double> frameSeconds; ///< each frame's wall time (FrameReport::seconds), in order
    int64_t massInitial = 0;
    int64_t massFinal = 0;
    int64_t massAdded = 0;   ///< clay the add tools deposited during this run
    int64_t massRemoved = 0; ///< clay the remove tools took away during this run
    /// massFinal - (massInitial + massAdded - massRemoved): exactly 0 unless mass was lost or made
    int64_t massDrift = 0;
    int64_t residualOverload = 0;
    bool settled = false;         ///< the last frame settled
    uint64_t framesUnsettled = 0; ///< frames whose settling hit the step budget or had no room
    uint64_t framesNoRoom = 0;    ///< of those, frames stopped because the overload had no room (NoRoom)
    int64_t massTrapped = 0;      ///< clay inside a tool after the last push: it had nowhere to go
    /// Candidate blocks examined (before any filter), of those with a cell over Tc, and updated.
    uint64_t blocksVisited = 0, blocksOverTc = 0, blocksUpdated = 0;
    double pushSeconds = 0;      ///< everything but the automaton's steps and the global transport
    double transportSeconds = 0; ///< of that, the global layer (Scene::transport global)
    uint64_t transportSolves = 0, transportIterations = 0;
    int64_t transportMassMoved = 0;
    uint64_t framesTransportNoRoom = 0; ///< frames whose global layer found walled-in clay
    /// Clay the smooth tools and the scene's surface tension moved (FrameReport::massSmoothed, summed).
    int64_t massSmoothed = 0;
    /// The scene's surface tension (FrameReport's figures, summed): of pushSeconds, its wall time; the
    /// boxes it smoothed and the voxels it read into them.
    double tensionSeconds = 0;
    uint64_t tensionBoxes = 0, tensionVoxels = 0;
    StageSeconds stages;
    /// The final clay measured by measureClay() with the automaton's obstacles (tools included).
    ClayMetrics metrics;
};

class Sculptor {
public:
    /// Checks the memory budget (checkMemoryBudget), builds the clay (or reads the scene's start
    /// file), rasterises obstacles, places the tools at the frame the start file reached (0
    /// without one). A start file written in the middle of a frame (ClayMeta::frameSteps > 0)
    /// reopens that frame: its tools are placed, its push is not repeated, and its settling goes on
    /// with the rest of its step budget.
    /// @throw Error if the budget is exceeded, clay overlaps an obstacle, masses overflow a cell, a
    ///        file is bad, or a mid-frame start file was written with another rule, Tc, alpha,
    ///        seed or dimensions than the scene's.
    Sculptor(const Scene& scene, int threads = 0);
    ~Sculptor();

    /// Runs the next frame, or finishes the open one. @throw Error if there is none left (done()).
    /// Returns early (report.finished false) when the stop request asks for it.
    FrameReport runFrame();
    /// Runs up to @a maxFrames frames (all when 0), calling @a onFrame after each. Returns early,
    /// with stopped() true, when the stop request asks for it.
    RunSummary run(uint64_t maxFrames = 0, const std::function<void(const FrameReport&)>& onFrame = {});

    /// Lets a caller stop a run early, e.g. on SIGINT: @a poll is called after every automaton step
    /// and between frames; once it returns true, runFrame() and run() return at the next point from
    /// which checkpointMeta() resumes exactly: after the current step if that step changed the clay
    /// (almost always), else after the next such step or at the next frame boundary. Pass an empty
    /// function to remove it. @a poll must be cheap (it runs between steps).
    void setStopRequest(std::function<bool()> poll);
    /// True when the last run() or runFrame() returned early on the stop request or the memory budget.
    bool stopped() const;
    /// The memory budget a run keeps as its clay grows: Scene::memoryBudget, defaultMemoryBudget()
    /// when that is 0, kNoMemoryBudget for none. Unless none, every 64th stop poll (the points
    /// setStopRequest names) measures the clay (clayMemoryInUse, plus the estimate's obstacles and
    /// tools), and run() and runFrame() stop as on a stop request once that exceeds the budget.
    uint64_t memoryBudget() const;
    /// When the memory budget stopped the last run() or runFrame(): what the run needed then
    /// (bytes); 0 otherwise (it ran on, or the stop request stopped it).
    uint64_t outgrewBudget() const;
    /// Metadata for writing the current state with writeClayFile() as a file a scene's "start"
    /// continues from exactly (same clay, same step count, same content hash as an unbroken run):
    /// the scene's rule, seed, dimensions and voxel size, the step count, the frames finished, and
    /// the steps already settled in an open frame.
    ClayMeta checkpointMeta() const;

    /// The metadata of the scene's start file (defaults when there is none or it has none).
    const ClayMeta& startMeta() const;
    /// Clay the add tools deposited (massAdded) and the remove tools took away (massRemoved) since
    /// the scene's frame 0: a start file's counts (ClayMeta) plus this Sculptor's frames. The clay's
    /// mass is always the initial clay's + massAdded() - massRemoved().
    int64_t massAdded() const;
    int64_t massRemoved() const;
    /// estimateSceneMemory(scene()): the constructor's, when it checked the budget (computed
    /// here otherwise), so a caller reporting it does not pay for a second estimate.
    const MemoryEstimate& memoryEstimate();

    bool done() const;
    uint64_t frame() const; ///< frames finished so far (including those of the start file)
    bool frameOpen() const; ///< a frame was cut short by a stop request and is not finished
    uint64_t totalFrames() const;
    const Scene& scene() const;
    /// The automaton the frames settle. While tools are placed, their voxels are obstacles where
    /// the clay can reach them (near the clay, extended as it spreads while runFrame() settles),
    /// not over the tools' whole bounds; step it through runFrame() rather than directly.
    Automaton& automaton();
    const MassGridPtr& mass() const;

private:
    struct Impl;
    std::unique_ptr<Impl> mImpl;
};

} // namespace vdbclay
