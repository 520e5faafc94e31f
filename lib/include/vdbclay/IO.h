/// @file IO.h
/// @brief Clay files (.vdb): writing atomically, reading with checks; clay from other .vdb files
///        (fog volumes, level sets); a description of any .vdb.
///
/// Surface meshes are written by SurfaceMesh.h, pictures by Render.h, clay from a shape made by
/// makeClay() (Shapes.h).
#pragma once

#include "vdbclay/Fwd.h"
#include "vdbclay/Shapes.h"
#include "vdbclay/Types.h"

#include <array>
#include <cstdint>
#include <optional>
#include <string>
#include <vector>

namespace vdbclay {

// ---- Clay files ----------------------------------------------------------------------------------

/// What a clay file records beside the voxels (as grid metadata, names prefixed "vdbclay_").
struct ClayMeta {
    int dimensions = 3;
    RuleParams rule;
    uint64_t seed = 0;
    uint64_t steps = 0;  ///< automaton steps run so far
    uint64_t frames = 0; ///< scene frames run so far
    /// 0: written at a frame boundary. n > 0: a checkpoint written during frame frames + 1, after
    /// its push and n steps of its settling (Sculptor resumes the frame there). Stored only when > 0.
    uint64_t frameSteps = 0;
    double voxelSize = 1.0;
    /// The world's up axis: the grids' transform is voxelSize, rotated for UpAxis::Z (Shapes.h).
    /// Stored as vdbclay_up only when it is z.
    UpAxis up = UpAxis::Y;
    /// Clay that add tools deposited and remove tools took away in the frames run so far (a
    /// Sculptor resumes its counts from them). Stored only when not 0.
    int64_t massAdded = 0, massRemoved = 0;
    /// A checkpoint written inside a frame of a scene with "surface_tension": where the frame's clay
    /// has changed so far, one box per leaf slot (the bounds of its changed voxels, inside the slot),
    /// in slot order; the frame smooths there once it settles. Stored only when not empty
    /// (vdbclay_changed_clay: six integers a box, min then max).
    std::vector<Box> changedClay;
    std::string version; ///< vdbclay version that wrote it (filled by writeClayFile)
};

/// The grids a clay file holds (writeClayFile): any of the three, at least one.
struct ClayGrids {
    bool mass = true;    ///< Int32Grid "mass": the exact clay, what "start" and readClayFile read
    bool density = true; ///< FloatGrid "density": mass / Tc, a fog volume
    bool surface = true; ///< FloatGrid level set "surface": the clay surface at density 0.5
};
/// The grids @a names names, each of mass, density and surface.
/// @throw Error naming a name that is none of those or is given twice, or saying the list is empty.
ClayGrids clayGridsOf(const std::vector<std::string>& names);
/// Grid names separated by commas ("mass,surface"): clayGridsOf() of them, an error naming the list.
ClayGrids parseClayGrids(const std::string& list);
/// The grids' names in file order, separated by commas ("mass,density,surface").
std::string clayGridsName(const ClayGrids& grids);

/// Writes @a path holding the @a grids named: an Int32Grid "mass" (exact clay), a FloatGrid
/// "density" (mass / Tc, a fog volume) and a FloatGrid level set "surface" (the clay surface at
/// density 0.5), in that order, with @a meta as metadata on "mass" and "density" (on "surface" when
/// it is alone). Atomic: writes PATH.tmp-XXXX beside it, then renames, so an interrupted write never
/// leaves a half-written file; @a path may be the file the clay was read from.
/// @throw Error naming the path on any failure (unwritable directory, full disk, no grid named); then
///        nothing is left behind and an existing @a path is untouched.
void writeClayFile(const std::string& path, const MassGrid& mass, const ClayMeta& meta,
                   const ClayGrids& grids = ClayGrids());

/// A clay file read back.
struct ClayFile {
    MassGridPtr mass;
    ClayMeta meta;
    bool hasMeta = false; ///< false when the file carries no vdbclay metadata (meta then defaults)
};
/// Reads the Int32Grid @a gridName of @a path.
/// @throw Error naming the file if it is missing, unreadable, truncated, not a .vdb, lacks a grid
///        of that name, or the grid is not an Int32Grid, or holds negative mass.
ClayFile readClayFile(const std::string& path, const std::string& gridName = "mass");

/// Gives @a mass the transform a clay file records: @a voxelSize world units per voxel, rotated for
/// @a up (Shapes.h: UpAxis). writeSurfaceMesh() places its vertices through it.
/// @throw Error if voxelSize is not positive and finite.
void setClayTransform(MassGrid& mass, double voxelSize, UpAxis up);

// ---- Clay from other .vdb files ------------------------------------------------------------------

/// The fog volume `vdbclay import` reads from @a path: @a gridName when it names a FloatGrid fog
/// volume; with @a gridName empty, the first fog volume if the file holds no FloatGrid level set
/// (level sets come first). Empty: import reads a level set instead. With @a asDensity, any FloatGrid
/// that is not a level set counts as a fog volume (`vdbclay import --as density`): @a gridName, else
/// the first such grid.
/// @throw Error as readClayFile if the file is not a readable .vdb; if the grid import would read is
///        a FloatGrid of another class (unknown, staggered) and not @a asDensity (it says to ask for
///        density); with @a asDensity, if there is no such grid or @a gridName is not one.
std::string fogGridToImport(const std::string& path, const std::string& gridName, bool asDensity = false);

/// The box (min, max) of a mesh file's vertices, in its own world units and axes: what `vdbclay
/// import --resolution` divides into voxels. Reads the file as loadMesh() does (OBJ, STL, PLY).
/// @throw Error as loadMesh() for a file it cannot read.
std::array<Vec3, 2> meshFileBounds(const std::string& path, uint64_t memoryBudget = 0);

/// Clay from a fog volume: a float density per voxel (1 = a full cell).
struct FogClay {
    MassGridPtr mass;      ///< in the index space of the clay's transform (setClayTransform, set)
    double voxelSize = 1;  ///< the fog volume's own
    UpAxis up = UpAxis::Y; ///< z when the fog is vdbclay's own z-up density (its vdbclay_up or rotation)
    std::string note;      ///< one line for the user: the grid, its class and the rule applied
};
/// Reads the FloatGrid fog volume @a gridName of @a path as clay: each voxel (active voxels and
/// tiles) holds round(density x @a fullMass), voxel for voxel at its voxel size and where it lies in
/// the world: the fog's transform (translation, a rotation by quarter turns, vdbclay's own z-up
/// rotation) is kept, its voxels moved to the clay's index space (a translation that is not a whole
/// number of voxels is rounded to one, and the note says by how much). 2D: only the z = 0 layer.
/// Density above 1 is overfull clay. @a asDensity: any FloatGrid that is not a level set is read.
/// @a up: the clay's up axis (its index y along world z for UpAxis::Z); by default the fog's own.
/// @throw Error naming the file and grid if it is missing, not a FloatGrid fog volume, has
///        non-cubic voxels, a non-linear transform or one turning its axes other than by quarter
///        turns, a non-zero background, a negative or non-finite density, a cell that does not fit
///        an int32, or holds no clay.
FogClay readFogAsClay(const std::string& path, const std::string& gridName, int32_t fullMass,
                      int dimensions = 3, bool asDensity = false, std::optional<UpAxis> up = std::nullopt);

/// A clay file, or any other .vdb as clay (for `vdbclay render` and `mesh`): the Int32 grid "mass"
/// if there is one (readClayFile); else the first FloatGrid fog volume, density x Tc (default Tc,
/// the fog's own transform); else the first FloatGrid level set, as clay at its own voxel size
/// (makeClay with Tc per voxel). @a note says which grid was used when it is not "mass".
/// @throw Error naming the file if it holds none of these, or as readClayFile.
ClayFile readAsClay(const std::string& path, std::string& note);

// ---- Any .vdb ------------------------------------------------------------------------------------

/// A human-readable description of any .vdb: each grid's name, type, class, active voxel count,
/// index bounding box, voxel size, metadata, and for Int32 grids the total mass.
/// @throw Error as readClayFile.
std::string describeVdb(const std::string& path);

} // namespace vdbclay
