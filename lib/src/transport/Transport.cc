// Global transport: the overload moved through the full clay to where there is room, in integers.
//
// Why. In clay at m0 = Tc the paper's automaton moves displaced clay by a random walk through
// saturated cells: steps grow as N^2 and work as N^5-N^6, and the clay exits where the walk
// happens to reach open space. A pressure projection solved as an obstacle problem moves it in one
// pass (docs/TRANSPORT.md, and the prototype study it follows).
//
// The stages of a call, each in its own file:
// 1. Domain (Domain.h). Seeds: every non-obstacle cell over Tc (in the seed region), in tree order.
//    If the overload fits where it is (room near every seed, enough of it), nothing runs: the
//    automaton settles it. Otherwise a breadth-first flood through face neighbours that are full
//    (m >= Tc) and not obstacles, at most `reach` steps from the contact (the seeds with a face on
//    an obstacle, a tool or room; the plastic zone: a small tool moves clay near itself, a plate
//    covering the body moves the whole body), gives the unknown cells D. Seeds inside the full clay
//    (a compress push's chains) join at their depth; one beyond the reach starts its own flood with
//    a margin of kInnerMargin. D's face neighbours with room (m < Tc, not an obstacle) are Dirichlet
//    cells B (p = 0). Obstacles, and full cells beyond the reach, are walls: their faces are left out
//    of the Laplacian (no flux).
// 2. Singular parts (Domain.h). A connected part of D with no face on B has no room: its Poisson
//    problem is singular (the flood finds the parts and which touch B; only then are they searched).
//    If it was cut by the reach, the reach doubles and the domain is rebuilt (up to the whole body);
//    otherwise it is walled in: its clay stays (NoRoom), it leaves the solve.
// 3. Active set (ActiveSet.h). Solve L p = m - Tc on D (Laplacian.h: for each non-wall face,
//    p_i - p_j; p_j = 0 on B) by preconditioned conjugate gradients (Pcg.h), warm-started from the
//    previous round: MIC(0) (Mic0.h) for small solves, an aggregation multigrid V-cycle (Multigrid.h)
//    for large ones (Poisson.h chooses and keeps them across rounds). A B cell whose inflow exceeds
//    its room joins D, a joined cell with p < 0 leaves again, until nothing changes: the cells of D
//    end exactly full.
// 4. Routing, exact (Routing.h). Cells of D in order of decreasing p (RadixSort.h) send their
//    integer excess to their lower-p face neighbours, pro rata of the drop, largest remainder first:
//    every D cell with excess ends at exactly Tc, mass is exact by construction, walls are never
//    crossed. The changed cells are written through Automaton::setMasses().
//
// Determinism. The cell numbering is the one-by-one flood's (a large layer's faces are probed in
// parallel, and what they found is added in that order: Domain.h); the routing's integer split is
// serial and ordered, and its sort is on a strict total order. The solver's set-up and vector
// operations run over fixed chunks of rows (Chunks.h); dot products add per-chunk partial sums in
// chunk order. Every floating-point operation is therefore the same on any thread count, and so is
// the potential, the routing and the result. Every array lives in a GlobalTransportWorkspace when
// the caller keeps one (the Sculptor does: no fresh pages each frame); none is read before written.
//
// Cost. The flood and the solve touch the full cells within the reach and their faces, never the
// bounding box: work follows the clay body (or the plastic zone), times the CG iterations.

#include "vdbclay/Transport.h"
#include "vdbclay/Automaton.h"

#include "transport/ActiveSet.h"
#include "transport/Domain.h"
#include "transport/Poisson.h"
#include "transport/RadixSort.h"
#include "transport/Routing.h"
#include "transport/SolverTuning.h"

#include <tbb/task_arena.h>

#include <algorithm>
#include <chrono>
#include <memory>
#include <string>
#include <vector>

