// What the library (not its users) may change on an Automaton: private to lib/src and the tests.
#pragma once

#include "vdbclay/Automaton.h"

namespace vdbclay {
namespace automaton_internal {

/// Which blocks a step examines (blocksVisited; the results are the same either way). On (the
/// default), a block is examined again only where the cells that changed near it can let it change:
/// its own over cells, or cells that went over Tc or came down from over it (Candidates.h,
/// sinkActive). Off, every block that overlaps a block changed in the last two steps is examined, so
/// that blocksVisited counts the same blocks however the automaton was built or resumed (the
/// Sculptor's bounded try caps its work by that count).
void setPruneCandidates(Automaton& automaton, bool on);
bool pruneCandidates(const Automaton& automaton);

class ChangedClay;
/// While @a changed is not null, @a automaton records into it where its clay changes: each block a
/// step changes, each cell setMasses() changes, the part of an edit()'s region in each of its leaves
/// (ChangedClay.h). @a changed must outlive the attachment; null detaches.
void setChangedClay(Automaton& automaton, ChangedClay* changed);

/// When no cell of @a automaton is over Tc, no block can change before the next edit: forgets the
/// blocks that edits and steps woke, so the next steps examine none of them (as an automaton built
/// from the same clay, a resumed one, would not). Changes no clay. Returns whether it forgot.
bool forgetWakesWhenSettled(Automaton& automaton);

/// Reaches Automaton's state for the functions above (the friend of Automaton).
struct AutomatonAccess;

} // namespace automaton_internal
} // namespace vdbclay
