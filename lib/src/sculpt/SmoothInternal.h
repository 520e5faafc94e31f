// smoothRegion (vdbclay/Smooth.h) in its two halves, for a caller that smooths many regions at once
// (the scene's surface tension, sculpt/SurfaceTension.h). Computing a region's result
// (smoothedRegion) reads the automaton's masses and obstacles over the region grown by
// kShelterReach, and nothing else of it: regions may be computed concurrently while nothing writes
// the automaton. Writing the result (write) goes through Automaton::setMasses, which may add and
// prune leaves: one region at a time, with no computation running.
#pragma once

#include "vdbclay/Automaton.h"
#include "vdbclay/Smooth.h"

#include <vector>

namespace vdbclay {
namespace smooth_internal {

/// How far beyond its region a smoothing reads the masses and obstacles: the shelters' reach, in
/// x, y and z (2D: x and y). It writes inside its region only.
constexpr int kShelterReach = 2;

/// A region's smoothing, computed and not yet written.
struct Smoothed {
    SmoothReport report;                    ///< what smoothRegion reports once it is written
    std::vector<Automaton::CellMass> cells; ///< the voxels it changed, their new masses
};

/// What smoothRegion(@a automaton, @a region, @a strength, @a passes, @a solids) does, without
/// writing it: reads @a automaton only (file comment). @throw Error as smoothRegion.
Smoothed smoothedRegion(const Automaton& automaton, const Box& region, double strength, int passes,
                        const std::vector<ShapePtr>& solids);

/// Writes @a s into @a automaton through Automaton::setMasses over its region (nothing when nothing
/// moved): smoothRegion is smoothedRegion, then write.
void write(Automaton& automaton, const Smoothed& s);

} // namespace smooth_internal
} // namespace vdbclay
