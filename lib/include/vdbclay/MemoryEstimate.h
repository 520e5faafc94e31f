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

/// What a run of a scene is expected to need at its peak, in bytes, estimated before any grid is
/// built (estimateSceneMemory). Each part follows what the run allocates: OpenVDB's nodes (sizeof,
/// plus the allocator's overhead) and the arrays the automaton, the push, the global layer and the
/// output keep per leaf, per cell or per voxel. The parts that live through the whole run add up; the
/// push's scratch with the global layer's arrays (kept from frame to frame), and the output grids
/// (built after the last frame, when the layer's arrays are freed), do not overlap: the larger counts.
struct MemoryEstimate {
    uint64_t clayLeaves = 0;      ///< 8^3 leaves of the initial clay (an upper bound)
    uint64_t clayLeavesGrown = 0; ///< leaves the clay may reach as it spreads (>= clayLeaves)
    /// Voxels the clay may hold as it spreads, in leaves and in tiles (uniform clay inside a shape
    /// is tiles, not leaves): the global layer's domain over the whole body is at most these.
    uint64_t clayVoxels = 0;
    uint64_t anchorLeaves =
        0; ///< leaves within one leaf of those (the automaton's anchors, the surface band)
    uint64_t obstacleLeaves = 0; ///< leaves of the obstacle masks (static obstacles)
    uint64_t toolVoxels = 0;     ///< voxels in the tools' bounds at once (the largest frame)
    uint64_t toolSlots = 0;      ///< leaf slots of the tools' bounds at once, where their cells are marked
    uint64_t processBytes = 0;   ///< the program and its libraries, resident before any grid
    uint64_t clayBytes = 0;      ///< the Int32 mass grid, grown: leaves + internal nodes
    uint64_t obstacleBytes = 0;  ///< two masks (static, and the automaton's copy with the tools)
    uint64_t toolBytes = 0;      ///< the tools' cells as obstacles (a mask per leaf slot)
    uint64_t automatonBytes = 0; ///< the automaton's leaf table, candidates and work lists
    uint64_t pushBytes = 0;      ///< during a push: its sources, targets and plan (compress: its pools)
    uint64_t transportBytes = 0; ///< Scene::transport global: the layer's cells and vectors
    uint64_t transportCells = 0; ///< Scene::transport global: the cells of its domain counted (a bound)
    uint64_t outputBytes = 0;    ///< writing the result: the density and surface grids and their scratch
    /// processBytes + clayBytes + obstacleBytes + toolBytes + automatonBytes + the larger of
    /// (pushBytes + transportBytes) and outputBytes, saturating at UINT64_MAX (never wrapping
    /// below its parts).
    uint64_t total() const;
    /// One line: "about 1.2 GiB (program 40 MiB; clay 800 MiB for up to 370000 leaves ..., ...)".
    std::string describe() const;
};

/// Estimates the memory a run of @a scene needs, from the clay shapes (the leaves an analytic shape
/// can hold a voxel of, by its distance; other shapes' bounds; clay from .vdb files and the start
/// file: the file's grid statistics and topology, without reading the voxels), the obstacles'
/// bounds and the tools' bounds along their paths, under the frame policy the run follows
/// (lib/src/sculpt/FramePolicy.h). Growth: clay a tool pokes may spread a leaf around itself and
/// around the tool's sweep; clay a tool covers, clay over Tc and clay from files that may overflow,
/// over the bounding box of each cluster of clay and tool sweeps, grown by one leaf; never over
/// more leaves than it has units of mass.
/// @throw Error if a file the scene names cannot be read.
MemoryEstimate estimateSceneMemory(const Scene& scene);

/// What @a mass takes now by the measure estimateSceneMemory() uses for the clay: its tree, the
/// automaton's state for each of its leaves (compact clay: two anchors a leaf), and the output
/// grids writing it would build. A run compares this (plus the estimate's program, obstacle and
/// tool bytes) with its budget as the clay grows.
uint64_t clayMemoryInUse(const MassGrid& mass);

/// @throw Error "SOURCE: needs about X ... more than the memory budget of Y ..." when
///        estimateSceneMemory(scene) exceeds the scene's budget (Scene::memoryBudget; 0: the
///        default). Does nothing when the budget is kNoMemoryBudget.
void checkMemoryBudget(const Scene& scene);

} // namespace vdbclay
