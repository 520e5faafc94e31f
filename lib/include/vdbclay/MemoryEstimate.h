/// @file MemoryEstimate.h
/// @brief What a scene's run is expected to need, in bytes, before any grid is built, and the
///        budget check made with it.
#pragma once

#include "vdbclay/Fwd.h"
#include "vdbclay/MemoryBudget.h"
#include "vdbclay/Scene.h"

#include <cstdint>
#include <string>

namespace vdbclay {

/// What a scene's grids are expected to need, in bytes, before any of them is built
/// (estimateSceneMemory). Node sizes are OpenVDB's own (sizeof), plus allocator overhead.
struct MemoryEstimate {
    uint64_t clayLeaves = 0;      ///< 8^3 leaves of the initial clay (an upper bound: shapes' bounds)
    uint64_t clayLeavesGrown = 0; ///< leaves the clay may reach as it spreads (>= clayLeaves)
    uint64_t obstacleLeaves = 0;  ///< leaves of the obstacle masks (static obstacles)
    uint64_t toolVoxels = 0;      ///< voxels in the tools' bounds at once (the largest frame)
    uint64_t clayBytes = 0;       ///< the Int32 mass grid, grown: leaves + internal nodes
    uint64_t obstacleBytes = 0;   ///< two masks (static, and the automaton's copy with the tools)
    uint64_t toolBytes = 0;       ///< the tools' voxels as obstacle cells and push scratch
    uint64_t automatonBytes = 0;  ///< the automaton's per-leaf block masks and work lists
    uint64_t outputBytes = 0;     ///< writing the result: density and surface grids
    uint64_t transportBytes = 0;  ///< Scene::transport global: the solver's cells and vectors
    uint64_t transportCells = 0;  ///< Scene::transport global: the cells of its domain counted (a bound)
    uint64_t total() const;
    /// One line: "about 1.2 GiB (clay 800 MiB for up to 370000 leaves, obstacles ..., ...)".
    std::string describe() const;
};

/// Estimates the memory a run of @a scene needs, from the clay shapes' bounds (clay from .vdb
/// files and the start file: from the file's grid statistics, without reading the voxels), the
/// obstacles' bounds and the tools' bounds along their paths. Growth: clay may spread over the
/// bounding box of each cluster of clay and tool sweeps (boxes that touch are merged), grown by one
/// leaf on every side, and over no more leaves than it has units of mass.
/// @throw Error if a file the scene names cannot be read.
MemoryEstimate estimateSceneMemory(const Scene& scene);

/// What @a mass takes now by the measure estimateSceneMemory() uses for the clay: its tree, the
/// automaton's state for each of its leaves, and the output grids writing it would build. A run
/// compares this (plus the estimate's obstacle and tool bytes) with its budget as the clay grows.
uint64_t clayMemoryInUse(const MassGrid& mass);

/// @throw Error "SOURCE: needs about X ... more than the memory budget of Y ..." when
///        estimateSceneMemory(scene) exceeds the scene's budget (Scene::memoryBudget; 0: the
///        default). Does nothing when the budget is kNoMemoryBudget.
void checkMemoryBudget(const Scene& scene);

} // namespace vdbclay
