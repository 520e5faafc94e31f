// vdbclay run: a scene file (or the built-in scene) frame by frame, then its outputs (.vdb, picture,
// mesh, the run's report). SIGINT/SIGTERM and an outgrown memory budget stop it with a checkpoint
// that --resume continues exactly.
#include "cli.h"

#include "vdbclay/AtomicWrite.h"
#include "vdbclay/BatchHeap.h"
#include "vdbclay/IO.h"
#include "vdbclay/MemoryEstimate.h"
#include "vdbclay/Render.h"
#include "vdbclay/RunReport.h"
#include "vdbclay/Scene.h"
#include "vdbclay/Sculpt.h"
#include "vdbclay/SurfaceMesh.h"

#include <signal.h>
#include <tbb/global_control.h>
#include <unistd.h>

#include <algorithm>
#include <cerrno>
#include <chrono>
#include <climits>
#include <cstdio>
#include <cstdlib>
#include <iostream>
#include <memory>
#include <string>
#include <vector>

namespace vdbclay_cli {
namespace {

using Clock = std::chrono::steady_clock;

struct RunArgs {
    std::string scene, out, stats, png, mesh, rule, checkpoint, resume, memoryBudget, push, transport, sweep;
    int threads = 0;
    int64_t seed = -1;
    int64_t frames = 0; ///< 0: all
    int64_t every = 0;  ///< --every: 0 when not given (every frame)
    bool quiet = false;
    bool sceneOutputsAnywhere = false; ///< --scene-outputs-anywhere
    std::string up;                    ///< --up: empty keeps the scene's
    std::string grids;                 ///< --grids: empty keeps the scene's
};

/// Where a run writes: the options' files, else the scene's outputs; the checkpoint's default
/// beside -o.
struct RunOutputs {
    std::string vdb, stats, png, mesh, checkpoint;
    uint64_t every = 1; ///< sequences write every this many frames (and the last)
};

/// The run of '#' characters in an output's file name that makes it a sequence ("clay.####.vdb"):
/// where it starts and how many; width 0 when the name has none.
struct FramePattern {
    size_t pos = 0, width = 0;
};

/// @a o's frame pattern. @throw Error if its file name holds '#' in more than one run.
FramePattern framePatternOf(const FileArg& o)
{
    const size_t slash = o.path.find_last_of('/');
    const size_t nameStart = slash == std::string::npos ? 0 : slash + 1;
    const size_t first = o.path.find('#', nameStart);
    if (first == std::string::npos) return {};
    const size_t end = std::min(o.path.find_first_not_of('#', first), o.path.size());
    if (o.path.find('#', end) != std::string::npos) {
        throw vdbclay::Error(o.text() +
                             ": more than one run of '#' in the file name; one run (e.g. clay.####.vdb) "
                             "stands for the frame number");
    }
    return {first, end - first};
}

/// @a path with its frame pattern @a p replaced by @a frame, zero-padded to the pattern's width.
std::string frameFile(const std::string& path, FramePattern p, uint64_t frame)
{
    std::string n = std::to_string(frame);
    if (n.size() < p.width) n.insert(0, p.width - n.size(), '0');
    return path.substr(0, p.pos) + n + path.substr(p.pos + p.width);
}

/// A sequence's name without its frame pattern ("clay.####.vdb" -> "clay.vdb"), for the default
/// checkpoint beside it.
std::string withoutFramePattern(const std::string& path, FramePattern p)
{
    std::string base = path.substr(0, p.pos);
    std::string rest = path.substr(p.pos + p.width);
    if (!base.empty() && !rest.empty() && base.back() == '.' && rest.front() == '.') rest.erase(0, 1);
    return base + rest;
}

double secondsSince(Clock::time_point t0)
{
    return std::chrono::duration<double>(Clock::now() - t0).count();
}

std::string fmtSeconds(double s)
{
    char buf[32];
    std::snprintf(buf, sizeof buf, "%.3f s", s);
    return buf;
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
    for (const auto& c : scene.clay)
        files |= readWithUp(c.shape);
    for (const auto& t : scene.tools)
        files |= readWithUp(t.shape);
    for (const auto& o : scene.obstacles)
        files |= readWithUp(o);
    if (files) {
        throw vdbclay::Error("--up " + up + ": " + scene.source +
                             " reads its meshes and level sets with up " + vdbclay::upAxisName(scene.up) +
                             "; set \"up\": \"" + up + "\" in the scene instead");
    }
    scene.up = axis;
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
        throw vdbclay::Error(
            "VDBCLAY_TEST_RAISE: expected SIGNAL@STEP with SIGNAL INT or TERM, e.g. INT@1000");
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
                             scene.source + " has " + here +
                             " (give the same scene and options as the run it came from)");
    };
    if (m.version.empty())
        throw vdbclay::Error("--resume " + path + ": not written by vdbclay (no vdbclay metadata)");
    if (m.dimensions != scene.dimensions)
        differs("dimensions", std::to_string(m.dimensions), std::to_string(scene.dimensions));
    if (m.rule.rule != scene.rule.rule)
        differs("rule", vdbclay::ruleName(m.rule.rule), vdbclay::ruleName(scene.rule.rule));
    if (m.rule.threshold != scene.rule.threshold)
        differs("Tc", std::to_string(m.rule.threshold), std::to_string(scene.rule.threshold));
    if (m.seed != scene.seed) differs("seed", std::to_string(m.seed), std::to_string(scene.seed));
    if (m.frames > scene.frames) {
        differs("frames", std::to_string(m.frames) + " done", std::to_string(scene.frames) + " frames");
    }
}

