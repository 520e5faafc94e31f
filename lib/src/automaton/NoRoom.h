// Whether the overload can never vanish: the flood behind StopReason::NoRoom (Automaton::settle).
#pragma once

#include "vdbclay/Fwd.h"

#include <cstdint>

namespace vdbclay {
namespace automaton_internal {

/// True when the overload provably cannot vanish: flooding from every over cell (mass > @a tc, not
/// an obstacle) through the non-obstacle cells (face neighbours; 2D: in z = 0) closes on walled-in
/// regions that hold more than Tc per cell. Gives up (false) as soon as the cells reached have room
/// for the whole @a overload, or are more than ceil(@a totalMass / Tc) (they could hold all the clay
/// there is): the cost is bounded by the clay's volume. False when @a overload is 0.
bool overloadHasNoRoom(const Tree543<int32_t>& mass, const Tree543<openvdb::ValueMask>* obstacles, int64_t tc,
                       int64_t overload, int64_t totalMass, bool is3D);

} // namespace automaton_internal
} // namespace vdbclay
