/// @file Push.h
/// @brief The paper's push operation: tools move clay out of the voxels they enter.
#pragma once

#include "vdbclay/Shapes.h"
#include "vdbclay/Types.h"

#include <cstdint>
#include <string>
#include <vector>

namespace vdbclay {

class Automaton;

/// What one push did.
struct PushReport {
    uint64_t voxelsPushed = 0;  ///< clay voxels found inside a tool and emptied
    int64_t massMoved = 0;      ///< clay moved out of tools
    uint64_t voxelsTrapped = 0; ///< clay voxels inside a tool with no free voxel to go to
    int64_t massTrapped = 0;    ///< their clay, left where it was (conserved, reported)
    Box region;                 ///< voxels the push read or wrote (empty when nothing moved)
    /// The largest tool contact this push saw, about the width of the contact: sqrt of the voxels one
    /// tool entered (3D), or their number (2D), at most sqrt of the largest face of their bounds (3D)
    /// or its longest side (2D), so a deep dip counts as wide as the tool. 0 when no tool entered
    /// clay. The compress
    /// push limits its depth to it (unless the tool covers the clay); the global transport limits its
    /// reach to a multiple of it.
    double contactSize = 0;
    uint64_t voxelsCompressed = 0; ///< compress: sources spread over the clay ahead (not surface-pushed)
};

/// Where a push puts the clay of a voxel a tool enters.
enum class PushMode {
    /// The paper's push: into the nearest free voxel just past the tool's surface, along its normal.
    Surface,
    /// A compressing push: spread evenly over the contiguous clay (m >= 0.3 Tc; thinner clay is a film,
    /// pushed to the surface) ahead of the tool along its normal. A tool with clay beside it (a small tool
    /// in a large block) goes at most its contact size deep, each entered voxel's clay down its own
    /// column (a local rim); a tool that covers the clay it entered (a plate wider than the clay)
    /// compresses every column under it all the way, its clay shared evenly over all of them
    /// (uniform compression, straight sides). Remainders go +1 to the voxels nearest the tool. With no
    /// such voxel just past the surface, the surface push.
    Compress
};
const char* pushModeName(PushMode mode);
/// "surface" or "compress". @throw Error naming @a name otherwise.
PushMode parsePushMode(const std::string& name);

struct PushOptions {
    PushMode mode = PushMode::Surface;
    /// How far (voxels, Chebyshev) a target may lie from its source, in [0, 1024].
    int maxSearch = 16;
    /// Tc, for the compress push's full test (read from the automaton when 0).
    int32_t threshold = 0;
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
/// @throw Error if @a maxSearch is outside [0, 1024] or a tool is null, or (compress, a tool covering
/// the clay) a voxel would exceed INT32_MAX; nothing is changed then.
PushReport push(Automaton& automaton, const std::vector<ShapePtr>& tools, int maxSearch = 16);
/// The same, with the push mode chosen (PushMode::Surface gives exactly the push above).
PushReport push(Automaton& automaton, const std::vector<ShapePtr>& tools, const PushOptions& options);

} // namespace vdbclay