/// @a word quoted for a POSIX shell where it needs to be.
std::string shellWord(const std::string& word)
{
    const bool plain =
        !word.empty() && word.find_first_not_of("abcdefghijklmnopqrstuvwxyzABCDEFGHIJKLMNOPQRSTUVWXYZ"
                                                "0123456789_-+=./,:@%") == std::string::npos;
    if (plain) return word;
    std::string out = "'";
    for (char c : word)
        out += c == '\'' ? std::string("'\\''") : std::string(1, c);
    return out + "'";
}

/// The command that continues an interrupted run from @a checkpoint and writes what the
/// interrupted one would have: the same scene, the options that shaped the result or name its
/// outputs, and --resume.
std::string continueCommand(const RunArgs& a, const std::string& checkpoint)
{
    std::string cmd = "vdbclay run";
    if (!a.scene.empty()) cmd += " " + shellWord(a.scene);
    auto opt = [&](const char* name, const std::string& value) {
        if (!value.empty()) cmd += std::string(" ") + name + " " + shellWord(value);
    };
    opt("--resume", checkpoint);
    opt("-o", a.out);
    opt("--stats", a.stats);
    opt("--png", a.png);
    opt("--mesh", a.mesh);
    if (a.every > 0) opt("--every", std::to_string(a.every));
    opt("--rule", a.rule);
    if (a.seed >= 0) opt("--seed", std::to_string(a.seed));
    opt("--memory-budget", a.memoryBudget);
    opt("--checkpoint", a.checkpoint);
    if (a.threads) opt("--threads", std::to_string(a.threads));
    if (a.quiet) cmd += " --quiet";
    if (a.sceneOutputsAnywhere) cmd += " --scene-outputs-anywhere";
    return cmd;
}

/// Why the run stopped early, as its one line on stderr begins: the memory budget, or the signal.
std::string stopCause(const vdbclay::Sculptor& sculptor)
{
    if (const uint64_t needs = sculptor.outgrewBudget()) {
        return "stopped: the clay outgrew the memory budget of " +
               vdbclay::formatBytes(sculptor.memoryBudget()) + " (it needs about " +
               vdbclay::formatBytes(needs) + " now; raise --memory-budget to go on)";
    }
    const int sig = gStopSignal.load();
    return std::string("interrupted by ") +
           (sig == SIGINT ? "SIGINT" : (sig == SIGTERM ? "SIGTERM" : "a signal"));
}