namespace vdbclay {

const char* transportName(Transport transport)
{
    return transport == Transport::Global ? "global" : "local";
}

Transport parseTransport(const std::string& name)
{
    if (name == "local") return Transport::Local;
    if (name == "global") return Transport::Global;
    throw Error("unknown transport \"" + name + "\" (expected one of: local, global)");
}

namespace transport_internal {

/// The layer's arrays, kept from one call to the next by a GlobalTransportWorkspace.
struct Workspace {
    std::vector<CellCoord> seeds; ///< the over cells
    DomainArrays domain;
    PoissonArrays poisson;
    ActiveSetArrays activeSet;
    RoutingArrays routing;
    RadixScratch sort;
};

/// The workspace's arrays, made on first use.
struct WorkspaceAccess {
    static Workspace& of(GlobalTransportWorkspace& w)
    {
        if (!w.mImpl) w.mImpl = std::make_unique<Workspace>();
        return *w.mImpl;
    }
};

namespace {

/// One call's stages on @a ws's arrays. @a keep: the arrays outlive the call (a workspace), so the
/// solver's are not freed before the routing.
GlobalTransportReport run(Automaton& automaton, const GlobalTransportOptions& options,
                          const SolverTuning& tuning, Workspace& ws, bool keep)
{
    GlobalTransportReport rep;
    // Nothing over Tc (the automaton keeps the sum): nothing to do, at no cost (a push that found
    // room where it was, a compressible clay).
    if (automaton.residualOverload() == 0) return rep;
    const bool serial = options.threads == 1;
    Domain domain(automaton, ws.domain, tuning.reachFromContact, tuning.floodBatchMin, serial);
    std::vector<CellCoord>& seeds = ws.seeds;
    seeds.clear();
    rep.overloadBefore = domain.seeds(options.seedRegion, seeds);
    rep.overloadAfter = automaton.residualOverload();
    if (seeds.empty()) return rep;
    if (domain.fitsNearby(seeds, rep.overloadBefore)) {
        rep.skipped = true;
        return rep;
    }

    int64_t reach = options.reach > 0 ? options.reach : 0;
    int64_t margin = kInnerMargin; // doubles with the reach: a walled-in inner seed grows as fast
    for (;;) {
        bool cut = false;
        const bool allRoom = domain.build(seeds, reach, margin, cut);
        rep.reach = reach;
        bool grow = false;
        if (!allRoom) domain.freezeSingular(cut, grow, rep);
        if (!grow) break;
        int64_t next = reach * 2 >= int64_t(1) << 40 ? 0 : reach * 2;
        if (reach > 0 && options.roomWithin > reach && (next == 0 || options.roomWithin < next))
            next = options.roomWithin;
        reach = next;
        margin = std::min<int64_t>(margin * 2, int64_t(1) << 40);
    }
    PoissonSolver solver(domain.cells(), ws.poisson, ws.sort, domain.threshold(), tuning.multigridMin,
                         serial);
    solveActiveSet(domain, solver, tuning, serial, ws.activeSet, rep);
    solver.release(keep); // before the routing's own arrays: a lower peak
    route(automaton, domain.cells(), ws.activeSet.p, domain.threshold(), domain.dirs(), serial, ws.routing,
          ws.sort, rep);
    return rep;
}

} // namespace

GlobalTransportReport transportGlobally(Automaton& automaton, const GlobalTransportOptions& options,
                                        const SolverTuning& tuning, GlobalTransportWorkspace* workspace)
{
    if (options.reach < 0)
        throw Error("transportGlobally: reach must be >= 0, got " + std::to_string(options.reach));
    if (options.roomWithin < 0)
        throw Error("transportGlobally: roomWithin must be >= 0, got " + std::to_string(options.roomWithin));
    if (tuning.maxRounds < 1) throw Error("transportGlobally: maxRounds must be >= 1");
    if (!(tuning.tolerance > 0 && tuning.tolerance < 1))
        throw Error("transportGlobally: tolerance must lie in (0, 1)");
    if (!(tuning.roundTolerance >= 0 && tuning.roundTolerance < 1))
        throw Error("transportGlobally: roundTolerance must lie in [0, 1)");
    const auto t0 = std::chrono::steady_clock::now();
    std::unique_ptr<Workspace> local;
    Workspace* ws = nullptr;
    if (workspace) {
        ws = &WorkspaceAccess::of(*workspace);
    } else {
        local = std::make_unique<Workspace>();
        ws = local.get();
    }
    GlobalTransportReport rep;
    auto body = [&] { rep = run(automaton, options, tuning, *ws, workspace != nullptr); };
    if (options.threads > 1) {
        tbb::task_arena arena(options.threads);
        arena.execute(body);
    } else {
        body();
    }
    rep.seconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
    return rep;
}

} // namespace transport_internal

GlobalTransportWorkspace::GlobalTransportWorkspace() = default;
GlobalTransportWorkspace::~GlobalTransportWorkspace() = default;

void GlobalTransportWorkspace::release()
{
    mImpl.reset();
}

GlobalTransportReport transportGlobally(Automaton& automaton, const GlobalTransportOptions& options,
                                        GlobalTransportWorkspace* workspace)
{
    return transport_internal::transportGlobally(automaton, options, transport_internal::SolverTuning{},
                                                 workspace);
}

} // namespace vdbclay
