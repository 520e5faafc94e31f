/// @file Smooth.h
/// @brief Surface tension: clay moves along its surface from convex places to concave ones, with
///        integer masses conserved exactly (a "smooth" tool; docs/SCENES.md).
///
/// The model. The shelters read the clay's solid shape: a voxel holding at least Tc/2 is full (Tc),
/// one holding less empty, an obstacle half full (clay meets walls and tools at about a right
/// angle). A voxel's shelter G is the sum of these fills over its 5^3 neighbourhood (5^2 in 2D)
/// weighted by the tent (1 2 3 2 1) along each axis, its own left out: high in a hollow, low on a
/// bump, a measure of the surface's curvature two voxels wide. Clay under Tc/2 (a film on a face,
/// coverage-weighted clay outside the solid shape) shelters nothing, so it neither gathers into
/// lumps nor makes the face under it look concave. A pass has two steps, each a descent of the
/// weighted count of broken bonds.
///
/// The threshold step moves whole voxels of the surface (a threshold dynamics after Merriman, Bence
/// and Osher, the volume held): the surface's voxels holding at least Tc/2 (and at most Tc) that
/// are more convex than a flat face (G below a flat face's inner voxel's), least sheltered first,
/// then the surface's voxels under Tc/2 holding clay that are more convex than a flat face (G below
/// a flat face's outer voxel's), least sheltered first, each give their clay to the most sheltered
/// voxel under Tc/2 within 4 voxels along each axis that lies on the surface, is more concave than
/// a flat face (G above a flat face's outer voxel's), is of the same connected part of the region
/// (face neighbours; obstacles, solids and the region's edge part them), has not received yet this
/// step, and is more sheltered than the giver once the giver's own fill is taken out of its
/// shelter (a move that only rolls a bump or a step over its own foot is not made). The receiver
/// takes min(giver's clay, Tc - its clay). A giver holding at least Tc/2 leaves one of the two at
/// or over Tc/2 and the other under it, so the volume (voxels at or over Tc/2) is kept; a film's
/// clay fills the creases near it. Bumps and terraces of full cells move into the creases beside
/// them. The step does not depend on the strength.
///
/// The exchange step then lets clay flow between face neighbours from the less sheltered to the
/// more sheltered voxel: a voxel on a convex bump gives, a voxel in a concave crease receives, and
/// a flat surface does not move. A pair moves
///   t = floor(strength x (G(to) - G(from)) / (2 x the face weight)),
/// (face weight 18 in 3D, 6 in 2D), at most what the giver holds and the room (Tc - mass) the
/// receiver has left, so no voxel is made overloaded; the receiver must lie on the clay's surface
/// (a face neighbour under Tc/2, not an obstacle), so clay under Tc inside is not packed. The solid
/// shape grows only where it is concave and shrinks only where it is convex: a receiver under Tc/2
/// that is not more concave than a flat face stays under Tc/2, a giver at or over Tc/2 that is not
/// more convex than a flat face stays at or over it.
///
/// What it does not do: a step of full cells one voxel high on a flat face is as sheltered on its
/// two sides and stays; a voxel's clay goes at most 4 voxels a pass; a film under Tc/2 on a flat
/// face stays where it is (docs/SCENES.md gives figures).
///
/// The threshold step runs once a pass, on the shelters at the pass's start. The exchange visits
/// the pairs along x, then y, then z (3D), each axis in two sub-passes (pairs whose lower voxel has
/// an even, then an odd coordinate along it), so the pairs of a sub-pass are disjoint; each sub-pass
/// reads the shelters of the masses at its start. Everything is integer and in a fixed order: the
/// result does not depend on the thread count.
///
/// The scene's "surface_tension" runs smoothRegion over boxes that cover the surface a frame
/// changed (the whole surface in the scene's first frame): lib/src/sculpt/SurfaceTension.h.
#pragma once

#include "vdbclay/Fwd.h"
#include "vdbclay/Shapes.h"
#include "vdbclay/Types.h"

#include <cstdint>
#include <vector>

namespace vdbclay {

class Automaton;

/// What one smooth() did.
struct SmoothReport {
    int64_t massMoved = 0; ///< clay moved from one voxel to another (each unit once)
    uint64_t voxels = 0;   ///< voxels whose mass changed
    Box region;            ///< the voxels changed (their bounds; empty when nothing moved)
    uint64_t visited = 0;  ///< voxels read (the region grown by the shelters' reach): the work
};

/// Strength bounds: a tool's "strength" lies in (0, kMaxSmoothStrength].
constexpr double kMaxSmoothStrength = 1.0;
/// A scene's "surface_tension" smooths the voxels a frame changed grown by this many voxels (the
/// threshold step's reach; lib/src/sculpt/SurfaceTension.h).
constexpr int kSurfaceTensionMargin = 4;

/// Runs @a passes passes of surface tension (file comment) on the voxels whose centre lies inside
/// @a tool and that are neither obstacles of @a automaton nor inside one of @a solids. Only those
/// voxels change (no margin); their shelters read two voxels beyond. Writes the changed voxels
/// through Automaton::setMasses (nothing when nothing moved). Work: (the tool's bounds + 4)^3 x
/// (15 + 7 x passes), plus a pass's givers' 9^3 neighbourhoods and 5^3 for each voxel changed.
/// @throw Error if @a strength is outside (0, 1] or @a passes < 1; nothing is changed then.
SmoothReport smooth(Automaton& automaton, const Shape& tool, double strength, int passes = 1,
                    const std::vector<ShapePtr>& solids = {});

/// The same over every voxel of @a region that is neither an obstacle nor inside one of @a solids
/// (the scene's surface tension).
SmoothReport smoothRegion(Automaton& automaton, const Box& region, double strength, int passes = 1,
                          const std::vector<ShapePtr>& solids = {});

/// The roughness measure smoothing lowers: the weighted count of broken bonds (a 3^3 stencil) over the voxels
/// of
/// @a region (3D: Σ over each voxel v and neighbour u of weight(u - v) x fill(v) x (Tc - fill(u))
/// / Tc, the weights above; a neighbour without clay, an obstacle too, reads as empty), i.e. a weighted
/// surface area in units of Tc (a flat face of one full voxel to empty space: 6 x 1 + 4 x 3 + 4 x 2 = 26). A
/// smooth surface has the least for its volume; bumps, terraces and pits add to it. @a dimensions 2: in the
/// z = 0 layer with the 2D weights. Exact (integers, in units of 1/Tc).
int64_t surfaceEnergy(const MassGrid& mass, const Box& region, int32_t threshold, int dimensions = 3);

} // namespace vdbclay