/// After the run stopped early: writes the checkpoint (or nothing when no step ran or there is
/// nowhere to write it), says so in one line on stderr. Returns 1 when the memory budget stopped
/// the run, else 128 + the signal number.
int finishStopped(vdbclay::Sculptor& sculptor, const RunArgs& a, const std::string& checkpoint,
                  uint64_t frame0, uint64_t steps0, bool tty)
{
    const std::string cause = stopCause(sculptor);
    const char* name = cause.c_str();
    const uint64_t steps = sculptor.automaton().stepCount();
    const vdbclay::ClayMeta meta = sculptor.checkpointMeta();
    const std::string where =
        meta.frameSteps
            ? "in frame " + std::to_string(meta.frames + 1) + "/" + std::to_string(sculptor.totalFrames()) +
                  " after " + std::to_string(meta.frameSteps) + " of its settling steps"
            : "after frame " + std::to_string(meta.frames) + "/" + std::to_string(sculptor.totalFrames());
    if (tty) std::fprintf(stderr, "\n");
    std::fflush(stdout);
    if (sculptor.frame() == frame0 && steps == steps0) {
        std::fprintf(stderr, "vdbclay: %s before any step; nothing written\n", name);
    } else if (checkpoint.empty()) {
        std::fprintf(stderr, "vdbclay: %s %s (step %llu); no checkpoint written (give -o or --checkpoint)\n",
                     name, where.c_str(), (unsigned long long)steps);
    } else {
        try {
            // The mass alone: what --resume reads, in a second at any size (the surface's sweep of a
            // 2048-wide model would keep the interrupted user waiting 20 s).
            vdbclay::writeClayFile(checkpoint, *sculptor.mass(), meta,
                                   vdbclay::ClayGrids{true, false, false});
            std::fprintf(stderr,
                         "vdbclay: %s %s (step %llu); checkpoint written to %s "
                         "(continue: %s)\n",
                         name, where.c_str(), (unsigned long long)steps, printable(checkpoint).c_str(),
                         printable(continueCommand(a, checkpoint)).c_str());
        } catch (const std::exception& e) {
            std::fprintf(stderr, "vdbclay: %s %s; no checkpoint written: %s\n", name, where.c_str(),
                         printable(e.what()).c_str());
        }
    }
    if (sculptor.outgrewBudget()) return 1;
    const int sig = gStopSignal.load();
    return 128 + (sig > 0 ? sig : SIGINT);
}

/// --memory-budget in bytes; 0 when not given.
uint64_t budgetOption(const RunArgs& a)
{
    if (a.memoryBudget.empty()) return 0;
    return parsedOption("--memory-budget", [&] { return vdbclay::parseByteSize(a.memoryBudget); });
}

/// The scene the arguments name (the built-in one without a file), with the options that override
/// it applied. --memory-budget replaces the scene's; meshes are checked against it as they are read.
vdbclay::Scene sceneOf(const RunArgs& a)
{
    const uint64_t cliBudget = budgetOption(a);
    vdbclay::Scene scene = a.scene.empty() ? vdbclay::defaultScene() : vdbclay::loadScene(a.scene, cliBudget);
    if (!a.rule.empty()) scene.rule.rule = parsedOption("--rule", [&] { return vdbclay::parseRule(a.rule); });
    if (a.seed >= 0) scene.seed = uint64_t(a.seed);
    if (!a.push.empty()) scene.push = parsedOption("--push", [&] { return vdbclay::parsePushMode(a.push); });
    if (!a.transport.empty()) {
        scene.transport = parsedOption("--transport", [&] { return vdbclay::parseTransport(a.transport); });
    }
    if (!a.sweep.empty()) {
        if (a.sweep != "on" && a.sweep != "off") {
            throw vdbclay::Error("--sweep: expected on or off, got \"" + a.sweep + "\"");
        }
        scene.sweep = a.sweep == "on";
    }
    if (!a.grids.empty())
        scene.outputs.grids = parsedOption("--grids", [&] { return vdbclay::parseClayGrids(a.grids); });
    if (!a.resume.empty()) scene.start = a.resume; // relative to the current directory
    applyUp(scene, a.up);
    if (cliBudget != 0) scene.memoryBudget = cliBudget;
    return scene;
}

RunOutputs outputsOf(const RunArgs& a, const vdbclay::Scene& scene)
{
    RunOutputs o;
    o.vdb = a.out.empty() ? scene.outputs.vdb : a.out;
    o.stats = a.stats.empty() ? scene.outputs.stats : a.stats;
    o.png = a.png.empty() ? scene.outputs.png : a.png;
    o.mesh = a.mesh.empty() ? scene.outputs.mesh : a.mesh;
    o.every = a.every > 0 ? uint64_t(a.every) : 1;
    const FramePattern vdbFrames = framePatternOf({"-o", o.vdb});
    o.checkpoint =
        a.checkpoint.empty()
            ? defaultCheckpointPath(vdbFrames.width ? withoutFramePattern(o.vdb, vdbFrames) : o.vdb)
            : a.checkpoint;
    return o;
}

