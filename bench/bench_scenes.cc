// bench_scenes: vdbclay on whole scenes, against two baselines written here for comparison only. The
// scenes are templates in data/scenes/bench (press.json.in, stroke.json.in: the size filled in).
//
//   press   A cube N^3 of clay at 950 (Tc 1000, prorata, seed 1) on a floor, pressed N/8 voxels by a
//           plate wider than the cube over N/8 frames with no settling between frames (settle
//           max_steps 0): the state right after the last push, all N/8 pushed layers piled on the
//           top layer. Then that state is settled to rest by
//             vdbclay   Automaton::settle, for each --threads count (min of --repeats);
//             DENSE     a dense std::vector<int32_t> box (the final clay's bounds + 4 voxels) that
//                       visits every block of the phase every step, with the inline rule
//                       (rules_internal::repartition) and the same block keys;
//             NAIVE     OpenVDB as a user writes it first: each step, every active voxel's block of
//                       the phase (collected, sorted, deduplicated), getValue / setValue through a
//                       ValueAccessor, obstacles through an accessor, the public repartitionBlock,
//                       single-threaded.
//           All must end bit-identical (contentHash). A baseline whose projected time (its time per
//           step so far x vdbclay's step count) exceeds --baseline-limit seconds is stopped and
//           reported as an estimate.
//   --layers  also DENSE swept in horizontal layers: one thread, fork-join per step, the paper's
//           two-thread Petri net pipeline (T threads, step k on thread k mod T) and temporal
//           blocking (D steps as a wavefront); all bit-identical to DENSE.
//   stroke  A sphere of clay of diameter D (mass 950) and a sphere tool of radius 6 that dips 2
//           voxels into its top and then slides along the surface (rotating about the sphere's
//           centre, 2 voxels per frame) for 10 frames in all, each settled fully; run --repeats
//           times from scratch. Time per frame (median, p95 of the 10 x repeats frames), grid
//           memory per clay voxel and peak RSS; each (D, threads) in a child process so ru_maxrss
//           is its own.
//
// Output: CSV (one header, one row per measurement) to stdout or --csv FILE; a readable summary
// with the ratios on stderr. See docs/PERFORMANCE.md.
#include "automaton/RulesImpl.h"
#include "vdbclay/Automaton.h"
#include "vdbclay/BatchHeap.h"
#include "vdbclay/Metrics.h"
#include "vdbclay/Rules.h"
#include "vdbclay/Scene.h"
#include "vdbclay/Sculpt.h"

#include <openvdb/openvdb.h>

#include <sys/resource.h>
#include <sys/wait.h>
#include <unistd.h>

#include <tbb/blocked_range.h>
#include <tbb/parallel_for.h>
#include <tbb/task_arena.h>

#include <algorithm>
#include <atomic>
#include <chrono>
#include <climits>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <exception>
#include <fstream>
#include <iterator>
#include <mutex>
#include <sstream>
#include <string>
#include <thread>
#include <vector>

namespace {

using namespace vdbclay;
using openvdb::Coord;
using Clock = std::chrono::steady_clock;

double since(Clock::time_point t0)
{
    return std::chrono::duration<double>(Clock::now() - t0).count();
}

struct Options {
    std::vector<int> press{32, 64, 128};
    std::vector<int> stroke{64, 128, 256, 512};
    std::vector<int> threads{1, 2};
    int repeats = 3;
    double baselineLimit = 60; ///< seconds; projected longer: stop and estimate
    double vdbLimit = 60;      ///< seconds; vdbclay settling longer than this is stopped
    bool baselines = true;
    bool layers = false;     ///< also the layer schedules of DENSE (forkjoin, pipe, tblock)
    uint64_t pressSteps = 0; ///< 0: settle to rest; K: run K steps only (every implementation)
    std::string csv;
    std::string scenes = "data/scenes/bench"; ///< where press.json.in and stroke.json.in are
};

std::vector<int> parseList(const std::string& s)
{
    std::vector<int> v;
    if (s == "none" || s.empty()) return v;
    std::stringstream ss(s);
    std::string item;
    while (std::getline(ss, item, ','))
        v.push_back(std::stoi(item));
    return v;
}

// ---- CSV rows -----------------------------------------------------------------------------------
const char* kHeader =
    "scene,size,impl,threads,seconds,steps,blocks_visited,blocks_updated,ns_per_updated_block,"
    "gather_s,repartition_s,grow_s,bookkeeping_s,pass_busy_s,pass_idle_s,frame_median_ms,frame_p95_ms,frame_"
    "max_ms,"
    "clay_voxels,grid_bytes,bytes_per_clay_voxel,maxrss_mb,hash,identical,note";

struct Row {
    std::string scene, impl, note, identical;
    int size = 0, threads = 1;
    double seconds = 0;
    uint64_t steps = 0, visited = 0, updated = 0;
    StageSeconds stages;
    double medianMs = -1, p95Ms = -1, maxMs = -1;
    uint64_t clayVoxels = 0, gridBytes = 0;
    double maxrssMb = -1;
    uint64_t hash = 0;

