/// @file Automaton.h
/// @brief The virtual-clay cellular automaton on a sparse OpenVDB grid.
///
/// An Automaton owns a reference to a MassGrid (openvdb::Int32Grid, background value 0) and,
/// optionally, an ObstacleGrid (openvdb::MaskGrid; active voxels are obstacles). Each step()
/// applies the rule to every Margolus block of the current phase that can change: even steps use
/// blocks whose minimum corner has even coordinates, odd steps blocks shifted by one voxel along
/// every axis. 3D blocks are 2x2x2; in 2D the clay lives in the z = 0 layer and blocks are 2x2 in xy.
///
/// Guarantees:
/// - Mass is conserved exactly (integers throughout; sums in 64 bits).
/// - The result is bit-identical for every thread count and for the serial path (threads = 1):
///   blocks of one phase are disjoint and each block's update depends only on its own cells and on
///   a counter-based hash of (block origin, step, seed).
/// - The cost of a step follows the blocks that can change: a block is examined only if one of its
///   cells changed during the previous two steps. A settled region costs nothing.
/// - The tree grows leaves only where clay flows; the automaton never creates an empty leaf.
/// - A state whose masses could overflow a cell is refused (Error) before anything is written.
///
/// Thread-safety: one Automaton must not be used from several threads at once, and nothing else
/// may modify its grids while a step runs. Between steps, change the grid only through edit() or
/// follow the change with resync().
#pragma once

#include "vdbclay/Fwd.h"
#include "vdbclay/Types.h"

#include <array>
#include <cstdint>
#include <functional>
#include <memory>
#include <vector>

namespace vdbclay {

/// How an Automaton is set up. Plain definition struct: the defaults make a working automaton.
struct AutomatonOptions {
    /// 3 for 2x2x2 blocks; 2 for 2x2 blocks in the z = 0 layer (clay elsewhere is refused).
    int dimensions = 3;
    RuleParams rule;
    /// Seeds the remainder hash. Same seed, same state, same steps: same result.
    uint64_t seed = 0;
    /// Worker threads: 0 lets TBB choose (all cores), 1 runs the serial path, n > 1 caps at n.
    int threads = 0;
};

/// Seconds spent in each named stage of the step, summed over the steps reported.
struct StageSeconds {
    double gather = 0;      ///< build the list of candidate blocks from the last two steps' changes
    double repartition = 0; ///< the parallel pass over candidate blocks (TBB, horizontal layers)
    double grow = 0;        ///< blocks that flow into new leaves: create the leaves, then update
    double bookkeeping = 0; ///< collect changed blocks for the next steps, overflow checks
    /// Not stages (not in total()): how well the passes, within repartition, used their threads.
    /// passBusy: the thread-seconds the passes' shares of the work list ran (chunk 0's predrain of
    /// the next step's candidates included; on one thread, the passes' time).
    /// passIdle: the thread-seconds a thread of a pass ran none of its work: the caller cutting
    /// the work list, a thread waiting for its share to reach it or for the slowest share to end,
    /// every thread but one of a pass too small to share.
    /// Their sum is threads x the passes' time: passIdle / (passIdle + passBusy) is the fraction
    /// of the threads lost, 0 on one thread.
    double passBusy = 0;
    double passIdle = 0;
    double total() const { return gather + repartition + grow + bookkeeping; }
    StageSeconds& operator+=(const StageSeconds& o)
    {
        gather += o.gather;
        repartition += o.repartition;
        grow += o.grow;
        bookkeeping += o.bookkeeping;
        passBusy += o.passBusy;
        passIdle += o.passIdle;
        return *this;
    }
};

/// Why settle() stopped.
enum class StopReason {
    Settled,    ///< a full even+odd pair of steps changed nothing, and no cell is over Tc
    Tolerance,  ///< residual overload fell to the requested tolerance
    StepBudget, ///< the step budget ran out first
    /// The overload can never vanish: the cells connected to the over cells are walled in by
    /// obstacles and hold more than Tc each on average (clay squeezed with no room). Reported when
    /// nothing can move any more while cells are over Tc (settled is then true: every over cell is
    /// walled in by obstacles and other over cells), or, while clay still moves inside such a region
    /// (settled false), once a settle() call has run 8192 steps, then at each doubling. The state is
    /// exact; residualOverload says how much clay found no room.
    NoRoom,
    /// SettleOptions::stop asked to stop after a step (the state is exact; settling can go on).
    Stopped
};
const char* stopReasonName(StopReason reason);

class Automaton;
namespace automaton_internal {
struct AutomatonAccess; // the library's own hooks (lib/src/automaton/AutomatonInternal.h)
}

/// How settle() runs; settle(maxSteps, tolerance) is settle(SettleOptions{maxSteps, tolerance}).
struct SettleOptions {
    uint64_t maxSteps = 0; ///< step budget of the whole settle, the stepsDone included
    int64_t tolerance = 0; ///< stop once the residual overload is <= tolerance (when > 0)
    /// Steps an interrupted settle already ran (e.g. before a checkpoint): the budget and the
    /// no-room schedule count from here, so a resumed settle stops exactly where an unbroken one
    /// would.
    uint64_t stepsDone = 0;
    /// Polled after every step; returning true stops the settle after that step with
    /// StopReason::Stopped. Null: never stops early.
    std::function<bool(const Automaton&)> stop;
};

/// What a call to step(), run() or settle() did.
struct StepReport {
    uint64_t steps = 0; ///< steps run by this call
    /// Candidate blocks examined, counted before any filter: every block of every anchor's
    /// candidate mask, including those found to hold no over cell or to lie in a missing leaf.
    /// The cost of a step follows this number.
    uint64_t blocksVisited = 0;
    uint64_t blocksOverTc = 0;    ///< examined blocks holding a cell over Tc (the rule ran on them)
    uint64_t blocksUpdated = 0;   ///< blocks whose cells changed
    uint64_t blocksGrown = 0;     ///< updated blocks that needed new leaves (run after the pass)
    uint64_t leavesCreated = 0;   ///< leaves added to the tree
    int64_t residualOverload = 0; ///< after the call: sum over non-obstacle cells of max(0, m - Tc)
    bool settled = false;         ///< after the call: no block can change any more
    StopReason reason = StopReason::StepBudget; ///< settle() only
    StageSeconds seconds;

