// A run's report (RunReport.h) and its JSON text: the one place that names the report's keys, for the
// CLI's --stats file and the Python module's run report.
#include "vdbclay/RunReport.h"

#include "vdbclay/Metrics.h"

#include <nlohmann/json.hpp>

#include <cstdio>

namespace vdbclay {

RunReport makeRunReport(const Sculptor& sculptor, const RunSummary& summary, int threads)
{
    const Scene& scene = sculptor.scene();
    RunReport r;
    r.scene = scene.source;
    r.rule = scene.rule.rule;
    r.threshold = scene.rule.threshold;
    r.threads = threads;
    r.push = scene.push;
    r.sweep = scene.sweep;
    r.transport = scene.transport;
    r.summary = summary;
    r.clayVoxels = clayVoxelCount(*sculptor.mass());
    r.contentHash = contentHash(*sculptor.mass());
    return r;
}

std::string runReportJson(const RunReport& r, int indent)
{
    const RunSummary& s = r.summary;
    nlohmann::json j;
    j["scene"] = r.scene;
    j["rule"] = ruleName(r.rule);
    j["threshold"] = r.threshold;
    j["threads"] = r.threads;
    j["frames"] = s.frames;
    j["steps"] = s.steps;
    j["seconds"] = s.seconds;
    j["frame_seconds"] = s.frameSeconds;
    j["push_seconds"] = s.pushSeconds;
    j["setup_seconds"] = r.setupSeconds;
    j["output_seconds"] = r.outputSeconds;
    j["heap"] = r.heap;
    j["push"] = pushModeName(r.push);
    j["sweep"] = r.sweep;
    j["transport"] = transportName(r.transport);
    j["transport_seconds"] = s.transportSeconds;
    j["transport_solves"] = s.transportSolves;
    j["transport_iterations"] = s.transportIterations;
    j["transport_mass_moved"] = s.transportMassMoved;
    j["frames_transport_no_room"] = s.framesTransportNoRoom;
    j["stage_seconds"] = {{"gather", s.stages.gather},
                          {"repartition", s.stages.repartition},
                          {"grow", s.stages.grow},
                          {"bookkeeping", s.stages.bookkeeping}};
    // Thread-seconds within repartition: the passes' shares ran, and their threads sat idle.
    j["pass_busy_seconds"] = s.stages.passBusy;
    j["pass_idle_seconds"] = s.stages.passIdle;
    j["mass_initial"] = s.massInitial;
    j["mass_final"] = s.massFinal;
    j["mass_added"] = s.massAdded;
    j["mass_removed"] = s.massRemoved;
    j["mass_smoothed"] = s.massSmoothed;
    j["tension_seconds"] = s.tensionSeconds;
    j["tension_boxes"] = s.tensionBoxes;
    j["tension_voxels"] = s.tensionVoxels;
    j["residual_overload"] = s.residualOverload;
    j["settled"] = s.settled;
    j["frames_unsettled"] = s.framesUnsettled;
    j["mass_trapped"] = s.massTrapped;
    j["blocks_visited"] = s.blocksVisited; // candidates examined, before any filter
    j["blocks_over_tc"] = s.blocksOverTc;
    j["blocks_updated"] = s.blocksUpdated;
    j["clay_voxels"] = r.clayVoxels;
    j["frames_no_room"] = s.framesNoRoom;
    j["mass_drift"] = s.massDrift;
    j["max_cell"] = s.metrics.maxCell;
    j["occupied_voxels"] = s.metrics.occupiedVoxels;
    j["interior_cells"] = s.metrics.interiorCells;
    j["interior_mean_density"] = s.metrics.interiorMeanDensity;
    j["heterogeneity_cv"] = s.metrics.heterogeneityCV;
    j["compaction"] = s.metrics.compaction;
    // Runs on any thread count give the same (bench/thread-curve.sh checks it).
    char hash[17];
    std::snprintf(hash, sizeof hash, "%016llx", (unsigned long long)r.contentHash);
    j["content_hash"] = hash;
    return j.dump(indent);
}

} // namespace vdbclay
