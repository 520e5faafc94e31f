/// @file Push.h
/// @brief The paper's push operation: tools move clay out of the voxels they enter.
#pragma once

#include "vdbclay/Shapes.h"
#include "vdbclay/Types.h"

#include <cstdint>
#include <vector>

namespace vdbclay {

class Automaton;

/// What one push did.
struct PushReport {
    uint64_t voxelsPushed = 0; ///< clay voxels found inside a tool and emptied
    int64_t massMoved = 0;     ///< clay moved out of tools
    uint64_t voxelsTrapped = 0; ///< clay voxels inside a tool with no free voxel to go to
    int64_t massTrapped = 0;   ///< their clay, left where it was (conserved, reported)
    Box region;                ///< voxels the push read or wrote (empty when nothing moved)
};

/// Pushes the clay of every voxel whose centre lies inside one of @a tools along that tool's
/// normal into the nearest voxel outside every tool and not an obstacle of @a automaton: the
/// target is found by marching from the voxel along the normal past the surface (so a tool that
/// moved several voxels in one frame pushes clay all the way out), and, if that point is blocked,
/// by searching outward for the nearest free voxel within @a maxSearch voxels. Clay that finds no
/// free voxel stays where it is and is reported as trapped. Mass is conserved exactly. Only the
/// tools' bounds (plus the reach of the search) are visited. Goes through Automaton::edit(), so the
/// automaton wakes the touched region. Deterministic: voxels are processed in coordinate order.
/// Every clay voxel inside a tool is a source, even one that is an obstacle (a Sculptor marks the
/// tools' own voxels as obstacles while clay settles); clay in obstacles outside tools never moves.
/// Clay never passes through an obstacle: both the march and the search stop at obstacle voxels
/// that are not part of a tool.
/// @throw Error if @a maxSearch is outside [0, 1024] or a tool is null; nothing is changed then.
PushReport push(Automaton& automaton, const std::vector<ShapePtr>& tools, int maxSearch = 16);

} // namespace vdbclay