    StepReport& operator+=(const StepReport& other);
};

class Automaton {
public:
    /// Validates the state and prepares the automaton. Active tiles of @a mass holding at most Tc
    /// stay tiles (uniform clay: the automaton reads them as their voxels, turning a tile's slot into
    /// a leaf only where a block that can change reads it); tiles over Tc are voxelized.
    /// @throw Error if @a mass is null, its background is not 0, a voxel or tile holds negative mass,
    ///        an inactive tile holds nonzero mass, 2D clay lies outside z = 0 (a tile holding clay
    ///        does), or the options are invalid. Nothing is modified when it throws, except
    ///        voxelization.
    explicit Automaton(MassGridPtr mass, const AutomatonOptions& options = AutomatonOptions(),
                       ObstacleGridPtr obstacles = nullptr);
    ~Automaton();
    Automaton(const Automaton&) = delete;
    Automaton& operator=(const Automaton&) = delete;
    Automaton(Automaton&&) noexcept;
    Automaton& operator=(Automaton&&) noexcept;

    /// One step of the current phase (even, then odd, alternating).
    /// @throw Error if a block's result would overflow int32; the grid is then left unchanged.
    StepReport step();
    /// @a n steps (fewer if a step throws).
    StepReport run(uint64_t n);
    /// Steps until the automaton settles, residual overload <= @a tolerance (when tolerance > 0),
    /// @a maxSteps steps have run, or the overload provably has no room (StopReason::NoRoom),
    /// whichever comes first.
    StepReport settle(uint64_t maxSteps, int64_t tolerance = 0);
    /// settle() with a stop hook and a resumable step count (see SettleOptions). The checks run in
    /// this order before each step: settled (Settled, or NoRoom when overload is left), tolerance,
    /// the no-room flood (at kNoRoomCheckSteps steps, counted with stepsDone, then at each
    /// doubling), the budget; after each step the stop hook.
    StepReport settle(const SettleOptions& options);
    /// settle() checks for StopReason::NoRoom once a call has run this many steps, then at each
    /// doubling (a flood costs about as much as a few hundred steps of a large lump).
    static constexpr uint64_t kNoRoomCheckSteps = 8192;
    /// True when settle() runs the no-room flood before the step that follows @a stepsDone steps
    /// (counted with SettleOptions::stepsDone): at kNoRoomCheckSteps and at each doubling. Callers
    /// that prepare what the flood reads (the Sculptor's tool cells) ask here.
    static constexpr bool noRoomCheckDue(uint64_t stepsDone)
    {
        return stepsDone >= kNoRoomCheckSteps && (stepsDone & (stepsDone - 1)) == 0;
    }
    /// True when the overload provably cannot vanish: a flood from every over cell through the
    /// non-obstacle cells closes on walled-in regions holding more than Tc per cell. Bounded by the
    /// clay's volume. For callers that settle step by step (Sculptor, to stop between steps) and
    /// want settle()'s NoRoom check on the same schedule.
    bool overloadHasNoRoom();