    std::string csv() const
    {
        char buf[1024];
        auto opt = [](double v) { return v < 0 ? std::string() : std::to_string(v); };
        std::snprintf(buf, sizeof buf,
                      "%s,%d,%s,%d,%.6f,%llu,%llu,%llu,%.2f,%.6f,%.6f,%.6f,%.6f,%.6f,%.6f,%s,%s,%s,%llu,%llu,"
                      "%s,%s,%016llx,%s,%s",
                      scene.c_str(), size, impl.c_str(), threads, seconds, (unsigned long long)steps,
                      (unsigned long long)visited, (unsigned long long)updated,
                      updated ? 1e9 * seconds / double(updated) : 0.0, stages.gather, stages.repartition,
                      stages.grow, stages.bookkeeping, stages.passBusy, stages.passIdle,
                      opt(medianMs).c_str(), opt(p95Ms).c_str(), opt(maxMs).c_str(),
                      (unsigned long long)clayVoxels, (unsigned long long)gridBytes,
                      clayVoxels ? std::to_string(double(gridBytes) / double(clayVoxels)).c_str() : "",
                      opt(maxrssMb).c_str(), (unsigned long long)hash, identical.c_str(), note.c_str());
        return buf;
    }
};

double maxrssMb()
{
    rusage ru{};
    getrusage(RUSAGE_SELF, &ru);
    return double(ru.ru_maxrss) / 1024.0; // Linux: kilobytes
}

// ---- press: the state to settle ------------------------------------------------------------------
struct State {
    MassGridPtr mass;
    ObstacleGridPtr obstacles;
    uint64_t step0 = 0;
    AutomatonOptions options;
};

/// The scene template @a name in opt.scenes (data/scenes/bench by default) with every {{key}} replaced by
/// its value, each number printed with 10 significant digits. @throw Error if the file cannot be read
/// or a {{...}} is left.
Scene sceneFromTemplate(const Options& opt, const std::string& name,
                        const std::vector<std::pair<std::string, double>>& values)
{
    const std::string path = opt.scenes + "/" + name;
    std::ifstream in(path, std::ios::binary);
    if (!in)
        throw Error(path +
                    ": cannot read the scene template (run from the repository root or pass --scenes)");
    std::string text((std::istreambuf_iterator<char>(in)), std::istreambuf_iterator<char>());
    std::string label;
    for (const auto& [key, value] : values) {
        std::ostringstream v;
        v.precision(10);
        v << value;
        const std::string placeholder = "{{" + key + "}}";
        for (size_t at = text.find(placeholder); at != std::string::npos; at = text.find(placeholder, at))
            text.replace(at, placeholder.size(), v.str());
        label += (label.empty() ? " (" : ", ") + key + " " + v.str();
    }
    if (const size_t left = text.find("{{"); left != std::string::npos)
        throw Error(path + ": no value for " + text.substr(left, text.find("}}", left) + 2 - left));
    return parseScene(text, path + label + ")", opt.scenes);
}

/// The press scene for a cube of @a n (data/scenes/bench/press.json.in).
Scene pressScene(const Options& opt, int n)
{
    return sceneFromTemplate(opt, "press.json.in",
                             {{"n", n},
                              {"last", n - 1},
                              {"frames", std::max(1, n / 8)},
                              {"plate_min", -n / 2},
                              {"plate_max", n + n / 2 - 1},
                              {"plate_top", n + 3},
                              {"floor_min", -2 * n},
                              {"floor_max", 3 * n}});
}

State makePress(const Options& opt, int n)
{
    const Scene scene = pressScene(opt, n);
    Sculptor sculptor(scene, 0);
    sculptor.run();
    State st;
    st.mass = sculptor.mass()->deepCopy();
    st.obstacles = sculptor.automaton().obstacles()->deepCopy();
    st.step0 = sculptor.automaton().stepCount();
    st.options.dimensions = 3;
    st.options.rule = scene.rule;
    st.options.seed = scene.seed;
    return st;
}

struct Result {
    Row row;
    MassGridPtr grid; ///< final state
    bool complete = true;
};

/// After each baseline step: true when the run must stop, either because its projected time exceeds
/// @a limit before it reaches vdbclay's step count (then res.complete = false and its time is
/// extrapolated), or because it ran far past vdbclay's steps.
bool baselineMustStop(Result& res, uint64_t steps, uint64_t refSteps, double elapsed, double limit)
{
    if (elapsed > 1.0 && elapsed / double(steps) * double(std::max(refSteps, steps)) > limit &&
        steps < refSteps) {
        res.complete = false;
        return true;
    }
    if (steps > 4 * refSteps + 100) {
        res.row.note = "ran past 4x vdbclay's steps";
        return true;
    }
    return false;
}

/// Fills a baseline's row; an incomplete run's time is extrapolated to vdbclay's step count.
void finishBaseline(Result& res, const char* impl, double seconds, uint64_t steps, uint64_t visited,
                    uint64_t updated, uint64_t refSteps)
{
    res.row.seconds = seconds;
    res.row.impl = impl;
    res.row.steps = steps;
    res.row.visited = visited;
    res.row.updated = updated;
    if (!res.complete) {
        res.row.note = "estimated: " + std::to_string(steps) + " of " + std::to_string(refSteps) +
                       " steps run, time extrapolated";
        res.row.seconds = seconds / double(steps) * double(refSteps);
    }
}

Result runVdbclay(const State& st, int threads, double limit, uint64_t maxSteps)
{
    Result res;
    res.grid = st.mass->deepCopy();
    AutomatonOptions o = st.options;
    o.threads = threads;
    Automaton a(res.grid, o, st.obstacles->deepCopy());
    a.setStepCount(st.step0);
    StepReport total;
    const auto t0 = Clock::now();
    for (;;) {
        const uint64_t chunk = maxSteps ? std::min<uint64_t>(256, maxSteps - total.steps) : 256;
        const StepReport r = a.settle(chunk);
        total += r;
        if (r.reason != StopReason::StepBudget) break;
        if (maxSteps && total.steps >= maxSteps) break;
        if (since(t0) > limit) {
            res.complete = false;
            break;
        }
    }
    res.row.seconds = since(t0);
    res.row.impl = "vdbclay";
    res.row.threads = threads;
    res.row.steps = total.steps;
    res.row.visited = total.blocksVisited;
    res.row.updated = total.blocksUpdated;
    res.row.stages = total.seconds;
    res.row.hash = contentHash(*res.grid);
    if (!res.complete) res.row.note = "stopped after " + std::to_string(limit) + " s, not settled";
    return res;
}

// ---- DENSE baseline ------------------------------------------------------------------------------
struct Dense {
    int x0, y0, z0, nx, ny, nz;
    std::vector<int32_t> m;
    std::vector<uint8_t> obs;
    size_t idx(int x, int y, int z) const
    {
        return size_t(x) + size_t(nx) * (size_t(y) + size_t(ny) * size_t(z));
    }
};

openvdb::CoordBBox clayBounds(const MassGrid& g)
{
    openvdb::CoordBBox bb;
    for (auto leaf = g.tree().cbeginLeaf(); leaf; ++leaf)
        for (auto v = leaf->cbeginValueAll(); v; ++v)
            if (*v != 0) bb.expand(v.getCoord());
    return bb;
}

Dense toDense(const State& st, openvdb::CoordBBox bb)
{
    bb.expand(4);
    Dense d;
    d.x0 = bb.min().x() & ~1; // even: local parity = world parity
    d.y0 = bb.min().y() & ~1;
    d.z0 = bb.min().z() & ~1;
    d.nx = bb.max().x() - d.x0 + 1;
    d.ny = bb.max().y() - d.y0 + 1;
    d.nz = bb.max().z() - d.z0 + 1;
    d.m.assign(size_t(d.nx) * d.ny * d.nz, 0);
    d.obs.assign(d.m.size(), 0);
    for (auto leaf = st.mass->tree().cbeginLeaf(); leaf; ++leaf)
        for (auto v = leaf->cbeginValueAll(); v; ++v)
            if (*v != 0) {
                const Coord c = v.getCoord();
                d.m[d.idx(c.x() - d.x0, c.y() - d.y0, c.z() - d.z0)] = *v;
            }
    const openvdb::CoordBBox box(Coord(d.x0, d.y0, d.z0),
                                 Coord(d.x0 + d.nx - 1, d.y0 + d.ny - 1, d.z0 + d.nz - 1));
    for (auto it = st.obstacles->tree().cbeginValueOn(); it; ++it) {
        openvdb::CoordBBox b = it.getBoundingBox();
        b.intersect(box);
        if (b.empty()) continue;
        for (int z = b.min().z(); z <= b.max().z(); ++z)
            for (int y = b.min().y(); y <= b.max().y(); ++y)
                for (int x = b.min().x(); x <= b.max().x(); ++x)
                    d.obs[d.idx(x - d.x0, y - d.y0, z - d.z0)] = 1;
    }
    return d;
}

MassGridPtr fromDense(const Dense& d)
{
    auto g = openvdb::Int32Grid::create(0);
    auto acc = g->getAccessor();
    for (int z = 0; z < d.nz; ++z)
        for (int y = 0; y < d.ny; ++y)
            for (int x = 0; x < d.nx; ++x) {
                const int32_t v = d.m[d.idx(x, y, z)];
                if (v) acc.setValue(Coord(x + d.x0, y + d.y0, z + d.z0), v);
            }
    return g;
}

inline int64_t over(int64_t m, int64_t tc)
{
    return m > tc ? m - tc : 0;
}

/// What one step (or one row of a step) did.
struct LayerStats {
    uint64_t changed = 0, visited = 0;
    int64_t overloadDelta = 0;
};

/// DENSE's unit of work: the block at local (x, y, z) of @a step, updated in place.
inline void denseBlock(Dense& d, const CompiledRule& rule, int x, int y, int z, uint64_t step, uint64_t seed,
                       const size_t* off, LayerStats& st)
{
    const size_t base = d.idx(x, y, z);
    int32_t m[8];
    uint32_t valid = 0;
    for (int i = 0; i < 8; ++i) {
        m[i] = d.m[base + off[i]];
        valid |= uint32_t(!d.obs[base + off[i]]) << i;
    }
    ++st.visited;
    const BlockKey key{d.x0 + x, d.y0 + y, d.z0 + z, step, seed};
    int64_t out[8];
    const uint32_t ch = rules_internal::repartition(rule, 8, m, valid, key, out);
    if (!ch) return;
    ++st.changed;
    const int64_t tc = rule.threshold;
    for (int i = 0; i < 8; ++i) {
        if (!((ch >> i) & 1u)) continue;
        if (out[i] > INT32_MAX) throw Error("dense: overflow");
        if ((valid >> i) & 1u) st.overloadDelta += over(out[i], tc) - over(m[i], tc);
        d.m[base + off[i]] = int32_t(out[i]);
    }
}

/// Folds step stats in step order and says when a run stops: the overload is 0, two steps in a row
/// changed nothing (vdbclay's "settled"), or @a cap steps have run.
struct StopTracker {
    int64_t overload;
    uint64_t cap; ///< steps allowed (the budget or a safety cap)
    uint64_t done = 0, updated = 0, visited = 0;
    int quiet = 0;
    bool stopped;
    StopTracker(int64_t overload0, uint64_t cap0) : overload(overload0), cap(cap0), stopped(overload0 <= 0) {}
    void add(const LayerStats& s)
    {
        if (stopped) return;
        ++done;
        updated += s.changed;
        visited += s.visited;
        overload += s.overloadDelta;
        quiet = s.changed ? 0 : quiet + 1;
        if (overload <= 0 || quiet >= 2 || done >= cap) stopped = true;
    }
};

/// Runs steps until the overload is 0 or two steps in a row change nothing (vdbclay's "settled"),
/// or the projected time exceeds @a limit (then the time is extrapolated to @a refSteps steps).
Result runDense(const State& st, const openvdb::CoordBBox& bounds, uint64_t refSteps, double limit,
                uint64_t maxSteps)
{
    Dense d = toDense(st, bounds);
    const CompiledRule rule = compileRule(st.options.rule);
    StopTracker track(residualOverload(*st.mass, st.options.rule.threshold, st.obstacles.get()),
                      maxSteps ? maxSteps : UINT64_MAX);
    uint64_t step = st.step0;
    size_t off[8];
    for (int i = 0; i < 8; ++i)
        off[i] = d.idx(i & 1, (i >> 1) & 1, i >> 2);
    Result res;
    const auto t0 = Clock::now();
    while (!track.stopped) {
        const int p = int(step & 1);
        LayerStats ls;
        for (int z = p; z + 1 < d.nz; z += 2)
            for (int y = p; y + 1 < d.ny; y += 2)
                for (int x = p; x + 1 < d.nx; x += 2)
                    denseBlock(d, rule, x, y, z, step, st.options.seed, off, ls);
        track.add(ls);
        ++step;
        if (baselineMustStop(res, track.done, refSteps, since(t0), limit)) break;
    }
    finishBaseline(res, "dense", since(t0), track.done, track.visited, track.updated, refSteps);
    if (res.complete) {
        res.grid = fromDense(d);
        res.row.hash = contentHash(*res.grid);
    }
    return res;
}

// ---- DENSE swept in horizontal layers: the paper's section 4, and temporal blocking ----------------
// The same lattice, rule and block keys as DENSE, so the same result, swept in layers of blocks along
// y. Block row j of phase p covers y = p + 2j and p + 2j + 1 (all x, z). Row j of step s reads and
// writes cells that rows i <= need(j) of step s - 1 (the other phase) touch, so it may run once those
// rows are done: rows of one step run in order, and steps follow one another at a lag of one or two
// rows. Three schedules:
//   layers    one thread, one step after the other, row by row (DENSE's work in layer order);
//   forkjoin T each step's rows shared by T threads (tbb::parallel_for), a join between steps: how
//             vdbclay itself runs a step;
//   pipe T    the paper's Petri net generalised to T threads: thread k runs steps k, k+T, k+2T, ...
//             and waits, before each row, for the previous step to have done the rows it needs. The
//             paper's two-thread case is T = 2 (one thread for even steps, one for odd steps).
//   tblock D  temporal blocking on one thread: D consecutive steps advance together as a wavefront
//             (row w of step s, row w - 2 of step s + 1, ...), so a layer is reused while in cache.
// Steps are never cut short: a run stops after the step where the overload reaches 0 or the second
// of two steps that change nothing. A step begun past that point changes nothing either (a block
// with a cell over Tc and a cell under it always changes, whatever its key), so stopping late gives
// the identical grid; the reported step count is where the stop condition first held.
int layerRows(const Dense& d, int phase)
{
    return std::max(0, (d.ny - phase) / 2);
}

/// The rows of the previous step (phase 1 - p) that must be done before row j of phase p runs.
int rowsNeeded(const Dense& d, int p, int j)
{
    const int q = 1 - p;
    return std::min(layerRows(d, q), (p + 2 * j + 1 - q) / 2 + 1);
}

void denseRow(Dense& d, const CompiledRule& rule, uint64_t step, uint64_t seed, int j, const size_t* off,
              LayerStats& st)
{
    const int p = int(step & 1);
    for (int z = p; z + 1 < d.nz; z += 2)
        for (int x = p; x + 1 < d.nx; x += 2)
            denseBlock(d, rule, x, p + 2 * j, z, step, seed, off, st);
}

enum class Schedule { Layers, ForkJoin, Pipe, TBlock };

Result runDenseLayers(const State& st, const openvdb::CoordBBox& bounds, uint64_t cap, Schedule sched,
                      int width)
{
    Dense d = toDense(st, bounds);
    const CompiledRule rule = compileRule(st.options.rule);
    const uint64_t seed = st.options.seed, s0 = st.step0;
    size_t off[8];
    for (int i = 0; i < 8; ++i)
        off[i] = d.idx(i & 1, (i >> 1) & 1, i >> 2);
    StopTracker track(residualOverload(*st.mass, st.options.rule.threshold, st.obstacles.get()), cap);
    Result res;
    const auto t0 = Clock::now();

    if (sched == Schedule::Layers || (sched == Schedule::TBlock && width <= 1)) {
        for (uint64_t s = s0; !track.stopped; ++s) {
            LayerStats ls;
            for (int j = 0, n = layerRows(d, int(s & 1)); j < n; ++j)
                denseRow(d, rule, s, seed, j, off, ls);
            track.add(ls);
        }
    } else if (sched == Schedule::ForkJoin) {
        tbb::task_arena arena(std::max(1, width));
        std::vector<LayerStats> perRow;
        for (uint64_t s = s0; !track.stopped; ++s) {
            perRow.assign(size_t(layerRows(d, int(s & 1))), LayerStats{});
            arena.execute([&] {
                tbb::parallel_for(tbb::blocked_range<int>(0, int(perRow.size())),
                                  [&](const tbb::blocked_range<int>& r) {
                                      for (int j = r.begin(); j != r.end(); ++j)
                                          denseRow(d, rule, s, seed, j, off, perRow[size_t(j)]);
                                  });
            });
            LayerStats ls;
            for (const LayerStats& r : perRow) {
                ls.changed += r.changed;
                ls.visited += r.visited;
                ls.overloadDelta += r.overloadDelta;
            }
            track.add(ls);
        }
    } else if (sched == Schedule::TBlock) {
        // D steps as a wavefront, 2 rows apart: at wave w, step s + k does row w - 2k, after step
        // s + k - 1 did row w - 2k + 2 >= rowsNeeded - 1 in the same wave.
        const int rmax = std::max(layerRows(d, 0), layerRows(d, 1));
        std::vector<LayerStats> ls(static_cast<size_t>(width));
        for (uint64_t s = s0; !track.stopped; s += uint64_t(width)) {
            const int depth = int(std::min<uint64_t>(uint64_t(width), track.cap - track.done));
            std::fill(ls.begin(), ls.end(), LayerStats{});
            for (int w = 0; w < rmax + 2 * (depth - 1); ++w)
                for (int k = 0; k < depth; ++k) {
                    const int j = w - 2 * k;
                    if (j >= 0 && j < layerRows(d, int((s + uint64_t(k)) & 1)))
                        denseRow(d, rule, s + uint64_t(k), seed, j, off, ls[size_t(k)]);
                }
            for (int k = 0; k < depth; ++k)
                track.add(ls[size_t(k)]);
        }
    } else {
        // The Petri net: progress[k] = (step - s0) * stride + rows done by thread k's current step.
        // Release/acquire on it orders one step's writes before the next step's reads of those rows.
        const int T = std::max(1, width);
        const int64_t stride = int64_t(std::max(layerRows(d, 0), layerRows(d, 1))) + 2;
        std::vector<std::atomic<int64_t>> progress(static_cast<size_t>(T));
        for (auto& a : progress)
            a.store(-1);
        std::vector<LayerStats> stats(static_cast<size_t>(track.cap));
        std::atomic<uint64_t> stopAfter{track.stopped ? 0 : UINT64_MAX}; // steps (from s0) worth running
        std::mutex foldMutex;
        std::exception_ptr failure;
        auto waitFor = [&](uint64_t i, int64_t rows) { // step index i has done `rows` rows (or stop)
            const std::atomic<int64_t>& a = progress[size_t(i % uint64_t(T))];
            const int64_t target = int64_t(i) * stride + rows;
            while (a.load(std::memory_order_acquire) < target) {
                if (i + 1 >= stopAfter.load(std::memory_order_acquire)) return false;
                std::this_thread::yield();
            }
            return true;
        };
        auto worker = [&](int k) {
            try {
                for (uint64_t i = uint64_t(k); i < track.cap && i < stopAfter.load(); i += uint64_t(T)) {
                    const uint64_t s = s0 + i;
                    const int p = int(s & 1);
                    LayerStats& ls = stats[size_t(i)];
                    bool abandoned = false;
                    for (int j = 0, n = layerRows(d, p); j < n && !abandoned; ++j) {
                        if (i > 0 && !waitFor(i - 1, rowsNeeded(d, p, j)))
                            abandoned = true;
                        else {
                            denseRow(d, rule, s, seed, j, off, ls);
                            progress[size_t(k)].store(int64_t(i) * stride + j + 1, std::memory_order_release);
                        }
                    }
                    if (abandoned) return; // past the stop: changes nothing (see above)
                    // Fold the stats in step order: wait for the previous step to be folded.
                    if (i > 0 && !waitFor(i - 1, stride - 1)) return;
                    {
                        std::lock_guard<std::mutex> lock(foldMutex);
                        track.add(ls);
                        if (track.stopped && stopAfter.load() == UINT64_MAX) stopAfter.store(track.done);
                    }
                    progress[size_t(k)].store(int64_t(i) * stride + stride - 1, std::memory_order_release);
                }
            } catch (...) {
                std::lock_guard<std::mutex> lock(foldMutex);
                if (!failure) failure = std::current_exception();
                stopAfter.store(0);
            }
        };
        std::vector<std::thread> pool;
        for (int k = 1; k < T; ++k)
            pool.emplace_back(worker, k);
        worker(0);
        for (auto& t : pool)
            t.join();
        if (failure) std::rethrow_exception(failure);
    }
    const double secs = since(t0);
    static const char* const names[] = {"layers", "forkjoin", "pipe", "tblock"};
    finishBaseline(res, names[int(sched)], secs, track.done, track.visited, track.updated, track.done);
    res.row.threads = sched == Schedule::Pipe || sched == Schedule::ForkJoin ? width : 1;
    if (sched == Schedule::TBlock) res.row.note = "depth " + std::to_string(width);
    res.grid = fromDense(d);
    res.row.hash = contentHash(*res.grid);
    return res;
}

// ---- NAIVE OpenVDB baseline ----------------------------------------------------------------------
Result runNaive(const State& st, uint64_t refSteps, double limit, uint64_t maxSteps)
{
    Result res;
    MassGridPtr g = st.mass->deepCopy();
    const CompiledRule rule = compileRule(st.options.rule);
    const int64_t tc = rule.threshold;
    StopTracker track(residualOverload(*g, st.options.rule.threshold, st.obstacles.get()),
                      maxSteps ? maxSteps : UINT64_MAX);
    auto obs = st.obstacles->getConstAccessor();
    uint64_t step = st.step0;
    std::vector<Coord> blocks;
    const auto t0 = Clock::now();
    while (!track.stopped) {
        const int p = int(step & 1);
        blocks.clear();
        for (auto leaf = g->tree().cbeginLeaf(); leaf; ++leaf)
            for (auto v = leaf->cbeginValueOn(); v; ++v) {
                const Coord c = v.getCoord();
                blocks.emplace_back(((c.x() - p) & ~1) + p, ((c.y() - p) & ~1) + p, ((c.z() - p) & ~1) + p);
            }
        std::sort(blocks.begin(), blocks.end());
        blocks.erase(std::unique(blocks.begin(), blocks.end()), blocks.end());
        auto acc = g->getAccessor();
        LayerStats ls;
        for (const Coord& b : blocks) {
            int32_t m[8];
            uint32_t valid = 0;
            Coord c[8];
            for (int i = 0; i < 8; ++i) {
                c[i] = b.offsetBy(i & 1, (i >> 1) & 1, i >> 2);
                m[i] = acc.getValue(c[i]);
                if (!obs.isValueOn(c[i])) valid |= 1u << i;
            }
            ++ls.visited;
            const BlockKey key{b.x(), b.y(), b.z(), step, st.options.seed};
            int64_t out[8];
            const uint32_t ch = repartitionBlock(rule, 8, m, valid, key, out);
            if (!ch) continue;
            ++ls.changed;
            for (int i = 0; i < 8; ++i) {
                if (!((ch >> i) & 1u)) continue;
                if (out[i] > INT32_MAX) throw Error("naive: overflow");
                if ((valid >> i) & 1u) ls.overloadDelta += over(out[i], tc) - over(m[i], tc);
                acc.setValue(c[i], int32_t(out[i]));
            }
        }
        track.add(ls);
        ++step;
        if (baselineMustStop(res, track.done, refSteps, since(t0), limit)) break;
    }
    finishBaseline(res, "naive", since(t0), track.done, track.visited, track.updated, refSteps);
    if (res.complete) {
        res.grid = g;
        res.row.hash = contentHash(*res.grid);
    }
    return res;
}

// ---- the press scene -----------------------------------------------------------------------------
void press(const Options& opt, int n, std::vector<Row>& rows)
{
    const auto tSetup = Clock::now();
    const State st = makePress(opt, n);
    std::fprintf(stderr, "\npress N=%d%s: set-up %.2f s, %llu clay voxels, overload %lld, step %llu\n", n,
                 opt.pressSteps ? (" (first " + std::to_string(opt.pressSteps) + " steps)").c_str()
                                : " (settle to rest)",
                 since(tSetup), (unsigned long long)clayVoxelCount(*st.mass),
                 (long long)residualOverload(*st.mass, st.options.rule.threshold, st.obstacles.get()),
                 (unsigned long long)st.step0);

    // vdbclay, min of repeats per thread count.
    std::vector<Row> vdb;
    MassGridPtr finalGrid;
    bool vdbComplete = true;
    for (int t : opt.threads) {
        Row best;
        for (int r = 0; r < opt.repeats; ++r) {
            Result res = runVdbclay(st, t, opt.vdbLimit, opt.pressSteps);
            if (!res.complete) vdbComplete = false;
            if (r == 0 || res.row.seconds < best.seconds) best = res.row;
            if (!finalGrid) finalGrid = res.grid;
            if (!res.complete || res.row.seconds > 10) break; // long runs: one is enough
        }
        best.scene = "press";
        best.size = n;
        vdb.push_back(best);
    }
    const uint64_t h = vdb.front().hash;
    bool threadsAgree = true;
    for (const Row& r : vdb)
        threadsAgree = threadsAgree && r.hash == h;
    for (Row& r : vdb)
        r.identical = threadsAgree ? "yes" : "no";
    const Row& ref = vdb.front(); // the first thread count (1 by default)

    std::vector<Row> base;
    if (opt.baselines && vdbComplete) {
        const openvdb::CoordBBox bb = clayBounds(*finalGrid);
        for (int which = 0; which < 2; ++which) {
            Row best;
            for (int r = 0; r < opt.repeats; ++r) {
                Result res = which == 0 ? runDense(st, bb, ref.steps, opt.baselineLimit, opt.pressSteps)
                                        : runNaive(st, ref.steps, opt.baselineLimit, opt.pressSteps);
                if (r == 0 || res.row.seconds < best.seconds) best = res.row;
                if (!res.complete || res.row.seconds > 10) break;
            }
            best.scene = "press";
            best.size = n;
            best.threads = 1;
            best.identical = best.note.rfind("estimated", 0) == 0 ? "n/a" : (best.hash == h ? "yes" : "no");
            base.push_back(best);
        }
        // The layer schedules (paper section 4; temporal blocking), when DENSE itself completed.
        if (opt.layers && !base.empty() && base.front().identical != "n/a") {
            const uint64_t cap = opt.pressSteps ? opt.pressSteps : ref.steps + 2;
            std::vector<std::pair<Schedule, int>> runs{{Schedule::Layers, 1}};
            for (int t : opt.threads)
                if (t > 1) {
                    runs.emplace_back(Schedule::ForkJoin, t);
                    runs.emplace_back(Schedule::Pipe, t);
                }
            runs.emplace_back(Schedule::TBlock, 2);
            runs.emplace_back(Schedule::TBlock, 4);
            std::vector<Row> best(runs.size());
            for (int r = 0; r < opt.repeats; ++r) // round-robin, so load drift hits every schedule alike
                for (size_t k = 0; k < runs.size(); ++k) {
                    Result res = runDenseLayers(st, bb, cap, runs[k].first, runs[k].second);
                    if (r == 0 || res.row.seconds < best[k].seconds) best[k] = res.row;
                }
            for (Row& b : best) {
                b.scene = "press";
                b.size = n;
                b.identical = b.hash == h && b.steps == ref.steps ? "yes" : "no";
                base.push_back(b);
            }
        }
    }

    std::fprintf(stderr, "  %-8s %3s %8s %12s %12s %10s %9s %10s %s\n", "impl", "thr", "steps", "visited",
                 "updated", "seconds", "ns/upd", "vs vdb t1", "identical");
    auto line = [&](const Row& r) {
        std::fprintf(stderr, "  %-8s %3d %8llu %12llu %12llu %10.3f %9.1f %9.2fx %s %s\n", r.impl.c_str(),
                     r.threads, (unsigned long long)r.steps, (unsigned long long)r.visited,
                     (unsigned long long)r.updated, r.seconds,
                     r.updated ? 1e9 * r.seconds / double(r.updated) : 0.0, r.seconds / ref.seconds,
                     r.identical.c_str(), r.note.c_str());
    };
    for (const Row& r : vdb)
        line(r);
    for (const Row& r : base)
        line(r);
    for (const Row& r : vdb)
        std::fprintf(stderr,
                     "  vdbclay t%d stages: gather %.3f repartition %.3f grow %.3f bookkeeping %.3f (sum "
                     "%.3f of %.3f s); passes' threads busy %.3f idle %.3f thread-s\n",
                     r.threads, r.stages.gather, r.stages.repartition, r.stages.grow, r.stages.bookkeeping,
                     r.stages.total(), r.seconds, r.stages.passBusy, r.stages.passIdle);
    if (vdb.size() > 1)
        std::fprintf(stderr, "  speedup t%d -> t%d: %.2fx\n", vdb.front().threads, vdb.back().threads,
                     vdb.front().seconds / vdb.back().seconds);
    if (opt.baselines && !vdbComplete) std::fprintf(stderr, "  baselines skipped: vdbclay did not settle\n");
    rows.insert(rows.end(), vdb.begin(), vdb.end());
    rows.insert(rows.end(), base.begin(), base.end());
}

// ---- the stroke scene ----------------------------------------------------------------------------
/// The stroke scene for a clay sphere of diameter @a dia (data/scenes/bench/stroke.json.in).
Scene strokeScene(const Options& opt, int dia)
{
    const double r = dia / 2.0, c = dia / 2.0;
    const double deg =
        2.0 / (r + 4.0) * 180.0 / 3.14159265358979323846; // 2 voxels of arc per frame at the tool's centre
    return sceneFromTemplate(opt, "stroke.json.in",
                             {{"c", c}, {"tool_y", c + r + 7}, {"pivot_y", c + 3}, {"deg", deg}});
}

/// The stroke, @a repeats times from scratch (a new Sculptor each time): frame times are pooled over
/// the repeats (median and p95 of 10 x repeats frames: single 10-frame runs of ~2 ms frames move by
/// 0.5-1 ms), counts and stages are the first run's, and every run must end with the same hash.
std::vector<Row> strokeChild(const Options& opt, int dia, int threads, int repeats)
{
    const Scene scene = strokeScene(opt, dia);
    std::vector<double> ms, firstMs;
    uint64_t steps = 0, updated = 0, visited = 0;
    StageSeconds stages;
    double setup = 0;
    uint64_t hash = 0;
    uint64_t clayVoxels = 0, gridBytes = 0;
    for (int rep = 0; rep < repeats; ++rep) {
        const auto tSetup = Clock::now();
        Sculptor s(scene, threads);
        if (rep == 0) setup = since(tSetup);
        while (!s.done()) {
            const auto t0 = Clock::now();
            const FrameReport fr = s.runFrame();
            ms.push_back(1e3 * since(t0));
            if (rep) continue;
            firstMs.push_back(ms.back());
            steps += fr.settle.steps;
            updated += fr.settle.blocksUpdated;
            visited += fr.settle.blocksVisited;
            stages += fr.settle.seconds;
        }
        const uint64_t h = contentHash(*s.mass());
        if (rep == 0) {
            hash = h;
            clayVoxels = clayVoxelCount(*s.mass());
            gridBytes = s.mass()->memUsage();
        } else if (h != hash) {
            throw Error("stroke D=" + std::to_string(dia) + ": repeat " + std::to_string(rep + 1) +
                        " ended with a different hash");
        }
    }
    std::vector<double> sorted = ms;
    std::sort(sorted.begin(), sorted.end());
    auto pct = [&](double q) {
        // nearest-rank percentile
        const size_t k = size_t(std::ceil(q * double(sorted.size())));
        return sorted[std::min(sorted.size() - 1, k ? k - 1 : 0)];
    };
    Row r;
    r.scene = "stroke";
    r.size = dia;
    r.impl = "vdbclay";
    r.threads = threads;
    for (double v : firstMs)
        r.seconds += v / 1e3;
    r.steps = steps;
    r.visited = visited;
    r.updated = updated;
    r.stages = stages;
    r.medianMs = sorted.size() % 2 ? sorted[sorted.size() / 2]
                                   : 0.5 * (sorted[sorted.size() / 2 - 1] + sorted[sorted.size() / 2]);
    r.p95Ms = pct(0.95);
    r.maxMs = sorted.back();
    r.clayVoxels = clayVoxels;
    r.gridBytes = gridBytes;
    r.maxrssMb = maxrssMb();
    r.hash = hash;
    r.note = "setup " + std::to_string(setup) + " s; " + std::to_string(repeats) +
             " run(s) pooled; first run's frames ms:";
    for (double v : firstMs)
        r.note += " " + std::to_string(int(std::lround(v)));
    return {r};
}

/// Runs @a fn in a child process (its own ru_maxrss); its rows come back through a pipe.
template <typename Fn> std::vector<Row> inChild(Fn fn, bool& ok)
{
    int fds[2];
    if (pipe(fds) != 0) throw Error("pipe failed");
    std::fflush(stdout);
    std::fflush(stderr);
    const pid_t pid = fork();
    if (pid == 0) {
        close(fds[0]);
        int code = 0;
        try {
            std::vector<Row> rows = fn();
            for (const Row& r : rows) {
                // fixed binary layout would be fragile; send the fields we need as text
                std::ostringstream os;
                os << r.scene << '\t' << r.size << '\t' << r.impl << '\t' << r.threads << '\t' << r.seconds
                   << '\t' << r.steps << '\t' << r.visited << '\t' << r.updated << '\t' << r.stages.gather
                   << '\t' << r.stages.repartition << '\t' << r.stages.grow << '\t' << r.stages.bookkeeping
                   << '\t' << r.stages.passBusy << '\t' << r.stages.passIdle << '\t' << r.medianMs << '\t'
                   << r.p95Ms << '\t' << r.maxMs << '\t' << r.clayVoxels << '\t' << r.gridBytes << '\t'
                   << r.maxrssMb << '\t' << r.hash << '\t' << r.note << '\n';
                const std::string s = os.str();
                if (write(fds[1], s.data(), s.size()) != ssize_t(s.size())) code = 3;
            }
        } catch (const std::exception& e) {
            std::fprintf(stderr, "  child failed: %s\n", e.what());
            code = 2;
        }
        close(fds[1]);
        std::fflush(stderr);
        _exit(code);
    }
    close(fds[1]);
    std::string text;
    char buf[4096];
    ssize_t k;
    while ((k = read(fds[0], buf, sizeof buf)) > 0)
        text.append(buf, size_t(k));
    close(fds[0]);
    int status = 0;
    waitpid(pid, &status, 0);
    ok = WIFEXITED(status) && WEXITSTATUS(status) == 0;
    std::vector<Row> rows;
    std::istringstream is(text);
    std::string ln;
    while (std::getline(is, ln)) {
        std::istringstream f(ln);
        Row r;
        std::string tok;
        auto next = [&]() {
            std::getline(f, tok, '\t');
            return tok;
        };
        r.scene = next();
        r.size = std::stoi(next());
        r.impl = next();
        r.threads = std::stoi(next());
        r.seconds = std::stod(next());
        r.steps = std::stoull(next());
        r.visited = std::stoull(next());
        r.updated = std::stoull(next());
        r.stages.gather = std::stod(next());
        r.stages.repartition = std::stod(next());
        r.stages.grow = std::stod(next());
        r.stages.bookkeeping = std::stod(next());
        r.stages.passBusy = std::stod(next());
        r.stages.passIdle = std::stod(next());
        r.medianMs = std::stod(next());
        r.p95Ms = std::stod(next());
        r.maxMs = std::stod(next());
        r.clayVoxels = std::stoull(next());
        r.gridBytes = std::stoull(next());
        r.maxrssMb = std::stod(next());
        r.hash = std::stoull(next());
        r.note = next();
        rows.push_back(r);
    }
    return rows;
}

void stroke(const Options& opt, std::vector<Row>& rows)
{
    std::fprintf(stderr, "\nstroke: sphere of diameter D, tool radius 6, 10 frames\n");
    std::fprintf(stderr, "  %5s %3s %9s %9s %9s %8s %10s %10s %8s %9s %s\n", "D", "thr", "median", "p95",
                 "max", "steps", "updated", "clayvox", "B/vox", "rss MB", "identical");
    std::vector<Row> all;
    for (int dia : opt.stroke) {
        std::vector<Row> mine;
        for (int t : opt.threads) {
            bool ok = false;
            std::vector<Row> got = inChild([&] { return strokeChild(opt, dia, t, opt.repeats); }, ok);
            if (!ok || got.empty()) {
                std::fprintf(stderr, "  D=%d threads=%d: failed (see above)\n", dia, t);
                continue;
            }
            mine.insert(mine.end(), got.begin(), got.end());
        }
        bool agree = true;
        for (const Row& r : mine)
            agree = agree && r.hash == mine.front().hash;
        for (Row& r : mine) {
            r.identical = agree ? "yes" : "no";
            std::fprintf(stderr, "  %5d %3d %8.2fms %8.2fms %8.2fms %8llu %10llu %10llu %8.2f %9.1f %s\n",
                         r.size, r.threads, r.medianMs, r.p95Ms, r.maxMs, (unsigned long long)r.steps,
                         (unsigned long long)r.updated, (unsigned long long)r.clayVoxels,
                         double(r.gridBytes) / double(r.clayVoxels), r.maxrssMb, r.identical.c_str());
            std::fprintf(
                stderr,
                "        stages s: gather %.4f repartition %.4f grow %.4f bookkeeping %.4f; passes' threads "
                "busy %.4f idle %.4f thread-s; %s\n",
                r.stages.gather, r.stages.repartition, r.stages.grow, r.stages.bookkeeping, r.stages.passBusy,
                r.stages.passIdle, r.note.c_str());
        }
        all.insert(all.end(), mine.begin(), mine.end());
    }
    // Flatness: median frame time relative to the smallest D, per thread count.
    for (int t : opt.threads) {
        const Row* first = nullptr;
        for (const Row& r : all)
            if (r.threads == t) {
                if (!first) first = &r;
                std::fprintf(stderr, "  threads %d: D=%d median / D=%d median = %.2fx\n", t, r.size,
                             first->size, r.medianMs / first->medianMs);
            }
    }
    rows.insert(rows.end(), all.begin(), all.end());
}

int usage(const char* argv0)
{
    std::fprintf(stderr,
                 "usage: %s [--press 32,64,128] [--stroke 64,128,256,512] [--threads 1,2] [--repeats 3]\n"
                 "          [--baseline-limit 60] [--vdb-limit 60] [--no-baselines] [--csv FILE]\n"
                 "          [--press-steps K]  (press: K steps only instead of settling to rest)\n"
                 "          [--layers]  (press: also DENSE in layers: forkjoin, the paper's pipe, tblock)\n"
                 "          [--scenes DIR]  (the scene templates press.json.in, stroke.json.in; default\n"
                 "                          data/scenes/bench, from the repository root)\n"
                 "  a list may be 'none'\n",
                 argv0);
    return 2;
}

} // namespace

