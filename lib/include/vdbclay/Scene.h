/// @file Scene.h
/// @brief Scene files: a JSON description of clay, tools with paths, obstacles and settling.
///
/// Coordinates are voxel indices, y is up, box bounds are inclusive. The format is documented in
/// docs/SCENES.md; parseScene() refuses anything else with one Error naming the file, the field
/// (as a path such as tools[0].path[1].frames) and what was expected.
#pragma once

#include "vdbclay/Deposit.h"
#include "vdbclay/IO.h"
#include "vdbclay/MemoryBudget.h"
#include "vdbclay/Push.h"
#include "vdbclay/Shapes.h"
#include "vdbclay/Transport.h"
#include "vdbclay/Types.h"

#include <cstdint>
#include <string>
#include <vector>

namespace vdbclay {

/// A shape as written in a scene, resolved to a ready-to-evaluate Shape.
struct ShapeSpec {
    std::string kind;  ///< sphere, box, cylinder, capsule, levelset, mesh, vdb
    std::string field; ///< where it came from, e.g. "clay[0]", for messages
    ShapePtr shape;    ///< null only for kind "vdb" (clay imported voxel for voxel)
    std::string file;  ///< levelset, mesh, vdb: the resolved path
    std::string grid;  ///< vdb: the Int32 grid to import (default "mass")
};

struct ClaySpec {
    ShapeSpec shape;
    int32_t mass = 0; ///< per voxel; 0 for kind "vdb" (the file's exact masses)
};

/// One segment of a tool's path: @a frames frames, each moving the tool by @a translate (voxels)
/// and rotating it by @a rotateDeg (degrees about x, y, z) around its current pivot.
struct PathSegment {
    Vec3 translate{{0, 0, 0}};
    Vec3 rotateDeg{{0, 0, 0}};
    uint64_t frames = 1;
};

struct ToolSpec {
    ShapeSpec shape;
    std::vector<PathSegment> path; ///< never empty
    /// "action": what the tool does to the clay it meets (default push).
    ToolAction action = ToolAction::Push;
    /// "mass" (add only): the clay a voxel wholly inside the tool is filled to; 0 (unset): Tc.
    int32_t mass = 0;
    /// "strength" (smooth only): in (0, 1], how far one frame's smoothing goes (Smooth.h).
    double strength = 0.5;
    Vec3 pivot{{0, 0, 0}}; ///< rotation centre at frame 0 (default: centre of the bounds)
    /// The tool's pose after @a frame frames (frame 0 = as written).
    Pose poseAt(uint64_t frame) const;
    uint64_t pathFrames() const;
};

struct SettleSpec {
    uint64_t maxSteps = 100000; ///< step budget per frame
    int64_t tolerance = 0;      ///< stop a frame's settling once residual overload <= tolerance
};

struct OutputSpec {
    std::string vdb, png, mesh, stats; ///< empty: not written
    ClayGrids grids;                   ///< the grids the .vdb holds ("grids": all three by default)
};

/// The voxel sizes (world units per voxel) a scene or import may use: OpenVDB refuses a transform
/// whose scale is near zero, and beyond these a world unit is no longer a useful measure.
constexpr double kMinVoxelSize = 1e-4;
constexpr double kMaxVoxelSize = 1e6;

struct Scene {
    std::string source; ///< the file (or "<built-in>") for messages
    int dimensions = 3;
    double voxelSize = 1.0;
    /// The world's up axis for files: meshes and level sets are read with it, and the output .vdb's
    /// transform (and --mesh) is rotated for it. Scene files: "up": "y" (default) or "z".
    UpAxis up = UpAxis::Y;
    RuleParams rule;
    uint64_t seed = 0;
    std::vector<ClaySpec> clay;
    std::vector<ToolSpec> tools;
    std::vector<ShapeSpec> obstacles;
    SettleSpec settle;
    /// "push": where a tool's push puts the clay it displaces (default: the paper's surface push).
    PushMode push = PushMode::Surface;
    /// "transport": how displaced clay travels (default: the paper's local automaton).
    Transport transport = Transport::Local;
    /// "sweep": the push acts on the volume each tool sweeps between two frames (the move split into
    /// sub-steps of at most a quarter voxel), so clay never passes through a thin or fast tool.
    bool sweep = false;
    /// "surface_tension": in [0, 1], 0 (the default) off. Each frame, once the clay has settled, one
    /// pass of surface tension (Smooth.h) of this strength runs over the surface: the whole surface in
    /// the scene's first frame, then the clay the frame changed grown by kSurfaceTensionMargin, so a
    /// later frame costs what the surface it changes costs, not the model (sculpt/SurfaceTension.h).
    double surfaceTension = 0;
    uint64_t frames = 0; ///< frames to run (default: the longest tool path)
    std::string start;   ///< a previous output .vdb to continue from (resolved path), or empty
    OutputSpec outputs;
    /// Bytes the run may need (estimateSceneMemory in MemoryEstimate.h); 0: defaultMemoryBudget();
    /// kNoMemoryBudget: unlimited. Scene files: "memory_budget": "8G" (or a byte count, or "none").
    uint64_t memoryBudget = 0;
};

/// Parses scene JSON. Relative file names inside the scene are resolved against @a baseDir.
/// @a memoryBudget, when not 0, replaces the scene's "memory_budget" (as `vdbclay run
/// --memory-budget` does; kNoMemoryBudget: none): meshes are voxelized as they are read, and are
/// checked against the budget that will hold for the run.
/// @throw Error "SOURCE: FIELD: what was wrong" on any malformed or inconsistent input.
Scene parseScene(const std::string& json, const std::string& source, const std::string& baseDir,
                 uint64_t memoryBudget = 0);
/// Reads and parses a scene file: a regular file, a pipe or FIFO with its writer (read whole), or
/// "-" for standard input (relative names in it then resolve against the current directory).
/// @throw Error as parseScene, or if the file cannot be read: missing, a directory, a FIFO that
///        nobody writes to (refused at once, never waited on), more than 16 MiB.
Scene loadScene(const std::string& path, uint64_t memoryBudget = 0);
/// The built-in default scene (the smallest complete example: a cube pressed by a plate).
Scene defaultScene();
/// The built-in default scene as JSON text.
const char* defaultSceneJson();

} // namespace vdbclay