/// Every output is checked before any work (a bad one found after an hour's run costs the hour).
void checkRunOutputs(const RunArgs& a, const vdbclay::Scene& scene, const RunOutputs& o)
{
    auto named = [](const char* option, const char* field, const std::string& cli) {
        return cli.empty() ? std::string("the scene's outputs.") + field : std::string(option);
    };
    const std::vector<FileArg> outputs{
        {named("-o", "vdb", a.out), o.vdb},
        {named("--stats", "stats", a.stats), o.stats},
        {named("--png", "png", a.png), o.png},
        {named("--mesh", "mesh", a.mesh), o.mesh},
        {a.checkpoint.empty() ? "the checkpoint" : "--checkpoint", o.checkpoint}};
    std::vector<InputArg> inputs;
    if (!a.scene.empty() && a.scene != "-") inputs.push_back({{"the scene file", a.scene}, {}});
    // The start file may be continued in place: -o and the checkpoint may replace it.
    if (!scene.start.empty()) {
        inputs.push_back({{a.resume.empty() ? "the scene's start file" : "--resume", scene.start},
                          {outputs[0].option, outputs[4].option}});
    }
    auto shapeInputs = [&](const vdbclay::ShapeSpec& sh) {
        if (!sh.file.empty()) inputs.push_back({{"the file of " + sh.field, sh.file}, {}});
    };
    for (const vdbclay::ClaySpec& c : scene.clay)
        shapeInputs(c.shape);
    for (const vdbclay::ToolSpec& t : scene.tools)
        shapeInputs(t.shape);
    for (const vdbclay::ShapeSpec& ob : scene.obstacles)
        shapeInputs(ob);
    // A scene's own outputs (not the command line's) stay inside the current directory.
    const bool fromScene[5] = {a.out.empty(), a.stats.empty(), a.png.empty(), a.mesh.empty(),
                               a.checkpoint.empty() && a.out.empty()};
    if (!a.sceneOutputsAnywhere) {
        for (int i = 0; i < 5; ++i)
            if (fromScene[i]) checkInsideWorkingDirectory(outputs[i], "--scene-outputs-anywhere");
    }
    checkMeshName(outputs[3]);
    // '#' numbers the frames of -o, --png and --mesh; the report and the checkpoint are one file each.
    bool sequence = false;
    for (int i : {0, 2, 3})
        sequence |= framePatternOf(outputs[i]).width > 0;
    for (int i : {1, 4}) {
        if (outputs[i].path.find('#', outputs[i].path.find_last_of('/') + 1) != std::string::npos) {
            throw vdbclay::Error(outputs[i].text() +
                                 ": '#' numbers the frames of -o, --png and --mesh; this output is one file");
        }
    }
    if (a.every > 0 && !sequence) {
        throw vdbclay::Error("--every " + std::to_string(a.every) +
                             ": no output is a sequence (put a run of '#' in the name given to -o, --png or "
                             "--mesh, e.g. clay.####.vdb)");
    }
    checkOutputs(outputs, inputs);
    checkFormatName(outputs[0], ".vdb", "a clay .vdb (OpenVDB)");
    checkFormatName(outputs[2], ".png", "a PNG picture");
    checkFormatName(outputs[4], ".vdb", "a clay .vdb (OpenVDB)");
}

/// The lines a run begins with: the scene, the push and transport when not the paper's, the memory
/// estimate and budget.
void printRunHeader(vdbclay::Sculptor& sculptor)
{
    const vdbclay::Scene& scene = sculptor.scene();
    std::cout << "vdbclay: " << scene.source << ": " << scene.dimensions << "D, Tc " << scene.rule.threshold
              << ", rule " << vdbclay::ruleName(scene.rule.rule) << ", " << scene.clay.size() << " clay, "
              << scene.tools.size() << " tools, " << scene.obstacles.size() << " obstacles, frames "
              << sculptor.frame() + 1 << ".." << sculptor.totalFrames() << "\n";
    const bool paperModel =
        scene.push == vdbclay::PushMode::Surface && scene.transport == vdbclay::Transport::Local;
    if (!paperModel || scene.sweep)
        std::cout << "push " << vdbclay::pushModeName(scene.push) << (scene.sweep ? " (swept)" : "")
                  << ", transport " << vdbclay::transportName(scene.transport) << "\n";
    const uint64_t budget = sculptor.memoryBudget();
    std::cout << "memory: " << sculptor.memoryEstimate().describe() << "; budget "
              << (budget == vdbclay::kNoMemoryBudget ? std::string("none") : vdbclay::formatBytes(budget))
              << "\n";
}