    /// Lets @a fn change voxels of the mass grid inside @a region (inclusive), e.g. a tool pushing
    /// clay. The automaton rescans the region: it re-derives the overload there and wakes every
    /// block that touches it. Changes outside @a region are not seen (use resync()).
    /// @throw Error (and restore nothing: validate before editing) if the region then holds
    ///        negative mass or, in 2D, clay outside z = 0.
    void edit(const Box& region, const std::function<void(MassGrid&)>& fn);
    /// One cell's new mass, for setMasses().
    struct CellMass {
        std::array<int32_t, 3> at{{0, 0, 0}};
        int32_t mass = 0;
    };
    /// Sets the masses of @a cells (each cell listed at most once), as edit() over @a region with an
    /// fn that sets them would, but reads only those cells instead of rescanning the region: the
    /// overload, the total mass and the bound follow from each cell's old and new mass (the grid
    /// holds active exactly its nonzero cells, as after every edit and step). Like edit(), it wakes
    /// every block that touches @a region and prunes the region's empty leaves. For a change list
    /// much smaller than its bounds (the global transport's routing).
    /// @throw Error (and change nothing) if a mass is negative, a cell lies outside @a region or,
    ///        in 2D, outside z = 0.
    void setMasses(const Box& region, const std::vector<CellMass>& cells);
    /// Turns the tiles of the mass grid that meet @a region (inclusive) into leaves, each voxel
    /// holding its tile's value: the clay is unchanged and nothing is woken. For code that walks the
    /// leaves of a box (the push's sources).
    void densify(const Box& region);
    /// Collapses every leaf whose voxels all hold one value of at most Tc (all holding clay, or all
    /// empty) into a tile, and nodes of equal tiles into larger tiles: the clay is unchanged, the
    /// memory follows its surface. A Sculptor calls it after each frame. It examines only the nodes
    /// that meet what was written since the last call (edits, setMasses, densify, the steps' changed
    /// blocks), so its cost follows the frame's clay, not the model; the tree it leaves is the one a
    /// walk of every node leaves. Returns the leaves removed.
    uint64_t collapseUniformLeaves();
    /// Lets @a fn change obstacles inside @a region (inclusive), e.g. to make a tool's voxels
    /// obstacles while clay settles around it. Creates an empty obstacle grid if there was none.
    /// The region is rescanned as by edit(). Clay left in a cell that becomes an obstacle stays
    /// there, frozen, until the cell is freed.
    void editObstacles(const Box& region, const std::function<void(ObstacleGrid&)>& fn);
    /// Lets @a fn turn on obstacle cells where no clay can be read yet, without rescanning or
    /// waking anything and keeping the quiet-step count, so that settling goes on exactly as if
    /// those cells had been obstacles all along (a Sculptor places its tools' cells ahead of the
    /// clay this way). The caller guarantees that every cell @a fn turns on holds no clay and
    /// shares no Margolus block with a cell that holds clay; it is not checked. Creates an empty
    /// obstacle grid if there was none. Use editObstacles() for any other change.
    void extendObstacles(const std::function<void(ObstacleGrid&)>& fn);
    /// Rescans the whole grid after arbitrary outside changes, as the constructor does.
    void resync();

    /// Changes the rule or its parameters; every block is reconsidered.
    void setRule(const RuleParams& rule);
    void setSeed(uint64_t seed);
    /// 0 = TBB's choice, 1 = serial, n = at most n workers.
    void setThreads(int threads);
    /// Sets the step counter, e.g. to continue a run saved after @a steps steps: the phase and the
    /// remainder hash follow the counter, so the continuation is identical to an unbroken run.
    /// Every block is reconsidered on the next two steps.
    void setStepCount(uint64_t steps);
    const AutomatonOptions& options() const;
    uint64_t stepCount() const; ///< steps run since construction; step parity gives the phase
    int64_t totalMass() const;  ///< tracked exactly; equals sum of the grid at every step
    int64_t residualOverload() const;
    bool settled() const;
    /// Consecutive steps that changed no cell; construction, resync(), edit(), editObstacles(),
    /// setRule() and setStepCount() restart it at 0. settled() is true once it reaches 2.
    int quietSteps() const;
    const MassGridPtr& mass() const;
    const ObstacleGridPtr& obstacles() const;

private:
    friend struct automaton_internal::AutomatonAccess;
    struct Impl;
    std::unique_ptr<Impl> mImpl;
};

} // namespace vdbclay
