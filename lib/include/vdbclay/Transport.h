/// @file Transport.h
/// @brief Global transport: displaced clay moved through the body to where there is room, in one
///        pass per frame, before the paper's automaton cleans up locally (lib/src/transport/).
#pragma once

#include "vdbclay/Types.h"

#include <cstdint>
#include <memory>
#include <string>

namespace vdbclay {

class Automaton;

/// How a Sculptor moves the clay a push displaced.
enum class Transport {
    Local, ///< the paper's automaton alone (settled every frame)
    Global ///< transportGlobally() right after the push, then the automaton as cleanup
};
const char* transportName(Transport transport);
/// "local" or "global". @throw Error naming @a name otherwise.
Transport parseTransport(const std::string& name);

/// What a caller chooses of the global layer (the solver's own tuning is internal).
struct GlobalTransportOptions {
    /// How far (face steps through full clay) from the over cells on the clay's boundary (where the
    /// tool touched) the layer may move clay: the plastic zone. 0: the whole connected body. When a
    /// region within the reach has no room, the reach is doubled until it has, or the whole body is
    /// reached (then NoRoom).
    int64_t reach = 0;
    /// The caller's bound on the face steps from an over cell to room (0: none known): a doubling of
    /// the reach that would pass it stops there first, so where room lies within it the reach ends
    /// at most max(reach, roomWithin), not just below twice it.
    int64_t roomWithin = 0;
    /// Only the cells over Tc in this box move (the push's region); empty: every cell of the grid.
    /// Either way nothing runs when the automaton holds no overload (residualOverload() == 0).
    Box seedRegion;
    /// Worker threads for the solver's vector operations: 0 all cores, 1 serial. The result does
    /// not depend on it (fixed chunks, partial sums added in chunk order).
    int threads = 0;
};

namespace transport_internal {
struct Workspace;
struct WorkspaceAccess;
} // namespace transport_internal

/// The global layer's arrays (cell lists, matrix, multigrid hierarchy, work vectors), kept between
/// transportGlobally() calls. Opaque; not shared between threads. Its memory is what the largest call
/// so far needed (estimateSceneMemory's transportBytes covers it); release() frees it.
class GlobalTransportWorkspace {
public:
    GlobalTransportWorkspace();
    ~GlobalTransportWorkspace();
    GlobalTransportWorkspace(const GlobalTransportWorkspace&) = delete;
    GlobalTransportWorkspace& operator=(const GlobalTransportWorkspace&) = delete;
    void release();

private:
    friend struct transport_internal::WorkspaceAccess;
    std::unique_ptr<transport_internal::Workspace> mImpl;
};

struct GlobalTransportReport {
    int64_t overloadBefore = 0;   ///< sum of max(0, m - Tc) over the seed region's cells, before
    int64_t overloadAfter = 0;    ///< after, over every cell (Automaton::residualOverload())
    int64_t massMoved = 0;        ///< clay routed from cell to cell (sum of the integer face flows)
    uint64_t unknowns = 0;        ///< cells of the last solve
    uint64_t solves = 0;          ///< Poisson solves (active-set rounds, over every reach tried)
    uint64_t iterations = 0;      ///< conjugate-gradient iterations, all solves
    uint64_t multigridSolves = 0; ///< of the solves, those preconditioned by multigrid
    uint64_t multigridReused = 0; ///< of those, the ones that reused an earlier active-set round's hierarchy
    int64_t reach = 0;            ///< the reach finally used (0: the whole body)
    /// Some over clay is walled in (obstacles, tools) with no room in its connected body: its
    /// Poisson problem is singular. That clay is left where it is (the automaton reports NoRoom).
    bool noRoom = false;
    /// The overload fitted where it was (room within two steps of every over cell, enough of it):
    /// no solve, the automaton settles it locally.
    bool skipped = false;
    int64_t massNoRoom = 0; ///< the overload of those walled-in regions
    double seconds = 0;
    Box region; ///< the voxels written (empty when nothing moved)
};

/// Moves the overload (m - Tc of cells over Tc) of @a automaton's clay through the full clay
/// (m >= Tc, connected by faces, not obstacles) to cells with room, in integers: a pressure p
/// solves the obstacle problem (Laplace p = m - Tc on the full cells and on every cell that would
/// receive more than its room; p = 0 on the others; no flux into obstacles), by active-set rounds
/// of preconditioned conjugate gradients (MIC(0) for small solves, an aggregation multigrid for
/// large ones); then every solved cell, in order of decreasing p, sends its integer excess to its
/// lower-p face neighbours pro rata of the drop (largest-remainder rounding). Every solved cell that
/// had excess ends at exactly Tc; mass is exact by construction; obstacles are never entered or
/// crossed. Deterministic for any thread count. Written through Automaton::setMasses(), so the
/// automaton wakes the region for its cleanup.
/// @throw Error if @a options.reach < 0; nothing is changed then.
/// @a workspace (optional): arrays kept from one call to the next (a Sculptor keeps one), so that
/// a frame reuses the last frame's memory instead of page-faulting fresh arrays (zeroing fresh pages
/// is ~10 % of the 128^3 press otherwise). Holds nothing a result depends on.
GlobalTransportReport transportGlobally(Automaton& automaton, const GlobalTransportOptions& options = {},
                                        GlobalTransportWorkspace* workspace = nullptr);

} // namespace vdbclay