/// After each frame: the heap's growth advised, then (unless --quiet) a progress bar on a terminal,
/// else one line per frame.
std::function<void(const vdbclay::FrameReport&)> frameProgress(bool quiet, bool tty, uint64_t total)
{
    return [=](const vdbclay::FrameReport& r) {
        vdbclay::adviseBatchHeapGrowth(); // the frame may have grown the heap
        if (quiet) return;
        if (tty) {
            const int width = 30;
            const int done = int(double(width) * double(r.frame) / double(std::max<uint64_t>(total, 1)));
            std::fprintf(stderr, "\r[%s%s] frame %llu/%llu  steps %llu  overload %lld   ",
                         std::string(done, '#').c_str(), std::string(width - done, '.').c_str(),
                         (unsigned long long)r.frame, (unsigned long long)total,
                         (unsigned long long)r.settle.steps, (long long)r.settle.residualOverload);
            if (r.frame == total && r.finished) std::fprintf(stderr, "\n");
        } else {
            std::printf("frame %llu/%llu: pushed %llu voxels (%lld clay, %lld trapped), ",
                        (unsigned long long)r.frame, (unsigned long long)total,
                        (unsigned long long)r.push.voxelsPushed, (long long)r.push.massMoved,
                        (long long)r.push.massTrapped);
            if (r.massAdded || r.massRemoved || r.massSmoothed)
                std::printf("added %lld, removed %lld, smoothed %lld, ", (long long)r.massAdded,
                            (long long)r.massRemoved, (long long)r.massSmoothed);
            std::printf("%llu steps (%s), residual overload %lld, %.3f s\n",
                        (unsigned long long)r.settle.steps,
                        r.finished ? vdbclay::stopReasonName(r.settle.reason) : "interrupted",
                        (long long)r.settle.residualOverload, r.seconds);
            std::fflush(stdout); // a log file follows the run frame by frame
        }
    };
}

/// The outputs named as sequences, written as the run's frames finish: every o.every-th frame and
/// the run's last, each file atomically, so that a run stopped at any point leaves whole frames.
class FrameWriter {
public:
    FrameWriter(const RunOutputs& o, uint64_t lastFrame) : mEvery(o.every), mLast(lastFrame)
    {
        add(Kind::Vdb, "-o", o.vdb);
        add(Kind::Png, "--png", o.png);
        add(Kind::Mesh, "--mesh", o.mesh);
    }

    /// True when @a path is one of the sequences (written here, not after the run).
    bool writes(const std::string& path) const
    {
        for (const Sequence& q : mSeqs)
            if (q.path == path) return true;
        return false;
    }

    /// After frame @a frame finished: writes the sequences' files for it when it is due.
    void frameDone(const vdbclay::Sculptor& sculptor, uint64_t frame)
    {
        if (mSeqs.empty() || (frame % mEvery != 0 && frame != mLast)) return;
        const auto t0 = Clock::now();
        const vdbclay::Scene& scene = sculptor.scene();
        for (Sequence& q : mSeqs) {
            const std::string path = frameFile(q.path, q.pattern, frame);
            switch (q.kind) {
            case Kind::Vdb:
                vdbclay::writeClayFile(path, *sculptor.mass(), sculptor.checkpointMeta(),
                                       scene.outputs.grids);
                break;
            case Kind::Png:
                vdbclay::renderPng(path, *sculptor.mass(), scene.rule.threshold, scene.dimensions);
                break;
            case Kind::Mesh: vdbclay::writeSurfaceMesh(path, *sculptor.mass(), scene.rule.threshold); break;
            }
            if (q.count++ == 0) q.first = path;
            q.last = path;
        }
        mSeconds += secondsSince(t0);
    }

