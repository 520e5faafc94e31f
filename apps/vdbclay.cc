// vdbclay: the command-line tool. Subcommands: run (scenes), info, mesh, render, import, demo.
// Thin: parsing and printing here, all work in the library. Every error ends in one line on stderr
// and a non-zero exit code.

#include "vdbclay/Automaton.h"
#include "vdbclay/BatchHeap.h"
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
#include <tbb/global_control.h>
#include <sys/stat.h>
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
#include <new>
#include <string>
#include <thread>
#include <utility>
#include <vector>

namespace {

struct DemoArgs {
    int size = 32;
    int overload = 3;
    vdbclay::AutomatonOptions opts;
    uint64_t maxSteps = 200000;
    std::string out;
};

std::string printable(const std::string& text)
{
    return vdbclay::printableText(text);
}

/// A file an option names, as messages refer to it: "-o out.vdb".
struct FileArg {
    std::string option; ///< "-o", "--png", "the scene file", ...
    std::string path;
    std::string text() const { return option + " " + path; }
};

/// What makes two paths the same file: device and inode for an existing regular file, the
/// directory's device and inode plus the name for a file to be created; "" for an existing file
/// that is not regular (a device such as /dev/null may take several outputs).
std::string fileIdentity(const std::string& path)
{
    struct stat st;
    if (::stat(path.c_str(), &st) == 0) {
        if (!S_ISREG(st.st_mode)) return "";
        return "f" + std::to_string(st.st_dev) + ":" + std::to_string(st.st_ino);
    }
    const auto slash = path.find_last_of('/');
    const std::string dir = slash == std::string::npos ? "." : (slash == 0 ? "/" : path.substr(0, slash));
    const std::string name = slash == std::string::npos ? path : path.substr(slash + 1);
    if (::stat(dir.c_str(), &st) == 0)
        return "d" + std::to_string(st.st_dev) + ":" + std::to_string(st.st_ino) + "/" + name;
    return "p" + path;
}

/// Refuses, before any work, an output that cannot be written: a directory, a path through a
/// missing directory or a symbolic-link loop, an unwritable directory. A device or FIFO that
/// exists is written through (never replaced), so it only has to be writable.
void checkWritable(const FileArg& o)
{
    if (o.path.empty()) return;
    const std::string& path = o.path;
    struct stat st;
    std::string dirOf = path;
    if (::stat(path.c_str(), &st) == 0) {
        if (S_ISDIR(st.st_mode)) throw vdbclay::Error(o.text() + ": is a directory, expected a file name");
        if (!S_ISREG(st.st_mode)) {
            if (::access(path.c_str(), W_OK) != 0)
                throw vdbclay::Error("cannot write " + path + ": " + std::strerror(errno));
            return;
        }
        if (char* real = ::realpath(path.c_str(), nullptr)) { // a link: the file it points to is replaced
            dirOf = real;
            std::free(real);
        }
    } else if (errno != ENOENT) {
        throw vdbclay::Error("cannot write " + path + ": " + std::strerror(errno));
    }
    const auto slash = dirOf.find_last_of('/');
    const std::string dir = slash == std::string::npos ? "." : (slash == 0 ? "/" : dirOf.substr(0, slash));
    if (::access(dir.c_str(), W_OK) != 0) {
        throw vdbclay::Error("cannot write " + path + ": directory " + dir + ": " + std::strerror(errno));
    }
}

/// Checks every output before any work: each writable (checkWritable), no two the same file, none
/// of them one of @a inputs. An input whose @a mayReplace flag is set may be written over by the
/// outputs named in it (a start file continued in place by -o).
struct InputArg {
    FileArg file;
    std::vector<std::string> mayReplace; ///< options of outputs allowed to write over it
};
void checkOutputs(const std::vector<FileArg>& outputs, const std::vector<InputArg>& inputs)
{
    for (const FileArg& o : outputs)
        checkWritable(o);
    for (size_t i = 0; i < outputs.size(); ++i) {
        if (outputs[i].path.empty()) continue;
        const std::string id = fileIdentity(outputs[i].path);
        if (id.empty()) continue;
        for (size_t j = 0; j < i; ++j) {
            if (!outputs[j].path.empty() && fileIdentity(outputs[j].path) == id) {
                throw vdbclay::Error(outputs[i].text() + ": the same file as " + outputs[j].text() +
                                     "; give each output its own file");
            }
        }
        for (const InputArg& in : inputs) {
            if (in.file.path.empty() || fileIdentity(in.file.path) != id) continue;
            if (std::find(in.mayReplace.begin(), in.mayReplace.end(), outputs[i].option) !=
                in.mayReplace.end())
                continue;
            throw vdbclay::Error(outputs[i].text() + ": that is " + in.file.text() +
                                 "; refusing to write over an input");
        }
    }
}

/// Refuses a mesh output whose extension names no format vdbclay writes.
void checkMeshName(const FileArg& o)
{
    if (o.path.empty()) return;
    const auto slash = o.path.find_last_of('/');
    const auto dot = o.path.find_last_of('.');
    std::string ext =
        dot == std::string::npos || (slash != std::string::npos && dot < slash) ? "" : o.path.substr(dot);
    for (char& c : ext)
        c = char(std::tolower(static_cast<unsigned char>(c)));
    if (ext != ".obj" && ext != ".ply") {
        throw vdbclay::Error(o.text() + ": unknown mesh format \"" + ext + "\" (use .obj or .ply)");
    }
}

/// A CLI11 check that an option's value is not an empty string ("" would silently mean "none").
CLI::Validator nonEmpty(const char* what)
{
    return CLI::Validator(
        [what](std::string& v) {
            return v.empty() ? std::string("expected ") + what + ", got an empty string" : std::string();
        },
        "", "non-empty");
}

/// A CLI11 check that a number is finite and within [@a lo, @a hi] (open at both ends when @a open):
/// CLI11's own range checks accept nan and print the limits of double in full.
CLI::Validator finiteIn(double lo, double hi, bool open = false)
{
    return CLI::Validator(
        [=](std::string& v) -> std::string {
            double d = 0;
            size_t used = 0;
            try {
                d = std::stod(v, &used);
            } catch (const std::exception&) {
                used = 0;
            }
            char range[96];
            std::snprintf(range, sizeof range, open ? "a number in (%g, %g)" : "a number in [%g, %g]", lo,
                          hi);
            const bool in = open ? (d > lo && d < hi) : (d >= lo && d <= hi);
            if (used == 0 || used != v.size() || !std::isfinite(d) || !in)
                return "expected " + std::string(range) + ", got " + v;
            return "";
        },
        "", "finite");
}

/// A CLI11 check for an unsigned integer option: "-3" is refused, not wrapped around.
const CLI::Validator unsignedInteger(
    [](std::string& v) -> std::string {
        if (v.empty() || v.find_first_not_of("0123456789") != std::string::npos) {
            return "expected a non-negative integer, got " + v;
        }
        return "";
    },
    "", "unsigned");

/// Largest image side render accepts (a 16384^2 RGB image is 768 MiB).
constexpr int kMaxImageSide = 16384;

/// Most worker threads an option may ask for: beyond this TBB only warns and clamps.
constexpr int kMaxThreads = 256;

std::string fmtSeconds(double s)
{
    char buf[32];
    std::snprintf(buf, sizeof buf, "%.3f s", s);
    return buf;
}

/// Refuses a demo whose grids would not fit in the default memory budget, with the estimate of a
/// scene of the same clay and floor (estimateSceneMemory).
void checkDemoMemory(const DemoArgs& a)
{
    const bool d3 = a.opts.dimensions == 3;
    const double n = a.size;
    vdbclay::Scene sc;
    sc.source = "demo --size " + std::to_string(a.size);
    sc.dimensions = a.opts.dimensions;
    vdbclay::ClaySpec clay;
    clay.shape.kind = "box";
    clay.shape.field = "demo";
    clay.shape.shape = vdbclay::makeBox({{0, 0, 0}}, {{n - 1, n - 1, d3 ? n - 1 : 0}});
    clay.mass = a.opts.rule.threshold;
    sc.clay.push_back(clay);
    vdbclay::ShapeSpec floor;
    floor.kind = "box";
    floor.field = "floor";
    floor.shape = vdbclay::makeBox({{-4 * n, -4, d3 ? -4 * n : 0}}, {{5 * n, -1, d3 ? 5 * n : 0}});
    sc.obstacles.push_back(floor);
    vdbclay::checkMemoryBudget(sc);
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
    floor->tree().fill(CoordBBox(Coord(-4 * n, -4, d3 ? -4 * n : 0), Coord(5 * n, -1, d3 ? 5 * n : 0)), true,
                       true);

    vdbclay::Automaton automaton(mass, a.opts, floor);
    const int64_t m0 = vdbclay::totalMass(*mass);
    std::cout << "vdbclay demo: " << (d3 ? "3D " : "2D ") << n << (d3 ? "^3" : "^2") << " lump at Tc=" << tc
              << ", core " << q << (d3 ? "^3" : "^2") << " at " << a.overload << "xTc, rule "
              << vdbclay::ruleName(a.opts.rule.rule) << ", threads "
              << (a.opts.threads ? std::to_string(a.opts.threads) : std::string("all")) << "\n";
    std::cout << "  initial: mass " << m0 << ", overload " << automaton.residualOverload() << ", "
              << vdbclay::clayVoxelCount(*mass) << " clay voxels\n";
    const auto t0 = std::chrono::steady_clock::now();
    const vdbclay::StepReport r = automaton.settle(a.maxSteps);
    const double secs = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
    const int64_t m1 = vdbclay::totalMass(*mass);
    std::printf("  steps %llu (%s), %.3f s, %.2f us/step\n", (unsigned long long)r.steps,
                vdbclay::stopReasonName(r.reason), secs, r.steps ? 1e6 * secs / double(r.steps) : 0.0);
    std::printf(
        "  blocks examined %llu, with a cell over Tc %llu, updated %llu, grown %llu; leaves created %llu\n",
        (unsigned long long)r.blocksVisited, (unsigned long long)r.blocksOverTc,
        (unsigned long long)r.blocksUpdated, (unsigned long long)r.blocksGrown,
        (unsigned long long)r.leavesCreated);
    std::printf("  stages: gather %.3f s, repartition %.3f s, grow %.3f s, bookkeeping %.3f s; "
                "the passes' threads busy %.3f, idle %.3f thread-s\n",
                r.seconds.gather, r.seconds.repartition, r.seconds.grow, r.seconds.bookkeeping,
                r.seconds.passBusy, r.seconds.passIdle);
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

/// What configureBatchHeap() did (main sets it first thing; --stats reports it).
vdbclay::BatchHeap gHeap;

struct RunArgs {
    std::string scene, out, stats, png, mesh, rule, checkpoint, resume, memoryBudget, push, transport, sweep;
    int threads = 0;
    int64_t seed = -1;
    int64_t frames = 0; ///< 0: all
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

// ---- interrupts -----------------------------------------------------------------------------------
// While a scene runs, SIGINT and SIGTERM only set a flag (a lock-free atomic store is
// async-signal-safe); the run polls it between automaton steps, stops where a checkpoint resumes
// exactly, and writes one. At any other time (building the scene, writing outputs, a second signal)
// the signal ends the process at once, as it would without vdbclay's handler, but first removes the
// temporary file of a write in progress: the file being written keeps its old contents.

std::atomic<int> gStopSignal{0};
std::atomic<bool> gStopAtOnce{true};
std::atomic<bool> gWriting{false};
static_assert(std::atomic<int>::is_always_lock_free, "the signal flag must be lock-free");

extern "C" void onStopSignal(int sig)
{
    if (gStopAtOnce.load() || gStopSignal.load() != 0) {
        vdbclay::removePendingTempFile();
        if (gWriting.load()) {
            static const char msg[] =
                "vdbclay: interrupted while writing an output; that file was left as it was\n";
            (void)!::write(2, msg, sizeof msg - 1);
        }
        ::signal(sig, SIG_DFL);
        ::raise(sig); // delivered when this handler returns: the process ends as killed by @a sig
        return;
    }
    gStopSignal.store(sig, std::memory_order_relaxed);
}

/// Catches SIGINT and SIGTERM (a SIGINT the caller ignores, as in a background job of a script,
/// stays ignored). SIGXFSZ is ignored, so that a write over the file size limit (ulimit -f) fails
/// with EFBIG and is reported, instead of killing the process with a temporary file left behind.
void catchSignals()
{
    ::signal(SIGXFSZ, SIG_IGN);
    struct sigaction sa;
    std::memset(&sa, 0, sizeof sa);
    sa.sa_handler = onStopSignal;
    sigemptyset(&sa.sa_mask);
    sa.sa_flags = SA_RESTART; // no EINTR in the middle of writing a file
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
    opt("--rule", a.rule);
    if (a.seed >= 0) opt("--seed", std::to_string(a.seed));
    opt("--memory-budget", a.memoryBudget);
    opt("--checkpoint", a.checkpoint);
    if (a.threads) opt("--threads", std::to_string(a.threads));
    if (a.quiet) cmd += " --quiet";
    return cmd;
}

/// After a stop request: writes the checkpoint (or nothing when no step ran or there is nowhere to
/// write it), says so in one line on stderr, returns 128 + the signal number.
int finishInterrupted(vdbclay::Sculptor& sculptor, const RunArgs& a, const std::string& checkpoint,
                      uint64_t frame0, uint64_t steps0, bool tty, const std::string& overBudget = "")
{
    const int sig = gStopSignal.load();
    const std::string cause =
        !overBudget.empty() ? overBudget
                            : std::string("interrupted by ") +
                                  (sig == SIGINT ? "SIGINT" : (sig == SIGTERM ? "SIGTERM" : "a signal"));
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
            vdbclay::writeClayFile(checkpoint, *sculptor.mass(), meta);
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
    if (!overBudget.empty()) return 1;
    return 128 + (sig > 0 ? sig : SIGINT);
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
    uint64_t cliBudget =
        0; // --memory-budget replaces the scene's; meshes are checked against it as they are read
    if (!a.memoryBudget.empty()) {
        try {
            cliBudget = vdbclay::parseByteSize(a.memoryBudget);
        } catch (const vdbclay::Error& e) {
            throw vdbclay::Error(std::string("--memory-budget: ") + e.what());
        }
    }
    vdbclay::Scene scene = a.scene.empty() ? vdbclay::defaultScene() : vdbclay::loadScene(a.scene, cliBudget);
    if (!a.rule.empty()) {
        try {
            scene.rule.rule = vdbclay::parseRule(a.rule);
        } catch (const vdbclay::Error& e) {
            throw vdbclay::Error(std::string("--rule: ") + e.what());
        }
    }
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
    if (cliBudget != 0) scene.memoryBudget = cliBudget;
    const std::string outVdb = a.out.empty() ? scene.outputs.vdb : a.out;
    const std::string outStats = a.stats.empty() ? scene.outputs.stats : a.stats;
    const std::string outPng = a.png.empty() ? scene.outputs.png : a.png;
    const std::string outMesh = a.mesh.empty() ? scene.outputs.mesh : a.mesh;
    const std::string checkpoint = a.checkpoint.empty() ? defaultCheckpointPath(outVdb) : a.checkpoint;

    // Every output is checked before any work (a bad one found after an hour's run costs the hour).
    auto named = [](const char* option, const char* field, const std::string& cli) {
        return cli.empty() ? std::string("the scene's outputs.") + field : std::string(option);
    };
    const std::vector<FileArg> outputs{
        {named("-o", "vdb", a.out), outVdb},
        {named("--stats", "stats", a.stats), outStats},
        {named("--png", "png", a.png), outPng},
        {named("--mesh", "mesh", a.mesh), outMesh},
        {a.checkpoint.empty() ? "the checkpoint" : "--checkpoint", checkpoint}};
    std::vector<InputArg> inputs;
    if (!a.scene.empty()) inputs.push_back({{"the scene file", a.scene}, {}});
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
    for (const vdbclay::ShapeSpec& o : scene.obstacles)
        shapeInputs(o);
    checkMeshName(outputs[3]);
    checkOutputs(outputs, inputs);

    const auto setupStart = std::chrono::steady_clock::now();
    vdbclay::Sculptor sculptor(scene, a.threads);
    const double setupSeconds =
        std::chrono::duration<double>(std::chrono::steady_clock::now() - setupStart).count();
    if (!a.resume.empty()) checkResumeFits(scene, sculptor.startMeta(), a.resume);
    const bool tty = ::isatty(2) && !a.quiet;
    if (!a.quiet)
        std::cout << "vdbclay: " << scene.source << ": " << scene.dimensions << "D, Tc "
                  << scene.rule.threshold << ", rule " << vdbclay::ruleName(scene.rule.rule) << ", "
                  << scene.clay.size() << " clay, " << scene.tools.size() << " tools, "
                  << scene.obstacles.size() << " obstacles, frames " << sculptor.frame() + 1 << ".."
                  << sculptor.totalFrames() << "\n";
    const bool paperModel =
        scene.push == vdbclay::PushMode::Surface && scene.transport == vdbclay::Transport::Local;
    if (!a.quiet && (!paperModel || scene.sweep))
        std::cout << "push " << vdbclay::pushModeName(scene.push) << (scene.sweep ? " (swept)" : "")
                  << ", transport " << vdbclay::transportName(scene.transport) << "\n";
    const uint64_t budget = scene.memoryBudget ? scene.memoryBudget : vdbclay::defaultMemoryBudget();
    const vdbclay::MemoryEstimate startEstimate = sculptor.memoryEstimate(); // the constructor's
    if (!a.quiet) {
        std::cout << "memory: " << startEstimate.describe() << "; budget "
                  << (budget == vdbclay::kNoMemoryBudget ? std::string("none") : vdbclay::formatBytes(budget))
                  << "\n";
    }
    std::cout.flush();
    const uint64_t total = sculptor.totalFrames();
    auto onFrame = [&](const vdbclay::FrameReport& r) {
        vdbclay::adviseBatchHeapGrowth(); // the frame may have grown the heap
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
    // The budget is kept while the run goes on: the estimate may fall short (clay from a file that
    // spreads far), so every 64 polls the grid is measured, and a run that outgrows the budget
    // stops where a checkpoint resumes exactly, as on SIGINT.
    const uint64_t fixedBytes =
        startEstimate.processBytes + startEstimate.obstacleBytes + startEstimate.toolBytes;
    uint64_t polls = 0, grewTo = 0;
    // The grid's size changes only with its nodes: it is measured again (a walk of every node)
    // only when its leaf or internal node count changed since the last poll (a walk of the
    // internal nodes; press 128^3: ~780 polls, 0.04 s of one core when each measured the tree).
    openvdb::Index64 lastLeaves = UINT64_MAX, lastInternal = UINT64_MAX;
    uint64_t lastBytes = 0;
    sculptor.setStopRequest([&] {
        if (testSignal) testSignal(automaton.stepCount());
        if (gStopSignal.load(std::memory_order_relaxed) != 0) return true;
        if (scene.memoryBudget == vdbclay::kNoMemoryBudget || ++polls % 64 != 0) return false;
        const auto& tree = sculptor.mass()->constTree();
        const openvdb::Index64 leaves = tree.leafCount(), internal = tree.nonLeafCount();
        if (leaves != lastLeaves || internal != lastInternal) {
            lastBytes = vdbclay::clayMemoryInUse(*sculptor.mass());
            lastLeaves = leaves;
            lastInternal = internal;
        }
        const uint64_t now = lastBytes + fixedBytes;
        if (now <= budget) return false;
        grewTo = now;
        return true;
    });
    // From here to the end of the run SIGINT/SIGTERM stop the run at the next step and save it;
    // before, there is nothing to save, and after, they end the process (removing a half-written
    // output's temporary file).
    gStopAtOnce.store(false);
    const vdbclay::RunSummary s = sculptor.run(uint64_t(a.frames), onFrame);
    gWriting.store(true);
    gStopAtOnce.store(true);
    sculptor.setStopRequest({});
    if (sculptor.stopped()) {
        std::string overBudget;
        if (gStopSignal.load() == 0 && grewTo > 0) {
            overBudget = "stopped: the clay outgrew the memory budget of " + vdbclay::formatBytes(budget) +
                         " (it needs about " + vdbclay::formatBytes(grewTo) +
                         " now; raise --memory-budget to go on)";
        }
        return finishInterrupted(sculptor, a, checkpoint, frame0, steps0, tty, overBudget);
    }
    const bool exact = s.massFinal == s.massInitial;
    std::printf("frames %llu, steps %llu, time %s (push %s, settle %s)\n", (unsigned long long)s.frames,
                (unsigned long long)s.steps, fmtSeconds(s.seconds).c_str(), fmtSeconds(s.pushSeconds).c_str(),
                fmtSeconds(s.stages.total()).c_str());
    std::printf("mass before %lld, after %lld (%s); residual overload %lld; settled %s",
                (long long)s.massInitial, (long long)s.massFinal, exact ? "exact" : "DRIFT",
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
    std::printf(
        "clay %llu voxels, %llu interior (mean density %.4f, heterogeneity CV %.4f), compaction %.4f\n",
        (unsigned long long)s.metrics.clayVoxels, (unsigned long long)s.metrics.interiorCells,
        s.metrics.interiorMeanDensity, s.metrics.heterogeneityCV, s.metrics.compaction);

    const auto outputStart = std::chrono::steady_clock::now();
    vdbclay::adviseBatchHeapGrowth();
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
    const double outputSeconds =
        std::chrono::duration<double>(std::chrono::steady_clock::now() - outputStart).count();
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
        j["setup_seconds"] = setupSeconds;   // the scene's clay, obstacles and tools into grids
        j["output_seconds"] = outputSeconds; // the .vdb, picture and mesh (not this file)
        j["heap"] = gHeap.note;              // the allocator policy (vdbclay/BatchHeap.h)
        j["push"] = vdbclay::pushModeName(scene.push);
        j["sweep"] = scene.sweep;
        j["transport"] = vdbclay::transportName(scene.transport);
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
        j["residual_overload"] = s.residualOverload;
        j["settled"] = s.settled;
        j["frames_unsettled"] = s.framesUnsettled;
        j["mass_trapped"] = s.massTrapped;
        j["blocks_visited"] = s.blocksVisited; // candidates examined, before any filter
        j["blocks_over_tc"] = s.blocksOverTc;
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
        // The clay's content hash, as `vdbclay info` prints it for the written .vdb: runs on any
        // thread count must give the same (bench/thread-curve.sh checks it).
        char hash[17];
        std::snprintf(hash, sizeof hash, "%016llx",
                      (unsigned long long)vdbclay::contentHash(*sculptor.mass()));
        j["content_hash"] = hash;
        vdbclay::writeTextFile(outStats, j.dump(2) + "\n");
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
    try {
        gHeap = vdbclay::configureBatchHeap(); // before the first large allocation
    } catch (const vdbclay::Error& e) {
        std::cerr << "vdbclay: error: " << printable(e.what()) << "\n";
        return 2;
    }
    CLI::App app{"vdbclay: virtual clay in sparse OpenVDB volumes (Druon, Crosnier, Brigandat 2003)"};
    app.require_subcommand(1);
    app.set_version_flag("--version", std::string("vdbclay ") + VDBCLAY_VERSION);
    const CLI::Validator fileName = nonEmpty("a file name");

    RunArgs ra;
    CLI::App* run = app.add_subcommand("run", "Run a scene file (or, with none, the built-in default scene)");
    run->add_option("scene", ra.scene, "scene JSON file (see docs/SCENES.md); omitted: the built-in scene")
        ->check(fileName);
    run->add_option("-o,--output", ra.out, "write the clay to this .vdb (mass, density, surface grids)")
        ->check(fileName);
    run->add_option("--threads", ra.threads, "worker threads for the whole command; 0 = all cores")
        ->check(CLI::Range(0, kMaxThreads));
    run->add_option("--rule", ra.rule, "override the scene's rule: arata, bingham, sorted, prorata")
        ->check(nonEmpty("a rule name"));
    run->add_option("--seed", ra.seed, "override the scene's seed")
        ->check(CLI::Range(int64_t(0), int64_t(INT64_MAX)));
    run->add_option("--stats", ra.stats, "write run statistics as JSON to this file")->check(fileName);
    run->add_option("--png", ra.png, "also render the result to this PNG")->check(fileName);
    run->add_option("--mesh", ra.mesh, "also write the clay surface to this .obj or .ply")->check(fileName);
    run->add_option("--frames", ra.frames,
                    "stop after this many frames (the output can be continued with \"start\")")
        ->check(CLI::Range(int64_t(1), int64_t(100000000)));
    run->add_flag("-q,--quiet", ra.quiet, "no progress output");
    run->add_option("--up", ra.up,
                    "y or z: the up axis of the output .vdb's transform and mesh (Blender: z)");
    run->add_option("--checkpoint", ra.checkpoint,
                    "on SIGINT/SIGTERM, save the run here (default: OUT.checkpoint.vdb beside -o OUT.vdb)")
        ->check(fileName);
    run->add_option("--resume", ra.resume,
                    "continue an interrupted run from its checkpoint (same scene and options)")
        ->check(fileName);
    run->add_option("--push", ra.push, "override the scene's push: surface (the paper's) or compress");
    run->add_option("--transport", ra.transport,
                    "override the scene's transport: local (the paper's automaton) or global");
    run->add_option("--sweep", ra.sweep,
                    "override the scene's sweep: on (push over the volume a tool sweeps) or off");
    run->add_option("--memory-budget", ra.memoryBudget,
                    "refuse a scene estimated to need more, e.g. 8G, 512M, none (default: 3/4 of memory)")
        ->check(nonEmpty("a size"));

    std::string infoPath;
    CLI::App* inf =
        app.add_subcommand("info", "Describe a .vdb file: grids, voxels, bounds, total mass, metadata");
    inf->add_option("file", infoPath, "a .vdb file")->required()->check(fileName);

    std::string meshIn, meshOut;
    double iso = 0.5;
    int32_t meshTc = 0;
    CLI::App* mesh = app.add_subcommand("mesh", "Write the clay surface of a clay .vdb as OBJ or PLY");
    mesh->add_option("file", meshIn,
                     "a clay .vdb (grid \"mass\"), else its first fog volume, else its first level set")
        ->required()
        ->check(fileName);
    mesh->add_option("-o,--output", meshOut, "OUT.obj or OUT.ply")->required()->check(fileName);
    mesh->add_option("--isovalue", iso, "surface where density (mass / Tc) equals this (default 0.5)")
        ->check(finiteIn(1e-9, 1e9));
    mesh->add_option("--threshold", meshTc, "Tc, if the file does not record it")
        ->check(CLI::Range(1, INT32_MAX));
    std::string meshUp;
    mesh->add_option("--up", meshUp, "y or z: orient the mesh for this up axis (default: the file's)");
    bool meshKeepVolume = false;
    mesh->add_flag("--keep-volume", meshKeepVolume,
                   "move the surface along its normals (at most half a voxel) to enclose the clay's volume");

    std::string renIn, renOut;
    vdbclay::RenderOptions ro;
    int renDims = 0;
    int32_t renTc = 0;
    CLI::App* ren =
        app.add_subcommand("render", "Render a clay .vdb to PNG (2D density map or 3D shaded surface)");
    ren->add_option("file", renIn,
                    "a clay .vdb (grid \"mass\"), else its first fog volume, else its first level set")
        ->required()
        ->check(fileName);
    ren->add_option("-o,--output", renOut, "OUT.png")->required()->check(fileName);
    ren->add_option("--width", ro.width, "image width")->check(CLI::Range(1, kMaxImageSide));
    ren->add_option("--height", ro.height, "image height")->check(CLI::Range(1, kMaxImageSide));
    ren->add_option("--azimuth", ro.azimuthDeg, "3D camera azimuth, degrees")->check(finiteIn(-1e6, 1e6));
    ren->add_option("--elevation", ro.elevationDeg, "3D camera elevation, degrees")
        ->check(finiteIn(-89.9, 89.9));
    ren->add_option("--dims", renDims, "2 or 3, if the file does not record it")->check(CLI::Range(2, 3));
    ren->add_option("--threshold", renTc, "Tc, if the file does not record it")
        ->check(CLI::Range(1, INT32_MAX));

    std::string impIn, impOut;
    int64_t impMass = 0;
    double impVoxel = 0; // 0: the level set's own voxel size, or 1 for meshes
    int impDims = 3;
    CLI::App* imp =
        app.add_subcommand("import", "Turn a mesh (OBJ/STL/PLY), a level set or a fog volume .vdb into clay");
    imp->add_option("file", impIn, "MESH.obj, MESH.stl, MESH.ply, LEVELSET.vdb or FOG.vdb")
        ->required()
        ->check(fileName);
    imp->add_option("-o,--output", impOut, "CLAY.vdb")->required()->check(fileName);
    imp->add_option("--mass", impMass, "clay per voxel inside the shape (a fog volume: per unit of density)")
        ->required()
        ->check(CLI::Range(int64_t(1), int64_t(INT32_MAX)));
    imp->add_option("--voxel-size", impVoxel,
                    "world units per voxel (default: a level set's own voxel size; 1 for meshes)")
        ->check(finiteIn(vdbclay::kMinVoxelSize, vdbclay::kMaxVoxelSize));
    std::string impGrid;
    imp->add_option(
        "--grid", impGrid,
        ".vdb: the level set or fog volume to import (default: the first level set, else the first fog "
        "volume)");
    imp->add_option("--dims", impDims, "2 (keep the z = 0 layer) or 3")->check(CLI::Range(2, 3));
    std::string impUp = "y";
    imp->add_option("--up", impUp, "y or z: the input's up axis, also written into the clay's transform");
    std::string impBudget;
    imp->add_option("--memory-budget", impBudget,
                    "refuse a shape estimated to need more (default: 3/4 of memory)")
        ->check(nonEmpty("a size"));

    DemoArgs da;
    std::string demoRule;
    CLI::App* demo =
        app.add_subcommand("demo", "Settle a built-in overloaded lump of clay (the automaton alone)");
    demo->add_option("--size", da.size, "cube edge in voxels")->check(CLI::Range(2, 4096));
    demo->add_option("--overload", da.overload, "the core holds this many times Tc per voxel")
        ->check(CLI::Range(1, 1000));
    demo->add_option("--rule", demoRule, "arata, bingham, sorted, prorata")->check(nonEmpty("a rule name"));
    demo->add_option("--threshold", da.opts.rule.threshold, "Tc")->check(CLI::Range(1, INT32_MAX));
    demo->add_option("--alpha", da.opts.rule.alpha, "arata's rate in (0,1)")->check(finiteIn(0, 1, true));
    demo->add_option("--dims", da.opts.dimensions, "2 or 3")->check(CLI::Range(2, 3));
    demo->add_option("--threads", da.opts.threads, "worker threads, 0 = all")
        ->check(CLI::Range(0, kMaxThreads));
    demo->add_option("--seed", da.opts.seed, "remainder hash seed")->check(unsignedInteger);
    demo->add_option("--max-steps", da.maxSteps, "step budget")->check(unsignedInteger);
    demo->add_option("-o,--output", da.out, "write the settled clay to this .vdb")->check(fileName);

    // CLI11 takes an unknown word for a stray argument and says only "A subcommand is required".
    if (argc > 1 && argv[1][0] != '-') {
        const std::string word = argv[1];
        bool known = false;
        for (const CLI::App* sub : app.get_subcommands([](const CLI::App*) { return true; }))
            known |= sub->check_name(word);
        if (!known) {
            std::cerr << "vdbclay: error: unknown subcommand \"" << printable(word)
                      << "\" (expected one of: run, info, mesh, render, import, demo; see vdbclay --help)\n";
            return 2;
        }
    }
    try {
        app.parse(argc, argv);
    } catch (const CLI::ParseError& e) {
        if (e.get_exit_code() == 0) return app.exit(e); // --help
        std::cerr << "vdbclay: error: " << printable(e.what()) << " (see vdbclay --help)\n";
        return e.get_exit_code();
    }
    catchSignals();
    try {
        openvdb::initialize();
        if (*run) return runScene(ra);
        if (*inf) return info(infoPath);
        if (*mesh) {
            checkMeshName({"-o", meshOut});
            checkOutputs({{"-o", meshOut}}, {{{"the input file", meshIn}, {}}});
            std::string note;
            const vdbclay::ClayFile f = vdbclay::readAsClay(meshIn, note);
            if (!note.empty()) std::printf("note: %s\n", note.c_str());
            if (!meshUp.empty()) vdbclay::setClayTransform(*f.mass, f.meta.voxelSize, upOption(meshUp));
            gWriting.store(true);
            vdbclay::writeSurfaceMesh(meshOut, *f.mass, thresholdOf(f, meshTc), iso, meshKeepVolume);
            std::printf("wrote %s\n", meshOut.c_str());
            return 0;
        }
        if (*ren) {
            checkOutputs({{"-o", renOut}}, {{{"the input file", renIn}, {}}});
            std::string note;
            const vdbclay::ClayFile f = vdbclay::readAsClay(renIn, note);
            if (!note.empty()) std::printf("note: %s\n", note.c_str());
            const int dims = renDims ? renDims : f.meta.dimensions;
            gWriting.store(true);
            vdbclay::renderPng(renOut, *f.mass, thresholdOf(f, renTc), dims, ro);
            std::printf("wrote %s\n", renOut.c_str());
            return 0;
        }
        if (*imp) {
            checkOutputs({{"-o", impOut}}, {{{"the input file", impIn}, {}}});
            const bool isVdb = impIn.size() > 4 && impIn.compare(impIn.size() - 4, 4, ".vdb") == 0;
            if (!isVdb && !impGrid.empty()) throw vdbclay::Error("--grid: only for a .vdb, not " + impIn);
            const std::string fogGrid = isVdb ? vdbclay::fogGridToImport(impIn, impGrid) : std::string();
            if (!fogGrid.empty()) {
                // A fog volume: round(density x M) per voxel, voxel for voxel at its own voxel size.
                const vdbclay::FogClay fog =
                    vdbclay::readFogAsClay(impIn, fogGrid, int32_t(impMass), impDims);
                if (impVoxel != 0 && impVoxel != fog.voxelSize) {
                    throw vdbclay::Error("--voxel-size: fog volume \"" + fogGrid + "\" in " + impIn +
                                         " is taken voxel for voxel at its own voxel size " +
                                         std::to_string(fog.voxelSize) + "; leave --voxel-size out");
                }
                vdbclay::ClayMeta meta;
                meta.dimensions = impDims;
                meta.voxelSize = fog.voxelSize;
                meta.up = upOption(impUp);
                gWriting.store(true);
                vdbclay::writeClayFile(impOut, *fog.mass, meta);
                std::printf("note: %s\n", fog.note.c_str());
                std::printf("wrote %s: %llu voxels, mass %lld\n", impOut.c_str(),
                            (unsigned long long)vdbclay::clayVoxelCount(*fog.mass),
                            (long long)vdbclay::totalMass(*fog.mass));
                return 0;
            }
            if (impVoxel == 0 && isVdb) {
                // The level set's own voxel size; loadLevelSet checks the file before OpenVDB reads it.
                vdbclay::loadLevelSet(impIn, 1.0, impGrid, upOption(impUp));
                openvdb::io::File f(impIn);
                f.open(false);
                std::string name = impGrid;
                if (name.empty()) {
                    // Held: a range-for over *f.readAllGridMetadata() would read a freed vector.
                    const openvdb::GridPtrVecPtr grids = f.readAllGridMetadata();
                    for (const auto& g : *grids) {
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
            uint64_t budget = 0; // the default
            if (!impBudget.empty()) {
                try {
                    budget = vdbclay::parseByteSize(impBudget);
                } catch (const vdbclay::Error& e) {
                    throw vdbclay::Error(std::string("--memory-budget: ") + e.what());
                }
            }
            const vdbclay::ShapePtr shape =
                isVdb ? vdbclay::loadLevelSet(impIn, impVoxel, impGrid, upOption(impUp))
                      : vdbclay::loadMesh(impIn, impVoxel, upOption(impUp), vdbclay::Placement(), budget);
            { // the clay makeClay builds must fit the default memory budget
                vdbclay::Scene sc;
                sc.source = "import " + impIn;
                sc.dimensions = impDims;
                vdbclay::ClaySpec c;
                c.shape.kind = isVdb ? "levelset" : "mesh";
                c.shape.field = "import";
                c.shape.shape = shape;
                c.mass = int32_t(impMass);
                sc.clay.push_back(c);
                sc.memoryBudget = budget;
                vdbclay::checkMemoryBudget(sc);
            }
            const vdbclay::MassGridPtr clay = vdbclay::makeClay(*shape, int32_t(impMass), impDims);
            vdbclay::ClayMeta meta;
            meta.dimensions = impDims;
            meta.voxelSize = impVoxel;
            meta.up = upOption(impUp);
            gWriting.store(true);
            vdbclay::writeClayFile(impOut, *clay, meta);
            if (shape->describe().find("winding number") != std::string::npos) {
                std::printf("note: %s\n",
                            shape->describe().c_str()); // open or non-manifold: how it was filled
            }
            std::printf("wrote %s: %llu voxels, mass %lld\n", impOut.c_str(),
                        (unsigned long long)vdbclay::clayVoxelCount(*clay),
                        (long long)vdbclay::totalMass(*clay));
            return 0;
        }
        if (*demo) {
            if (!demoRule.empty()) {
                try {
                    da.opts.rule.rule = vdbclay::parseRule(demoRule);
                } catch (const vdbclay::Error& e) {
                    throw vdbclay::Error(std::string("--rule: ") + e.what());
                }
            }
            vdbclay::validate(da.opts.rule);
            if (int64_t(da.overload) * da.opts.rule.threshold > INT32_MAX) {
                throw vdbclay::Error("--overload x --threshold exceeds the int32 range of a cell");
            }
            checkOutputs({{"-o", da.out}}, {});
            checkDemoMemory(da);
            return runDemo(da);
        }
    } catch (const std::bad_alloc&) {
        std::cerr
            << "vdbclay: error: out of memory (the memory estimate fell short; lower --memory-budget or "
               "shrink the input)\n";
        return 1;
    } catch (const std::exception& e) {
        std::cerr << "vdbclay: error: " << printable(e.what()) << "\n";
        return 1;
    }
    return 0;
}