int main(int argc, char** argv)
{
    Options opt;
    try {
        for (int i = 1; i < argc; ++i) {
            const std::string a = argv[i];
            auto val = [&]() -> std::string {
                if (i + 1 >= argc) throw std::runtime_error("missing value after " + a);
                return argv[++i];
            };
            if (a == "--press")
                opt.press = parseList(val());
            else if (a == "--stroke")
                opt.stroke = parseList(val());
            else if (a == "--threads")
                opt.threads = parseList(val());
            else if (a == "--repeats")
                opt.repeats = std::max(1, std::stoi(val()));
            else if (a == "--baseline-limit")
                opt.baselineLimit = std::stod(val());
            else if (a == "--vdb-limit")
                opt.vdbLimit = std::stod(val());
            else if (a == "--press-steps")
                opt.pressSteps = std::stoull(val());
            else if (a == "--no-baselines")
                opt.baselines = false;
            else if (a == "--layers")
                opt.layers = true;
            else if (a == "--csv")
                opt.csv = val();
            else if (a == "--scenes")
                opt.scenes = val();
            else if (a == "-h" || a == "--help")
                return usage(argv[0]);
            else
                throw std::runtime_error("unknown argument " + a);
        }
        if (opt.threads.empty()) throw std::runtime_error("--threads needs at least one count");
    } catch (const std::exception& e) {
        std::fprintf(stderr, "bench_scenes: %s\n", e.what());
        return usage(argv[0]);
    }

    try {
        // The vdbclay command's allocator policy, so the stages measure what the command runs
        // (VDBCLAY_HEAP=system for glibc's defaults); the forked runs inherit it.
        std::fprintf(stderr, "bench_scenes: heap %s\n", vdbclay::configureBatchHeap().note.c_str());
    } catch (const std::exception& e) {
        std::fprintf(stderr, "bench_scenes: %s\n", e.what());
        return 2;
    }
    openvdb::initialize();
    std::vector<Row> rows;
    try {
        for (int n : opt.press)
            press(opt, n, rows);
        if (!opt.stroke.empty()) stroke(opt, rows);
    } catch (const std::exception& e) {
        std::fprintf(stderr, "bench_scenes: %s\n", e.what());
        return 1;
    }
    FILE* out = opt.csv.empty() ? stdout : std::fopen(opt.csv.c_str(), "w");
    if (!out) {
        std::fprintf(stderr, "bench_scenes: cannot write %s\n", opt.csv.c_str());
        return 1;
    }
    std::fprintf(out, "%s\n", kHeader);
    for (const Row& r : rows)
        std::fprintf(out, "%s\n", r.csv().c_str());
    if (out != stdout) std::fclose(out);
    return 0;
}