    /// Seconds spent writing frames.
    double seconds() const { return mSeconds; }

    /// One line per sequence: the files it wrote.
    void printWritten() const
    {
        for (const Sequence& q : mSeqs) {
            if (q.count == 0) continue;
            if (q.count == 1) {
                std::printf("wrote %s\n", q.first.c_str());
            } else {
                std::printf("wrote %s .. %s (%llu frames)\n", q.first.c_str(), q.last.c_str(),
                            (unsigned long long)q.count);
            }
        }
    }

private:
    enum class Kind { Vdb, Png, Mesh };
    struct Sequence {
        Kind kind;
        std::string path;
        FramePattern pattern;
        std::string first, last;
        uint64_t count = 0;
    };
    void add(Kind kind, const char* option, const std::string& path)
    {
        const FramePattern p = framePatternOf({option, path});
        if (p.width) mSeqs.push_back({kind, path, p, "", "", 0});
    }

    uint64_t mEvery, mLast;
    std::vector<Sequence> mSeqs;
    double mSeconds = 0;
};

/// The run's frames, SIGINT/SIGTERM (and VDBCLAY_TEST_RAISE) asking it to stop at the next step
/// from which a checkpoint resumes exactly; the library's memory watchdog may stop it too. From
/// here to the end of the run the signals stop it and save it; before, there is nothing to save,
/// and after, they end the process (removing a half-written output's temporary file).
vdbclay::RunSummary runFrames(vdbclay::Sculptor& sculptor, const RunArgs& a, bool tty, FrameWriter& frames)
{
    const std::function<void(uint64_t)> testSignal = testSignalAtStep();
    vdbclay::Automaton& automaton = sculptor.automaton();
    sculptor.setStopRequest([&] {
        if (testSignal) testSignal(automaton.stepCount());
        return gStopSignal.load(std::memory_order_relaxed) != 0;
    });
    gStopAtOnce.store(false);
    const auto progress = frameProgress(a.quiet, tty, sculptor.totalFrames());
    const vdbclay::RunSummary s = sculptor.run(uint64_t(a.frames), [&](const vdbclay::FrameReport& r) {
        if (r.finished) frames.frameDone(sculptor, r.frame);
        progress(r);
    });
    gWriting.store(true);
    gStopAtOnce.store(true);
    sculptor.setStopRequest({});
    return s;
}

/// The lines a finished run ends with: frames, steps and times; mass; the global layer; the clay.
/// @a setupSeconds: building the scene before the first frame (its meshes' level sets, the clay);
/// @a frameWriteSeconds: writing sequences' frames, part of the frames' time.
void printSummary(const vdbclay::RunSummary& s, const vdbclay::Scene& scene, double setupSeconds,
                  double frameWriteSeconds)
{
    const bool exact = s.massDrift == 0; // mass_final = mass_initial + added - removed
    std::printf("frames %llu, steps %llu, time %s (push %s, settle %s", (unsigned long long)s.frames,
                (unsigned long long)s.steps, fmtSeconds(s.seconds).c_str(), fmtSeconds(s.pushSeconds).c_str(),
                fmtSeconds(s.stages.total()).c_str());
    if (frameWriteSeconds > 0) std::printf(", writing frames %s", fmtSeconds(frameWriteSeconds).c_str());
    std::printf("); set-up before the frames %s\n", fmtSeconds(setupSeconds).c_str());
    std::printf("mass before %lld, after %lld", (long long)s.massInitial, (long long)s.massFinal);
    if (s.massAdded || s.massRemoved)
        std::printf(" (added %lld, removed %lld)", (long long)s.massAdded, (long long)s.massRemoved);
    std::printf(" (%s); residual overload %lld; settled %s", exact ? "exact" : "DRIFT",
                (long long)s.residualOverload, s.settled ? "yes" : "no");
    if (s.framesUnsettled > s.framesNoRoom) {
        std::printf(" (%llu frames hit the step budget)",
                    (unsigned long long)(s.framesUnsettled - s.framesNoRoom));
    }
    if (s.framesNoRoom)
        std::printf(" (%llu frames had no room for their overload)", (unsigned long long)s.framesNoRoom);
    if (s.massTrapped) std::printf("; %lld clay trapped in tools", (long long)s.massTrapped);
    std::printf("\n");
    if (scene.transport == vdbclay::Transport::Global) {
        std::printf("global transport: %s, %llu solves, %llu CG iterations, %lld clay routed%s\n",
                    fmtSeconds(s.transportSeconds).c_str(), (unsigned long long)s.transportSolves,
                    (unsigned long long)s.transportIterations, (long long)s.transportMassMoved,
                    s.framesTransportNoRoom ? " (some clay walled in with no room)" : "");
    }
    if (scene.surfaceTension > 0 || s.massSmoothed) {
        std::printf("smoothing: %lld clay moved", (long long)s.massSmoothed);
        if (scene.surfaceTension > 0) {
            std::printf(" (surface tension %s, %llu boxes, %llu voxels read)",
                        fmtSeconds(s.tensionSeconds).c_str(), (unsigned long long)s.tensionBoxes,
                        (unsigned long long)s.tensionVoxels);
        }
        std::printf("\n");
    }
    std::printf(
        "clay %llu voxels, %llu interior (mean density %.4f, heterogeneity CV %.4f), compaction %.4f\n",
        (unsigned long long)s.metrics.clayVoxels, (unsigned long long)s.metrics.interiorCells,
        s.metrics.interiorMeanDensity, s.metrics.heterogeneityCV, s.metrics.compaction);
}

