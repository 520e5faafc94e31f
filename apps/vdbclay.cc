// vdbclay: the command-line tool. Subcommands: run (scenes), info, mesh, render, import, demo.
// Thin: parsing and printing here, all work in the library. Every error ends in one line on stderr
// and a non-zero exit code.

#include "vdbclay/Automaton.h"
#include "vdbclay/IO.h"
#include "vdbclay/Metrics.h"
#include "vdbclay/Render.h"
#include "vdbclay/Scene.h"
#include "vdbclay/Sculpt.h"

#include <CLI/CLI.hpp>
#include <nlohmann/json.hpp>
#include <openvdb/io/File.h>
#include <openvdb/openvdb.h>

#include <signal.h>
#include <unistd.h>

#include <atomic>
#include <cerrno>
#include <chrono>
#include <climits>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <fstream>
#include <functional>
#include <iostream>
#include <memory>
#include <string>

namespace {

struct DemoArgs {
    int size = 32;
    int overload = 3;
    vdbclay::AutomatonOptions opts;
    uint64_t maxSteps = 200000;
    std::string out;
};

/// Writes @a text to @a path through a temporary file and a rename.
void writeTextAtomically(const std::string& path, const std::string& text)
{
    const std::string tmp = path + ".tmp-" + std::to_string(::getpid());
    {
        std::ofstream out(tmp, std::ios::binary | std::ios::trunc);
        if (!out) throw vdbclay::Error("cannot write " + path + ": " + std::strerror(errno));
        out << text;
        out.flush();
        if (!out) {
            std::remove(tmp.c_str());
            throw vdbclay::Error("cannot write " + path + ": " + std::strerror(errno));
        }
    }
    if (std::rename(tmp.c_str(), path.c_str()) != 0) {
        const int err = errno;
        std::remove(tmp.c_str());
        throw vdbclay::Error("cannot write " + path + ": " + std::strerror(err));
    }
}

/// Refuses, before any work, an output whose directory does not exist or cannot be written.
void checkWritable(const std::string& path)
{
    if (path.empty()) return;
    const auto slash = path.find_last_of('/');
    const std::string dir = slash == std::string::npos ? "." : (slash == 0 ? "/" : path.substr(0, slash));
    if (::access(dir.c_str(), W_OK) != 0) {
        throw vdbclay::Error("cannot write " + path + ": directory " + dir + ": " + std::strerror(errno));
    }
}

std::string fmtSeconds(double s)
{
    char buf[32];
    std::snprintf(buf, sizeof buf, "%.3f s", s);
    return buf;
}



int runDemo(const DemoArgs& a)
{
    using namespace openvdb;
    const bool d3 = a.opts.dimensions == 3;
    const int tc = a.opts.rule.threshold;
    Int32Grid::Ptr mass = Int32Grid::create(0);
    mass->setName("mass");
    const int n = a.size, q = std::max(1, n / 4);
    const int zmax = d3 ? n - 1 : 0;
    mass->tree().fill(CoordBBox(Coord(0, 0, 0), Coord(n - 1, n - 1, zmax)), tc, true);
    const Coord c0(n / 2 - q / 2, n / 2 - q / 2, d3 ? n / 2 - q / 2 : 0);
    const Coord c1(c0.x() + q - 1, c0.y() + q - 1, d3 ? c0.z() + q - 1 : 0);
    mass->tree().fill(CoordBBox(c0, c1), tc * a.overload, true);
    mass->tree().voxelizeActiveTiles();
    MaskGrid::Ptr floor = MaskGrid::create(false);
    floor->setName("obstacles");
    floor->tree().fill(CoordBBox(Coord(-4 * n, -4, d3 ? -4 * n : 0), Coord(5 * n, -1, d3 ? 5 * n : 0)),
                       true, true);

    vdbclay::Automaton automaton(mass, a.opts, floor);
    const int64_t m0 = vdbclay::totalMass(*mass);
    std::cout << "vdbclay demo: " << (d3 ? "3D " : "2D ") << n << (d3 ? "^3" : "^2")
              << " lump at Tc=" << tc << ", core " << q << (d3 ? "^3" : "^2") << " at " << a.overload
              << "xTc, rule " << vdbclay::ruleName(a.opts.rule.rule) << ", threads "
              << (a.opts.threads ? std::to_string(a.opts.threads) : std::string("all")) << "\n";
    std::cout << "  initial: mass " << m0 << ", overload " << automaton.residualOverload() << ", "
              << vdbclay::clayVoxelCount(*mass) << " clay voxels\n";
    const auto t0 = std::chrono::steady_clock::now();
    const vdbclay::StepReport r = automaton.settle(a.maxSteps);
    const double secs = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
    const int64_t m1 = vdbclay::totalMass(*mass);
    std::printf("  steps %llu (%s), %.3f s, %.2f us/step\n", (unsigned long long)r.steps,
                vdbclay::stopReasonName(r.reason), secs, r.steps ? 1e6 * secs / double(r.steps) : 0.0);
    std::printf("  blocks visited %llu, updated %llu, grown %llu; leaves created %llu\n",
                (unsigned long long)r.blocksVisited, (unsigned long long)r.blocksUpdated,
                (unsigned long long)r.blocksGrown, (unsigned long long)r.leavesCreated);
    std::printf("  stages: gather %.3f s, repartition %.3f s, grow %.3f s, bookkeeping %.3f s\n",
                r.seconds.gather, r.seconds.repartition, r.seconds.grow, r.seconds.bookkeeping);
    std::printf("  final: mass %lld (%s), residual overload %lld, settled %s, %llu clay voxels, "
                "%llu leaves, content hash %016llx\n",
                (long long)m1, m1 == m0 ? "exact" : "DRIFT", (long long)r.residualOverload,
                r.settled ? "yes" : "no", (unsigned long long)vdbclay::clayVoxelCount(*mass),
                (unsigned long long)mass->tree().leafCount(),
                (unsigned long long)vdbclay::contentHash(*mass));
    if (!a.out.empty()) {
        vdbclay::ClayMeta meta;
        meta.dimensions = a.opts.dimensions;
        meta.rule = a.opts.rule;
        meta.seed = a.opts.seed;
        meta.steps = automaton.stepCount();
        vdbclay::writeClayFile(a.out, *mass, meta);
        std::cout << "  wrote " << a.out << "\n";
    }
    return m1 == m0 ? 0 : 3;
}


struct RunArgs {
    std::string scene, out, stats, png, mesh, rule, checkpoint, resume, memoryBudget, push, transport, sweep;
    int threads = 0;
    int64_t seed = -1;
    uint64_t frames = 0;
    bool quiet = false;
    std::string up; ///< --up: empty keeps the scene's
};

vdbclay::UpAxis upOption(const std::string& up)
{
    try {
        return vdbclay::parseUpAxis(up);
    } catch (const vdbclay::Error& e) {
        throw vdbclay::Error(std::string("--up: ") + e.what());
    }
}

/// --up for run: the scene's meshes and level sets were read with the scene's own "up", so a
/// different --up is refused when the scene has any (docs/INTEROP.md).
void applyUp(vdbclay::Scene& scene, const std::string& up)
{
    if (up.empty()) return;
    const vdbclay::UpAxis axis = upOption(up);
    if (axis == scene.up) return;
    auto readWithUp = [](const vdbclay::ShapeSpec& s) { return s.kind == "mesh" || s.kind == "levelset"; };
    bool files = false;
    for (const auto& c : scene.clay) files |= readWithUp(c.shape);
    for (const auto& t : scene.tools) files |= readWithUp(t.shape);
    for (const auto& o : scene.obstacles) files |= readWithUp(o);
    if (files) {
        throw vdbclay::Error("--up " + up + ": " + scene.source + " reads its meshes and level sets with up " +
                             vdbclay::upAxisName(scene.up) + "; set \"up\": \"" + up + "\" in the scene instead");
    }
    scene.up = axis;
}

// ---- interrupts -----------------------------------------------------------------------------------
// SIGINT and SIGTERM only set this flag (a lock-free atomic store is async-signal-safe); the run
// polls it between automaton steps, stops where a checkpoint resumes exactly, and writes one.

std::atomic<int> gStopSignal{0};
static_assert(std::atomic<int>::is_always_lock_free, "the signal flag must be lock-free");

extern "C" void onStopSignal(int sig) { gStopSignal.store(sig, std::memory_order_relaxed); }

/// Catches SIGINT and SIGTERM for the run. SA_RESETHAND: a second signal kills at once. A SIGINT
/// the caller ignores (a background job of a script) stays ignored.
void catchStopSignals()
{
    struct sigaction sa;
    std::memset(&sa, 0, sizeof sa);
    sa.sa_handler = onStopSignal;
    sigemptyset(&sa.sa_mask);
    sa.sa_flags = SA_RESETHAND | SA_RESTART; // no EINTR in the middle of writing a file
    for (int sig : {SIGINT, SIGTERM}) {
        struct sigaction old;
        if (::sigaction(sig, nullptr, &old) == 0 && sig == SIGINT && old.sa_handler == SIG_IGN) continue;
        ::sigaction(sig, &sa, nullptr);
    }
}

/// For tests that must interrupt a run at a known point, not after a guessed delay:
/// VDBCLAY_TEST_RAISE=SIGNAL@STEP (SIGNAL INT or TERM) makes the run send itself that signal, through
/// the same handler as a real one, once the automaton's step count (counted from the run's first
/// step, resumed runs included) reaches STEP. Returns a poll that does so; an empty one when unset.
/// @throw Error if the variable is set but malformed.
std::function<void(uint64_t)> testSignalAtStep()
{
    const char* spec = std::getenv("VDBCLAY_TEST_RAISE");
    if (!spec || !*spec) return {};
    const std::string s(spec);
    const size_t at = s.find('@');
    const std::string name = s.substr(0, at);
    const int sig = name == "INT" ? SIGINT : (name == "TERM" ? SIGTERM : 0);
    char* end = nullptr;
    errno = 0;
    const unsigned long long step = at == std::string::npos ? 0 : std::strtoull(s.c_str() + at + 1, &end, 10);
    if (sig == 0 || at == std::string::npos || at + 1 == s.size() || *end != '\0' || errno != 0 ||
        s[at + 1] == '-') {
        throw vdbclay::Error("VDBCLAY_TEST_RAISE: expected SIGNAL@STEP with SIGNAL INT or TERM, e.g. INT@1000");
    }
    auto raised = std::make_shared<bool>(false);
    return [sig, step, raised](uint64_t steps) {
        if (*raised || steps < step) return;
        *raised = true;
        ::raise(sig);
    };
}

/// "out.vdb" -> "out.checkpoint.vdb": where an interrupted run saves itself by default.
std::string defaultCheckpointPath(const std::string& outVdb)
{
    if (outVdb.empty()) return "";
    const size_t slash = outVdb.find_last_of('/');
    const size_t dot = outVdb.find_last_of('.');
    const bool hasExt = dot != std::string::npos && (slash == std::string::npos || dot > slash);
    return (hasExt ? outVdb.substr(0, dot) : outVdb) + ".checkpoint.vdb";
}

/// --resume continues a run of the same scene: refuse a file written with other parameters, whose
/// continuation would not be the run it was cut from.
void checkResumeFits(const vdbclay::Scene& scene, const vdbclay::ClayMeta& m, const std::string& path)
{
    auto differs = [&](const char* what, const std::string& file, const std::string& here) {
        throw vdbclay::Error("--resume " + path + ": it was written with " + what + " " + file + " but " +
                             scene.source + " has " + here + " (give the same scene and options as the run it came from)");
    };
    if (m.version.empty()) throw vdbclay::Error("--resume " + path + ": not written by vdbclay (no vdbclay metadata)");
    if (m.dimensions != scene.dimensions) differs("dimensions", std::to_string(m.dimensions), std::to_string(scene.dimensions));
    if (m.rule.rule != scene.rule.rule) differs("rule", vdbclay::ruleName(m.rule.rule), vdbclay::ruleName(scene.rule.rule));
    if (m.rule.threshold != scene.rule.threshold) differs("Tc", std::to_string(m.rule.threshold), std::to_string(scene.rule.threshold));
    if (m.seed != scene.seed) differs("seed", std::to_string(m.seed), std::to_string(scene.seed));
    if (m.frames > scene.frames) {
        differs("frames", std::to_string(m.frames) + " done", std::to_string(scene.frames) + " frames");
    }
}

/// After a stop request: writes the checkpoint (or nothing when no step ran or there is nowhere to
/// write it), says so in one line on stderr, returns 128 + the signal number.
int finishInterrupted(vdbclay::Sculptor& sculptor, const RunArgs& a, const std::string& checkpoint,
                      uint64_t frame0, uint64_t steps0, bool tty)
{
    const int sig = gStopSignal.load();
    const char* name = sig == SIGINT ? "SIGINT" : (sig == SIGTERM ? "SIGTERM" : "a signal");
    const uint64_t steps = sculptor.automaton().stepCount();
    const vdbclay::ClayMeta meta = sculptor.checkpointMeta();
    const std::string where = meta.frameSteps
                            ? "in frame " + std::to_string(meta.frames + 1) + "/" + std::to_string(sculptor.totalFrames()) +
                                  " after " + std::to_string(meta.frameSteps) + " of its settling steps"
                            : "after frame " + std::to_string(meta.frames) + "/" + std::to_string(sculptor.totalFrames());
    if (tty) std::fprintf(stderr, "\n");
    std::fflush(stdout);
    if (sculptor.frame() == frame0 && steps == steps0) {
        std::fprintf(stderr, "vdbclay: interrupted by %s before any step; nothing written\n", name);
    } else if (checkpoint.empty()) {
        std::fprintf(stderr, "vdbclay: interrupted by %s %s (step %llu); no checkpoint written (give -o or --checkpoint)\n",
                     name, where.c_str(), (unsigned long long)steps);
    } else {
        try {
            vdbclay::writeClayFile(checkpoint, *sculptor.mass(), meta);
            const std::string scene = a.scene.empty() ? "" : " " + a.scene;
            std::fprintf(stderr, "vdbclay: interrupted by %s %s (step %llu); checkpoint written to %s "
                                 "(continue: vdbclay run%s --resume %s)\n",
                         name, where.c_str(), (unsigned long long)steps, checkpoint.c_str(), scene.c_str(), checkpoint.c_str());
        } catch (const std::exception& e) {
            std::fprintf(stderr, "vdbclay: interrupted by %s %s; no checkpoint written: %s\n", name, where.c_str(), e.what());
        }
    }
    return 128 + (sig > 0 ? sig : SIGINT);
}

int runScene(const RunArgs& a)
{
    vdbclay::Scene scene = a.scene.empty() ? vdbclay::defaultScene() : vdbclay::loadScene(a.scene);
    if (!a.rule.empty()) scene.rule.rule = vdbclay::parseRule(a.rule);
    if (a.seed >= 0) scene.seed = uint64_t(a.seed);
    if (!a.push.empty()) {
        try {
            scene.push = vdbclay::parsePushMode(a.push);
        } catch (const vdbclay::Error& e) {
            throw vdbclay::Error(std::string("--push: ") + e.what());
        }
    }
    if (!a.transport.empty()) {
        try {
            scene.transport = vdbclay::parseTransport(a.transport);
        } catch (const vdbclay::Error& e) {
            throw vdbclay::Error(std::string("--transport: ") + e.what());
        }
    }
    if (!a.sweep.empty()) {
        if (a.sweep != "on" && a.sweep != "off") {
            throw vdbclay::Error("--sweep: expected on or off, got \"" + a.sweep + "\"");
        }
        scene.sweep = a.sweep == "on";
    }
    if (!a.resume.empty()) scene.start = a.resume; // relative to the current directory
    applyUp(scene, a.up);
    if (!a.memoryBudget.empty()) {
        try {
            scene.memoryBudget = vdbclay::parseByteSize(a.memoryBudget);
        } catch (const vdbclay::Error& e) {
            throw vdbclay::Error(std::string("--memory-budget: ") + e.what());
        }
    }
    const std::string outVdb = a.out.empty() ? scene.outputs.vdb : a.out;
    const std::string outStats = a.stats.empty() ? scene.outputs.stats : a.stats;
    const std::string outPng = a.png.empty() ? scene.outputs.png : a.png;
    const std::string outMesh = a.mesh.empty() ? scene.outputs.mesh : a.mesh;
    const std::string checkpoint = a.checkpoint.empty() ? defaultCheckpointPath(outVdb) : a.checkpoint;

    vdbclay::Sculptor sculptor(scene, a.threads);
    if (!a.resume.empty()) checkResumeFits(scene, sculptor.startMeta(), a.resume);
    const bool tty = ::isatty(2) && !a.quiet;
    for (const std::string* o : {&outVdb, &outStats, &outPng, &outMesh, &checkpoint}) checkWritable(*o);
    // From here on SIGINT/SIGTERM stop the run at the next step and save it; before, there is
    // nothing to save and they end the process as usual.
    catchStopSignals();
    if (!a.quiet) std::cout << "vdbclay: " << scene.source << ": " << scene.dimensions << "D, Tc " << scene.rule.threshold
              << ", rule " << vdbclay::ruleName(scene.rule.rule) << ", " << scene.clay.size() << " clay, "
              << scene.tools.size() << " tools, " << scene.obstacles.size() << " obstacles, frames "
              << sculptor.frame() + 1 << ".." << sculptor.totalFrames() << "\n";
    const bool paperModel = scene.push == vdbclay::PushMode::Surface && scene.transport == vdbclay::Transport::Local;
    if (!a.quiet && (!paperModel || scene.sweep))
        std::cout << "push " << vdbclay::pushModeName(scene.push) << (scene.sweep ? " (swept)" : "") << ", transport "
                  << vdbclay::transportName(scene.transport) << "\n";
    if (!a.quiet) {
        const uint64_t budget = scene.memoryBudget ? scene.memoryBudget : vdbclay::defaultMemoryBudget();
        std::cout << "memory: " << vdbclay::estimateSceneMemory(scene).describe() << "; budget "
                  << (budget == vdbclay::kNoMemoryBudget ? std::string("none") : vdbclay::formatBytes(budget)) << "\n";
    }
    std::cout.flush();
    const uint64_t total = sculptor.totalFrames();
    auto onFrame = [&](const vdbclay::FrameReport& r) {
        if (a.quiet) return;
        if (tty) {
            const int width = 30;
            const int done = int(double(width) * double(r.frame) / double(std::max<uint64_t>(total, 1)));
            std::fprintf(stderr, "\r[%s%s] frame %llu/%llu  steps %llu  overload %lld   ",
                         std::string(done, '#').c_str(), std::string(width - done, '.').c_str(),
                         (unsigned long long)r.frame, (unsigned long long)total,
                         (unsigned long long)r.settle.steps, (long long)r.settle.residualOverload);
            if (r.frame == total && r.finished) std::fprintf(stderr, "\n");
        } else {
            std::printf("frame %llu/%llu: pushed %llu voxels (%lld clay, %lld trapped), %llu steps (%s), "
                         "residual overload %lld\n",
                         (unsigned long long)r.frame, (unsigned long long)total,
                         (unsigned long long)r.push.voxelsPushed, (long long)r.push.massMoved,
                         (long long)r.push.massTrapped, (unsigned long long)r.settle.steps,
                         r.finished ? vdbclay::stopReasonName(r.settle.reason) : "interrupted",
                         (long long)r.settle.residualOverload);
            std::fflush(stdout); // a log file follows the run frame by frame
        }
    };
    const uint64_t frame0 = sculptor.frame(), steps0 = sculptor.automaton().stepCount();
    const std::function<void(uint64_t)> testSignal = testSignalAtStep();
    vdbclay::Automaton& automaton = sculptor.automaton();
    sculptor.setStopRequest([&testSignal, &automaton] {
        if (testSignal) testSignal(automaton.stepCount());
        return gStopSignal.load(std::memory_order_relaxed) != 0;
    });
    const vdbclay::RunSummary s = sculptor.run(a.frames, onFrame);
    sculptor.setStopRequest({});
    if (sculptor.stopped()) return finishInterrupted(sculptor, a, checkpoint, frame0, steps0, tty);
    const bool exact = s.massFinal == s.massInitial;
    std::printf("frames %llu, steps %llu, time %s (push %s, settle %s)\n", (unsigned long long)s.frames,
                (unsigned long long)s.steps, fmtSeconds(s.seconds).c_str(), fmtSeconds(s.pushSeconds).c_str(),
                fmtSeconds(s.stages.total()).c_str());
    std::printf("mass before %lld, after %lld (%s); residual overload %lld; settled %s", (long long)s.massInitial,
                (long long)s.massFinal, exact ? "exact" : "DRIFT", (long long)s.residualOverload,
                s.settled ? "yes" : "no");
    if (s.framesUnsettled > s.framesNoRoom) {
        std::printf(" (%llu frames hit the step budget)", (unsigned long long)(s.framesUnsettled - s.framesNoRoom));
    }
    if (s.framesNoRoom) std::printf(" (%llu frames had no room for their overload)", (unsigned long long)s.framesNoRoom);
    if (s.massTrapped) std::printf("; %lld clay trapped in tools", (long long)s.massTrapped);
    std::printf("\n");
    if (scene.transport == vdbclay::Transport::Global) {
        std::printf("global transport: %s, %llu solves, %llu CG iterations, %lld clay routed%s\n",
                    fmtSeconds(s.transportSeconds).c_str(), (unsigned long long)s.transportSolves,
                    (unsigned long long)s.transportIterations, (long long)s.transportMassMoved,
                    s.framesTransportNoRoom ? " (some clay walled in with no room)" : "");
    }
    std::printf("clay %llu voxels, %llu interior (mean density %.4f, heterogeneity CV %.4f), compaction %.4f\n",
                (unsigned long long)s.metrics.clayVoxels, (unsigned long long)s.metrics.interiorCells,
                s.metrics.interiorMeanDensity, s.metrics.heterogeneityCV, s.metrics.compaction);

    if (!outVdb.empty()) {
        vdbclay::writeClayFile(outVdb, *sculptor.mass(), sculptor.checkpointMeta());
        std::printf("wrote %s\n", outVdb.c_str());
    }
    if (!outPng.empty()) {
        vdbclay::renderPng(outPng, *sculptor.mass(), scene.rule.threshold, scene.dimensions);
        std::printf("wrote %s\n", outPng.c_str());
    }
    if (!outMesh.empty()) {
        vdbclay::writeSurfaceMesh(outMesh, *sculptor.mass(), scene.rule.threshold);
        std::printf("wrote %s\n", outMesh.c_str());
    }
    if (!outStats.empty()) {
        nlohmann::json j;
        j["scene"] = scene.source;
        j["rule"] = vdbclay::ruleName(scene.rule.rule);
        j["threshold"] = scene.rule.threshold;
        j["threads"] = a.threads;
        j["frames"] = s.frames;
        j["steps"] = s.steps;
        j["seconds"] = s.seconds;
        j["push_seconds"] = s.pushSeconds;
        j["push"] = vdbclay::pushModeName(scene.push);
        j["sweep"] = scene.sweep;
        j["transport"] = vdbclay::transportName(scene.transport);
        j["transport_seconds"] = s.transportSeconds;
        j["transport_solves"] = s.transportSolves;
        j["transport_iterations"] = s.transportIterations;
        j["transport_mass_moved"] = s.transportMassMoved;
        j["frames_transport_no_room"] = s.framesTransportNoRoom;
        j["stage_seconds"] = {{"gather", s.stages.gather}, {"repartition", s.stages.repartition},
                              {"grow", s.stages.grow}, {"bookkeeping", s.stages.bookkeeping}};
        j["mass_initial"] = s.massInitial;
        j["mass_final"] = s.massFinal;
        j["residual_overload"] = s.residualOverload;
        j["settled"] = s.settled;
        j["frames_unsettled"] = s.framesUnsettled;
        j["mass_trapped"] = s.massTrapped;
        j["blocks_visited"] = s.blocksVisited;
        j["blocks_updated"] = s.blocksUpdated;
        j["clay_voxels"] = vdbclay::clayVoxelCount(*sculptor.mass());
        j["frames_no_room"] = s.framesNoRoom;
        j["mass_drift"] = s.massDrift;
        j["max_cell"] = s.metrics.maxCell;
        j["occupied_voxels"] = s.metrics.occupiedVoxels;
        j["interior_cells"] = s.metrics.interiorCells;
        j["interior_mean_density"] = s.metrics.interiorMeanDensity;
        j["heterogeneity_cv"] = s.metrics.heterogeneityCV;
        j["compaction"] = s.metrics.compaction;
        writeTextAtomically(outStats, j.dump(2) + "\n");
        std::printf("wrote %s\n", outStats.c_str());
    }
    if (!exact) {
        std::fprintf(stderr, "vdbclay: error: mass changed from %lld to %lld\n", (long long)s.massInitial,
                     (long long)s.massFinal);
        return 3;
    }
    return 0;
}

int info(const std::string& path)
{
    std::cout << vdbclay::describeVdb(path);
    return 0;
}

int32_t thresholdOf(const vdbclay::ClayFile& f, int32_t override)
{
    if (override > 0) return override;
    return f.meta.rule.threshold;
}

} // namespace

