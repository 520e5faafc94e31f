/// @file Deposit.h
/// @brief Tools that add clay and take it away: deposit() fills the free voxels a tool covers,
///        carve() empties the clay inside a tool. Both go through Automaton::setMasses, so the
///        automaton's totals stay exact and the changed region is woken.
#pragma once

#include "vdbclay/Shapes.h"
#include "vdbclay/Types.h"

#include <cstdint>
#include <string>
#include <vector>

namespace vdbclay {

class Automaton;

/// What a tool does to the clay it meets (scene files: a tool's "action").
enum class ToolAction {
    Push,   ///< moves the clay out of the voxels it enters (Push.h; the default)
    Add,    ///< deposits clay into the free voxels it covers (deposit())
    Remove, ///< takes away the clay inside it (carve())
    Smooth  ///< surface tension inside it (Smooth.h)
};
/// "push", "add", "remove" or "smooth".
const char* toolActionName(ToolAction action);
/// @throw Error naming @a name and the valid names if it is none of them.
ToolAction parseToolAction(const std::string& name);
/// Whether a tool with @a action is a solid while clay settles: its voxels are obstacles, and
/// deposit() never writes into them (push and remove tools). Add and smooth tools are not.
bool toolIsSolid(ToolAction action);

/// What one deposit() or carve() did.
struct DepositReport {
    int64_t mass = 0;    ///< clay added (deposit) or taken away (carve); >= 0
    uint64_t voxels = 0; ///< voxels whose mass changed
    Box region;          ///< the voxels changed (their bounds; empty when nothing changed)
};

/// Raises every voxel that @a tool covers to at least round(@a massPerVoxel x the fraction of the
/// voxel the tool covers): a voxel wholly inside holds at least @a massPerVoxel, a boundary voxel
/// its share (the coverage makeClay gives volume-keeping shapes: Voxels.h, docs/INTEROP.md
/// "Coverage"). Clay already there counts: a voxel that holds as much or more is left as it is, so
/// a tool that stays where it is adds nothing after its first frame, and a moving one lays a bead
/// along its path. Never writes into an obstacle of @a automaton nor a voxel whose centre lies
/// inside one of @a solids (the other tools). Only the tool's bounds (grown by one voxel) are
/// visited, serially in coordinate order: deterministic and independent of the thread count. 2D
/// automata: the z = 0 layer only. A cell never exceeds max(old, massPerVoxel), so no cell
/// overflows; a block that would overflow int32 is refused by the automaton's next step.
/// @throw Error if @a massPerVoxel <= 0.
DepositReport deposit(Automaton& automaton, const Shape& tool, int32_t massPerVoxel,
                      const std::vector<ShapePtr>& solids = {});

/// Takes away the clay inside @a tool: a voxel wholly inside loses all of it, a boundary voxel
/// round(its mass x the fraction the tool covers). Obstacles included (clay frozen in a tool's cell
/// is taken as well; static obstacles hold no clay). Only the tool's bounds (grown by one voxel)
/// are visited, serially in coordinate order.
DepositReport carve(Automaton& automaton, const Shape& tool);

} // namespace vdbclay