/// Writes the .vdb, the picture and the mesh (those named); returns the seconds it took.
double writeOutputs(const vdbclay::Sculptor& sculptor, const RunOutputs& o, const FrameWriter& frames)
{
    const vdbclay::Scene& scene = sculptor.scene();
    const auto t0 = Clock::now();
    vdbclay::adviseBatchHeapGrowth();
    frames.printWritten();
    if (!o.vdb.empty() && !frames.writes(o.vdb)) {
        vdbclay::writeClayFile(o.vdb, *sculptor.mass(), sculptor.checkpointMeta(), scene.outputs.grids);
        std::printf("wrote %s\n", o.vdb.c_str());
    }
    if (!o.png.empty() && !frames.writes(o.png)) {
        vdbclay::renderPng(o.png, *sculptor.mass(), scene.rule.threshold, scene.dimensions);
        std::printf("wrote %s\n", o.png.c_str());
    }
    if (!o.mesh.empty() && !frames.writes(o.mesh)) {
        vdbclay::writeSurfaceMesh(o.mesh, *sculptor.mass(), scene.rule.threshold);
        std::printf("wrote %s\n", o.mesh.c_str());
    }
    return secondsSince(t0);
}

int runScene(const RunArgs& a)
{
    // --threads N holds for the whole command, not only the automaton: loading the scene, the memory
    // estimate and writing the outputs (density, surface, mesh, picture) run on at most N threads too.
    std::unique_ptr<tbb::global_control> threadLimit;
    if (a.threads > 0) {
        threadLimit = std::make_unique<tbb::global_control>(tbb::global_control::max_allowed_parallelism,
                                                            size_t(a.threads));
    }
    const vdbclay::Scene scene = sceneOf(a);
    const RunOutputs out = outputsOf(a, scene);
    checkRunOutputs(a, scene, out);

    const auto setupStart = Clock::now();
    vdbclay::Sculptor sculptor(scene, a.threads);
    const double setupSeconds = secondsSince(setupStart);
    if (!a.resume.empty()) checkResumeFits(scene, sculptor.startMeta(), a.resume);
    const bool tty = ::isatty(2) && !a.quiet;
    if (!a.quiet) printRunHeader(sculptor);
    std::cout.flush();

    const uint64_t frame0 = sculptor.frame(), steps0 = sculptor.automaton().stepCount();
    const uint64_t lastFrame = a.frames > 0
                                   ? std::min<uint64_t>(frame0 + uint64_t(a.frames), sculptor.totalFrames())
                                   : sculptor.totalFrames();
    FrameWriter frames(out, lastFrame);
    const vdbclay::RunSummary s = runFrames(sculptor, a, tty, frames);
    if (sculptor.stopped()) {
        frames.printWritten();
        return finishStopped(sculptor, a, out.checkpoint, frame0, steps0, tty);
    }
    printSummary(s, scene, setupSeconds, frames.seconds());

    const double outputSeconds = writeOutputs(sculptor, out, frames) + frames.seconds();
    if (!out.stats.empty()) {
        vdbclay::RunReport report = vdbclay::makeRunReport(sculptor, s, a.threads);
        report.setupSeconds = setupSeconds;
        report.outputSeconds = outputSeconds;
        report.heap = gHeap.note;
        vdbclay::writeTextFile(out.stats, vdbclay::runReportJson(report) + "\n");
        std::printf("wrote %s\n", out.stats.c_str());
    }
    if (s.massDrift != 0) { // mass_final = mass_initial + mass_added - mass_removed, exactly
        std::fprintf(stderr, "vdbclay: error: mass changed from %lld to %lld (added %lld, removed %lld)\n",
                     (long long)s.massInitial, (long long)s.massFinal, (long long)s.massAdded,
                     (long long)s.massRemoved);
        return 3;
    }
    return 0;
}

