/// @file RunReport.h
/// @brief What a scene's run did, as one record: its totals (RunSummary), its context (scene, rule,
///        modes, threads), its times and the clay's hash; and that record as JSON text, which is
///        the CLI's --stats file and the Python module's run report alike.
#pragma once

#include "vdbclay/Push.h"
#include "vdbclay/Sculpt.h"
#include "vdbclay/Transport.h"
#include "vdbclay/Types.h"

#include <cstdint>
#include <string>

namespace vdbclay {

/// A run of a Sculptor: what Sculptor::run() returned, with what it ran and what it took.
struct RunReport {
    std::string scene;       ///< Scene::source
    Rule rule = Rule::Arata; ///< the scene's rule
    int32_t threshold = 0;   ///< the scene's Tc
    int threads = 0;         ///< the threads asked for (0: all cores)
    PushMode push = PushMode::Surface;
    bool sweep = false;
    Transport transport = Transport::Local;
    std::string heap;         ///< the allocator policy (BatchHeap::note; the caller's to set)
    RunSummary summary;       ///< the run's totals and the final clay's metrics
    double setupSeconds = 0;  ///< the scene's clay, obstacles and tools into grids (the caller's)
    double outputSeconds = 0; ///< writing the .vdb, picture and mesh, not the report (the caller's)
    uint64_t clayVoxels = 0;  ///< voxels holding clay at the end (clayVoxelCount)
    uint64_t contentHash = 0; ///< the final clay's contentHash, as `vdbclay info` prints it
};

/// The report of the run of @a sculptor on @a threads threads that returned @a summary: the
/// scene's context, the summary, the clay's voxel count and content hash (a walk of the clay each).
/// The times and the heap are left for the caller, who measured them.
RunReport makeRunReport(const Sculptor& sculptor, const RunSummary& summary, int threads);

/// @a report as a JSON object (keys sorted, indented by @a indent; -1: one line), with these keys:
/// scene, rule, threshold, threads, push, sweep, transport, heap; frames, steps, seconds,
/// push_seconds, setup_seconds, output_seconds, stage_seconds {gather, repartition, grow,
/// bookkeeping}, pass_busy_seconds, pass_idle_seconds; transport_seconds, transport_solves,
/// transport_iterations, transport_mass_moved, frames_transport_no_room; mass_initial, mass_final,
/// mass_added, mass_removed, mass_drift (mass_final - mass_initial - mass_added + mass_removed),
/// mass_trapped, residual_overload, settled, frames_unsettled, frames_no_room; blocks_visited,
/// blocks_over_tc, blocks_updated; clay_voxels, max_cell, occupied_voxels, interior_cells,
/// interior_mean_density, heterogeneity_cv, compaction; content_hash (16 hex digits).
std::string runReportJson(const RunReport& report, int indent = 2);

} // namespace vdbclay