int main(int argc, char** argv)
{
    CLI::App app{"vdbclay: virtual clay in sparse OpenVDB volumes (Druon, Crosnier, Brigandat 2003)"};
    app.require_subcommand(1);

    RunArgs ra;
    CLI::App* run = app.add_subcommand("run", "Run a scene file (or, with none, the built-in default scene)");
    run->add_option("scene", ra.scene, "scene JSON file (see docs/SCENES.md); omitted: the built-in scene");
    run->add_option("-o,--output", ra.out, "write the clay to this .vdb (mass, density, surface grids)");
    run->add_option("--threads", ra.threads, "worker threads; 0 = all cores")->check(CLI::NonNegativeNumber);
    run->add_option("--rule", ra.rule, "override the scene's rule: arata, bingham, sorted, prorata");
    run->add_option("--seed", ra.seed, "override the scene's seed")->check(CLI::NonNegativeNumber);
    run->add_option("--stats", ra.stats, "write run statistics as JSON to this file");
    run->add_option("--png", ra.png, "also render the result to this PNG");
    run->add_option("--mesh", ra.mesh, "also write the clay surface to this .obj or .ply");
    run->add_option("--frames", ra.frames, "stop after this many frames (the output can be continued with \"start\")");
    run->add_flag("-q,--quiet", ra.quiet, "no progress output");
    run->add_option("--up", ra.up, "y or z: the up axis of the output .vdb's transform and mesh (Blender: z)");
    run->add_option("--checkpoint", ra.checkpoint,
                    "on SIGINT/SIGTERM, save the run here (default: OUT.checkpoint.vdb beside -o OUT.vdb)");
    run->add_option("--resume", ra.resume, "continue an interrupted run from its checkpoint (same scene and options)");
    run->add_option("--push", ra.push, "override the scene's push: surface (the paper's) or compress");
    run->add_option("--transport", ra.transport,
                    "override the scene's transport: local (the paper's automaton) or global");
    run->add_option("--sweep", ra.sweep, "override the scene's sweep: on (push over the volume a tool sweeps) or off");
    run->add_option("--memory-budget", ra.memoryBudget,
                    "refuse a scene estimated to need more, e.g. 8G, 512M, none (default: 3/4 of memory)");

    std::string infoPath;
    CLI::App* inf = app.add_subcommand("info", "Describe a .vdb file: grids, voxels, bounds, total mass, metadata");
    inf->add_option("file", infoPath, "a .vdb file")->required();

    std::string meshIn, meshOut;
    double iso = 0.5;
    int32_t meshTc = 0;
    CLI::App* mesh = app.add_subcommand("mesh", "Write the clay surface of a clay .vdb as OBJ or PLY");
    mesh->add_option("file", meshIn, "a clay .vdb (grid \"mass\")")->required();
    mesh->add_option("-o,--output", meshOut, "OUT.obj or OUT.ply")->required();
    mesh->add_option("--isovalue", iso, "surface where density (mass / Tc) equals this (default 0.5)");
    mesh->add_option("--threshold", meshTc, "Tc, if the file does not record it");
    std::string meshUp;
    mesh->add_option("--up", meshUp, "y or z: orient the mesh for this up axis (default: the file's)");

    std::string renIn, renOut;
    vdbclay::RenderOptions ro;
    int renDims = 0;
    int32_t renTc = 0;
    CLI::App* ren = app.add_subcommand("render", "Render a clay .vdb to PNG (2D density map or 3D shaded surface)");
    ren->add_option("file", renIn, "a clay .vdb (grid \"mass\")")->required();
    ren->add_option("-o,--output", renOut, "OUT.png")->required();
    ren->add_option("--width", ro.width, "image width")->check(CLI::PositiveNumber);
    ren->add_option("--height", ro.height, "image height")->check(CLI::PositiveNumber);
    ren->add_option("--azimuth", ro.azimuthDeg, "3D camera azimuth, degrees");
    ren->add_option("--elevation", ro.elevationDeg, "3D camera elevation, degrees");
    ren->add_option("--dims", renDims, "2 or 3, if the file does not record it")->check(CLI::Range(2, 3));
    ren->add_option("--threshold", renTc, "Tc, if the file does not record it");

    std::string impIn, impOut;
    int64_t impMass = 0;
    double impVoxel = 0; // 0: the level set's own voxel size, or 1 for meshes
    int impDims = 3;
    CLI::App* imp = app.add_subcommand("import", "Turn a closed mesh (OBJ/STL) or a level set .vdb into clay");
    imp->add_option("file", impIn, "MESH.obj, MESH.stl or LEVELSET.vdb")->required();
    imp->add_option("-o,--output", impOut, "CLAY.vdb")->required();
    imp->add_option("--mass", impMass, "clay per voxel inside the shape")->required();
    imp->add_option("--voxel-size", impVoxel,
                    "world units per voxel (default: a level set's own voxel size; 1 for meshes)");
    std::string impGrid;
    imp->add_option("--grid", impGrid, "LEVELSET.vdb: the level set grid to import (default: the first)");
    imp->add_option("--dims", impDims, "2 (keep the z = 0 layer) or 3")->check(CLI::Range(2, 3));
    std::string impUp = "y";
    imp->add_option("--up", impUp, "y or z: the input's up axis, also written into the clay's transform");

    DemoArgs da;
    std::string demoRule;
    CLI::App* demo = app.add_subcommand("demo", "Settle a built-in overloaded lump of clay (the automaton alone)");
    demo->add_option("--size", da.size, "cube edge in voxels")->check(CLI::Range(2, 4096));
    demo->add_option("--overload", da.overload, "the core holds this many times Tc per voxel")->check(CLI::Range(1, 1000));
    demo->add_option("--rule", demoRule, "arata, bingham, sorted, prorata");
    demo->add_option("--threshold", da.opts.rule.threshold, "Tc")->check(CLI::PositiveNumber);
    demo->add_option("--alpha", da.opts.rule.alpha, "arata's rate in (0,1)");
    demo->add_option("--dims", da.opts.dimensions, "2 or 3")->check(CLI::Range(2, 3));
    demo->add_option("--threads", da.opts.threads, "worker threads, 0 = all")->check(CLI::NonNegativeNumber);
    demo->add_option("--seed", da.opts.seed, "remainder hash seed");
    demo->add_option("--max-steps", da.maxSteps, "step budget");
    demo->add_option("-o,--output", da.out, "write the settled clay to this .vdb");

    try {
        app.parse(argc, argv);
    } catch (const CLI::ParseError& e) {
        if (e.get_exit_code() == 0) return app.exit(e); // --help
        std::cerr << "vdbclay: error: " << e.what() << " (see vdbclay --help)\n";
        return e.get_exit_code();
    }
    try {
        openvdb::initialize();
        if (*run) return runScene(ra);
        if (*inf) return info(infoPath);
        if (*mesh) {
            const vdbclay::ClayFile f = vdbclay::readClayFile(meshIn);
            if (!meshUp.empty()) vdbclay::setClayTransform(*f.mass, f.meta.voxelSize, upOption(meshUp));
            vdbclay::writeSurfaceMesh(meshOut, *f.mass, thresholdOf(f, meshTc), iso);
            std::printf("wrote %s\n", meshOut.c_str());
            return 0;
        }
        if (*ren) {
            const vdbclay::ClayFile f = vdbclay::readClayFile(renIn);
            const int dims = renDims ? renDims : f.meta.dimensions;
            vdbclay::renderPng(renOut, *f.mass, thresholdOf(f, renTc), dims, ro);
            std::printf("wrote %s\n", renOut.c_str());
            return 0;
        }
        if (*imp) {
            if (impMass <= 0 || impMass > INT32_MAX) {
                throw vdbclay::Error("--mass must be in [1, " + std::to_string(INT32_MAX) + "], got " +
                                     std::to_string(impMass));
            }
            if (!(impVoxel >= 0) || !std::isfinite(impVoxel)) throw vdbclay::Error("--voxel-size must be > 0");
            const bool isVdb = impIn.size() > 4 && impIn.compare(impIn.size() - 4, 4, ".vdb") == 0;
            if (!isVdb && !impGrid.empty()) throw vdbclay::Error("--grid: only for a level set .vdb, not " + impIn);
            if (impVoxel == 0 && isVdb) {
                // The level set's own voxel size; loadLevelSet checks the file before OpenVDB reads it.
                vdbclay::loadLevelSet(impIn, 1.0, impGrid, upOption(impUp));
                openvdb::io::File f(impIn);
                f.open(false);
                std::string name = impGrid;
                if (name.empty()) {
                    for (const auto& g : *f.readAllGridMetadata()) {
                        if (g->getGridClass() == openvdb::GRID_LEVEL_SET && g->isType<openvdb::FloatGrid>()) {
                            name = g->getName();
                            break;
                        }
                    }
                }
                impVoxel = f.readGridMetadata(name)->voxelSize()[0];
                f.close();
            }
            if (impVoxel == 0) impVoxel = 1.0;
            const vdbclay::ShapePtr shape =
                isVdb ? vdbclay::loadLevelSet(impIn, impVoxel, impGrid, upOption(impUp))
                      : vdbclay::loadMesh(impIn, impVoxel, upOption(impUp));
            const vdbclay::MassGridPtr clay = vdbclay::makeClay(*shape, int32_t(impMass), impDims);
            vdbclay::ClayMeta meta;
            meta.dimensions = impDims;
            meta.voxelSize = impVoxel;
            meta.up = upOption(impUp);
            vdbclay::writeClayFile(impOut, *clay, meta);
            if (shape->describe().find("winding number") != std::string::npos) {
                std::printf("note: %s\n", shape->describe().c_str()); // open or non-manifold: how it was filled
            }
            std::printf("wrote %s: %llu voxels, mass %lld\n", impOut.c_str(),
                        (unsigned long long)vdbclay::clayVoxelCount(*clay), (long long)vdbclay::totalMass(*clay));
            return 0;
        }
        if (*demo) {
            if (!demoRule.empty()) da.opts.rule.rule = vdbclay::parseRule(demoRule);
            vdbclay::validate(da.opts.rule);
            if (int64_t(da.overload) * da.opts.rule.threshold > INT32_MAX) {
                throw vdbclay::Error("--overload x --threshold exceeds the int32 range of a cell");
            }
            return runDemo(da);
        }
    } catch (const std::exception& e) {
        std::cerr << "vdbclay: error: " << e.what() << "\n";
        return 1;
    }
    return 0;
}