void addRunOptions(CLI::App* run, RunArgs& ra)
{
    run->add_option("scene", ra.scene,
                    "scene JSON file (see docs/SCENES.md), - for standard input; omitted: the built-in scene")
        ->check(fileName());
    run->add_option("-o,--output", ra.out,
                    "write the clay to this .vdb (the grids --grids names); a run of # in the name "
                    "(clay.####.vdb) writes every frame, numbered")
        ->check(fileName());
    run->add_option("--threads", ra.threads, "worker threads for the whole command; 0 = all cores")
        ->check(integerIn(0, kMaxThreads));
    run->add_option("--rule", ra.rule, "override the scene's rule: arata, bingham, sorted, prorata")
        ->check(nonEmpty("a rule name"));
    run->add_option("--seed", ra.seed, "override the scene's seed")->check(integerIn(0, INT64_MAX));
    run->add_option("--stats", ra.stats, "write run statistics as JSON to this file")->check(fileName());
    run->add_option("--png", ra.png, "also render the result to this PNG (# in the name: every frame)")
        ->check(fileName());
    run->add_option("--mesh", ra.mesh,
                    "also write the clay surface to this .obj, .ply or .stl (# in the name: every frame)")
        ->check(fileName());
    run->add_option("--every", ra.every,
                    "sequences (outputs named with #) write every K-th frame and the last (default 1)")
        ->check(integerIn(1, 100000000));
    run->add_option("--frames", ra.frames,
                    "stop after this many frames (the output can be continued with \"start\")")
        ->check(integerIn(1, 100000000));
    run->add_flag("-q,--quiet", ra.quiet, "no progress output");
    run->add_flag("--scene-outputs-anywhere", ra.sceneOutputsAnywhere,
                  "let the scene's outputs write outside the current directory (absolute paths, ..)");
    run->add_option("--up", ra.up,
                    "y or z: the up axis of the output .vdb's transform and mesh (Blender: z)");
    run->add_option("--checkpoint", ra.checkpoint,
                    "on SIGINT/SIGTERM, save the run here (default: OUT.checkpoint.vdb beside -o OUT.vdb)")
        ->check(fileName());
    run->add_option("--resume", ra.resume,
                    "continue an interrupted run from its checkpoint (same scene and options)")
        ->check(fileName());
    run->add_option("--grids", ra.grids,
                    "the grids the .vdb holds: mass, density, surface, comma-separated (default: all three; "
                    "\"start\" and --resume read mass)")
        ->check(nonEmpty("grid names"));
    run->add_option("--push", ra.push, "override the scene's push: surface (the paper's) or compress");
    run->add_option("--transport", ra.transport,
                    "override the scene's transport: local (the paper's automaton) or global");
    run->add_option("--sweep", ra.sweep,
                    "override the scene's sweep: on (push over the volume a tool sweeps) or off");
    run->add_option("--memory-budget", ra.memoryBudget,
                    "refuse a scene estimated to need more, e.g. 8G, 512M, none (default: 3/4 of memory)")
        ->check(nonEmpty("a size"));
}

} // namespace

Subcommand addRunCommand(CLI::App& app)
{
    auto args = std::make_shared<RunArgs>();
    CLI::App* run = app.add_subcommand("run", "Run a scene file (or, with none, the built-in default scene)");
    addRunOptions(run, *args);
    return {run, [args] { return runScene(*args); }};
}

} // namespace vdbclay_cli
