/// @file Metrics.h
/// @brief Whole-grid measurements: total mass, overload, a content hash; the accuracy metrics of a
///        clay state (density heterogeneity, compaction) and the shape error against a reference.
///
/// Definitions used throughout (3D: the 6 face neighbours; 2D, clay in z = 0: the 4 in xy):
/// - A cell *holds clay* when its mass is > 0.
/// - A cell is *occupied* when its density m / Tc is >= 0.5, i.e. 2 m >= Tc: the inside of the
///   surface that writeSurfaceMesh(), writeClayFile()'s "surface" grid and renderPng() draw at
///   isovalue 0.5 (volumeToMesh puts a fog value >= the isovalue inside).
/// - An *interior cell* holds clay, is not an obstacle, and all of its face neighbours hold clay.
///   The surface layer (cells next to empty space or obstacles) is left out, so the heterogeneity
///   below measures the inside of the object, as the paper's figures 3.2 and 4.2 show it.
/// - A *surface voxel* of an occupied set is an occupied voxel with at least one face neighbour
///   that is not occupied.
/// Their sums are exact integers (or taken in the grid's coordinate order): the same grid gives the
/// same numbers whatever its tree layout, and measureClay the same on any thread count.
#pragma once

#include "vdbclay/Fwd.h"

#include <cstdint>

namespace vdbclay {

class Shape;

/// Sum of all voxel values (active or not), in 64 bits.
/// @throw Error if it does not fit (a grid read from a damaged file can hold such tiles).
int64_t totalMass(const MassGrid& mass);

/// Sum over cells not in @a obstacles (may be null) of max(0, m - threshold).
int64_t residualOverload(const MassGrid& mass, int32_t threshold, const ObstacleGrid* obstacles);

/// Number of voxels holding nonzero mass.
uint64_t clayVoxelCount(const MassGrid& mass);

/// A 64-bit hash of the grid's content: every nonzero voxel's coordinate and value. Two grids with
/// the same nonzero voxels hash alike whatever their tree layout or active states (a tile hashes as
/// its voxels).
/// @throw Error if the grid's tiles hold more than 2^35 voxels of clay (a damaged or foreign file).
uint64_t contentHash(const MassGrid& mass);

/// The accuracy metrics of one clay state (see the definitions at the top of this file).
/// Mass drift is a difference of two states: the run summary reports it (RunSummary::massDrift).
struct ClayMetrics {
    int64_t mass = 0;             ///< totalMass()
    int64_t residualOverload = 0; ///< sum over non-obstacle cells of max(0, m - Tc); 0 at rest
    int32_t maxCell = 0;          ///< the largest mass of one cell
    uint64_t clayVoxels = 0;      ///< cells holding clay (m > 0)
    uint64_t occupiedVoxels = 0;  ///< cells with 2 m >= Tc (inside the 0.5 surface)
    uint64_t interiorCells = 0;   ///< interior cells (held clay, not obstacle, all face neighbours hold clay)
    /// Mean density m / Tc over interior cells (0 when there are none).
    double interiorMeanDensity = 0;
    /// Density heterogeneity: the coefficient of variation (population standard deviation / mean)
    /// of the mass over interior cells. 0 = every interior cell holds the same mass; 0 when there
    /// are no interior cells.
    double heterogeneityCV = 0;
    /// Compaction: clayVoxels / ceil(mass / Tc), the cells the clay occupies against the fewest
    /// cells that could hold it at rest. 1.0 = perfectly compact (every cell full but at most one);
    /// > 1 = spread thin (partly filled cells); < 1 only while cells are over Tc. 0 for no clay.
    double compaction = 0;
};

/// Measures @a mass with threshold Tc = @a threshold in @a dims dimensions (2: only z = 0 counts
/// for neighbours, as the automaton's 2D clay lives there). Obstacle cells (@a obstacles may be
/// null) are never interior and carry no residual overload; their clay still counts in mass,
/// clayVoxels and occupiedVoxels.
/// Runs over the leaves on @a threads threads (1: the calling thread only; 0: every core); the
/// result is the same on any thread count.
/// @throw Error if threshold <= 0, dims is not 2 or 3, or the grid holds a nonzero tile.
ClayMetrics measureClay(const MassGrid& mass, int32_t threshold, const ObstacleGrid* obstacles, int dims,
                        int threads = 0);

/// How far a clay shape is from a reference shape, both as occupied voxel sets.
struct ShapeError {
    uint64_t clayVoxels = 0;      ///< occupied voxels of the clay
    uint64_t referenceVoxels = 0; ///< occupied voxels of the reference
    uint64_t intersection = 0;    ///< voxels occupied in both
    uint64_t unionVoxels = 0;     ///< voxels occupied in either
    /// intersection / union; 1 when both are empty.
    double iou = 0;
    uint64_t claySurface = 0, referenceSurface = 0; ///< surface voxels of each set
    /// Mean symmetric surface distance, in voxels: every surface voxel of either set contributes
    /// the Euclidean distance between its centre and the nearest surface voxel centre of the other
    /// set; the mean over all of them. 0 when both are empty; +infinity when exactly one is.
    double meanSurfaceDistance = 0;
    /// The largest of those distances (the Hausdorff distance between the two surfaces).
    double maxSurfaceDistance = 0;
};

/// Compares the occupied voxels of @a clay (threshold @a threshold) with those of @a reference
/// (threshold @a referenceThreshold), e.g. a result against a run with another rule. In 2D only
/// z = 0 is compared.
/// @throw Error if a threshold <= 0, dims is not 2 or 3, or a grid holds a nonzero tile.
ShapeError compareShapes(const MassGrid& clay, int32_t threshold, const MassGrid& reference,
                         int32_t referenceThreshold, int dims);

/// Compares the occupied voxels of @a clay with an analytic shape rasterised on the same voxels: a
/// voxel is in the reference when the shape's distance at its centre is < 0 (as makeClay() fills
/// clay). In 2D only z = 0 is rasterised and compared.
/// @throw Error as above.
ShapeError compareShapes(const MassGrid& clay, int32_t threshold, const Shape& reference, int dims);

} // namespace vdbclay
