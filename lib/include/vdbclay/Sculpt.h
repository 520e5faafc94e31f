/// @file Sculpt.h
/// @brief Running a scene: each frame moves the tools, pushes clay out of them, then settles.
#pragma once

#include "vdbclay/Automaton.h"
#include "vdbclay/Metrics.h"
#include "vdbclay/Push.h"
#include "vdbclay/Scene.h"

#include <cstdint>
#include <functional>
#include <memory>

namespace vdbclay {

struct FrameReport {
    uint64_t frame = 0; ///< 1-based frame just run
    PushReport push;
    StepReport settle;
};

/// Totals of a run, as the CLI prints them and writes to --stats.
struct RunSummary {
    uint64_t frames = 0;
    uint64_t steps = 0;
    double seconds = 0;
    int64_t massInitial = 0;
    int64_t massFinal = 0;
    int64_t massDrift = 0;      ///< massFinal - massInitial: exactly 0 unless mass was lost or made
    int64_t residualOverload = 0;
    bool settled = false;       ///< the last frame settled
    uint64_t framesUnsettled = 0; ///< frames whose settling hit the step budget or had no room
    uint64_t framesNoRoom = 0;  ///< of those, frames stopped because the overload had no room (NoRoom)
    int64_t massTrapped = 0;    ///< clay inside a tool after the last push: it had nowhere to go
    uint64_t blocksVisited = 0, blocksUpdated = 0;
    double pushSeconds = 0;
    StageSeconds stages;
    /// The final clay measured by measureClay() with the automaton's obstacles (tools included).
    ClayMetrics metrics;
};

class Sculptor {
public:
    /// Builds the clay (or reads the scene's start file), rasterises obstacles, places the tools at
    /// the frame the start file reached (0 without one).
    /// @throw Error if clay overlaps an obstacle, masses overflow a cell, or a file is bad.
    Sculptor(const Scene& scene, int threads = 0);
    ~Sculptor();

    /// Runs the next frame. @throw Error if there is none left (done()).
    FrameReport runFrame();
    /// Runs up to @a maxFrames frames (all when 0), calling @a onFrame after each.
    RunSummary run(uint64_t maxFrames = 0, const std::function<void(const FrameReport&)>& onFrame = {});

    bool done() const;
    uint64_t frame() const;       ///< frames run so far (including those of the start file)
    uint64_t totalFrames() const;
    const Scene& scene() const;
    Automaton& automaton();
    const MassGridPtr& mass() const;

private:
    struct Impl;
    std::unique_ptr<Impl> mImpl;
};

} // namespace vdbclay
