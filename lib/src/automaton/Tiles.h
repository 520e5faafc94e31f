// Uniform clay as tiles: what the automaton allows of OpenVDB's tiles, and the three operations on them.
//
// A tile is one value at an internal node standing for all of its 8^3, 128^3 or 4096^3 voxels (a
// root tile: 4096^3). The mass tree holds clay of one value over a region (a full interior at Tc) as
// tiles, so memory and every walk follow the clay's surface, not its volume. The automaton keeps an
// active tile when its value is positive and at most Tc: no cell of it is over Tc, so no block inside
// it can change, and a block that reads it together with a leaf is deferred by the pass to the serial
// grow stage, which turns the tile's slot into a leaf (touchLeaf: the tile's value in every voxel)
// before updating the block (Kernel.cc, LeafSet::tile). So a step gives the same clay, voxel for
// voxel, whatever the tree's layout. A tile over Tc, or an active tile in 2D (it would span z != 0),
// is voxelized or refused when the automaton scans the grid (scanTiles).
//
// densifyTiles turns the tiles that meet a box into leaves (an edit, a push: code that walks the
// leaves of a box then sees every voxel of it); collapseUniformLeaves turns leaves whose voxels are
// all equal back into tiles, and nodes of equal tiles into larger tiles (after a frame). Both are
// serial and deterministic: the tree they leave depends only on its values. collapseUniformLeavesIn
// does the same over the nodes that meet a list of regions alone: after a collapse no node is left
// uniform, so only a node written since (inside the regions its writers record: the Automaton keeps
// that list) can have become so, and the tree it leaves is the one the whole walk leaves.
#pragma once

#include "automaton/LeafTable.h"

#include "vdbclay/Types.h"

#include <cstdint>
#include <string>
#include <vector>

namespace vdbclay {
namespace automaton_internal {

/// The clay the tiles hold.
struct TileScan {
    int64_t mass = 0;     ///< the tiles' mass (value x voxels)
    int64_t maxValue = 0; ///< the largest tile value (0 without tiles)
};

/// Checks every tile of @a tree and returns the clay they hold: inactive tiles must hold 0, active
/// ones a positive value, and in 2D (@a is3D false) none may hold clay. A tile over @a tc is voxelized
/// (the tree's voxelizeActiveTiles(), so leaves hold it), an active tile of 0 turned off. @a grid
/// names the grid in errors.
/// @throw Error naming the tile's bounds and value for a negative, inactive nonzero or 2D tile, or
///        clay whose total exceeds int64.
TileScan scanTiles(MassTree& tree, int64_t tc, bool is3D, const std::string& grid);

/// Turns every tile holding clay that meets @a region (inclusive) into the leaves of the region's
/// slots (touchLeaf: each voxel holds the tile's value, active). The clay is unchanged. Returns the
/// leaves made.
uint64_t densifyTiles(MassTree& tree, const Box& region);

/// Collapses each leaf whose voxels all hold one value of at most @a tc (all active and positive, or
/// all inactive and 0) into a tile, then each internal node made only of equal tiles into a tile of
/// its parent, as Tree::prune(0) does but never making a tile over @a tc. The clay is unchanged.
/// Returns the leaves removed.
uint64_t collapseUniformLeaves(MassTree& tree, int64_t tc);

/// collapseUniformLeaves() over the leaves and internal nodes that meet @a regions alone (each node
/// examined once, lowest level first, as the whole walk does). The same tree as the whole walk when
/// every node outside the regions is as the last collapse of the whole tree left it (directly, or
/// through collapses of the regions written since). Regions holding more leaf slots than the tree
/// holds leaves: the whole walk.
uint64_t collapseUniformLeavesIn(MassTree& tree, int64_t tc, const std::vector<Box>& regions);

} // namespace automaton_internal
} // namespace vdbclay
