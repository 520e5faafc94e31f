// transport_study: local vs global transport x surface vs compress push (docs/TRANSPORT.md).
//
//   transport_study squeeze R0        cylinder R0, H0 = 2 R0 between slip plates, pressed to H = R0
//   transport_study poke              sphere r 6 pressed 8 voxels into a 96 x 40 x 96 slab at Tc
//   transport_study stroke W          sphere r 6 dipped 9 voxels into a clay sphere W wide, slid 2/frame
//                                     (--mass M: the clay's mass per voxel, default 1000 = Tc;
//                                     --body slab: into the flat top of a W x 64 x W slab instead)
//                                     (no memory budget: the surface push's estimate counts the global
//                                     layer over the whole body, 54 GiB at W 512; compress: 5.7 GiB)
//   transport_study scene FILE        a scene file, its transport and push overridden: steps, block
//                                     updates, whole run and median frame time (frames 2..)
// Each runs the four combinations (or those named by --only local-surface,global-compress,...)
// on one thread and prints one line per combination. TRANSPORT_STUDY_PROFILE=1: a line per frame;
// TRANSPORT_STUDY_CALLGRIND=1 under `valgrind --tool=callgrind --instr-atstart=no`: the instructions of
// frames 2.. only (noise-free; the set-up runs uninstrumented).
#include <vdbclay/Metrics.h>
#include <vdbclay/Scene.h>
#include <vdbclay/Sculpt.h>
#include <vdbclay/Shapes.h>

#include <openvdb/openvdb.h>

#if __has_include(<valgrind/callgrind.h>)
#include <valgrind/callgrind.h>
#define VDBCLAY_HAVE_CALLGRIND 1
#endif

#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <string>
#include <vector>

using namespace vdbclay;

namespace {

using Clock = std::chrono::steady_clock;

struct Run {
    uint64_t steps = 0, blocks = 0;
    double seconds = 0, transportSeconds = 0;
    std::vector<double> frameSeconds;
    MassGridPtr mass;
    int64_t drift = 0;
};

Run runScene(Scene s)
{
    Run out;
    Sculptor sc(s, 1);
    const int64_t m0 = sc.automaton().totalMass();
    const auto t0 = Clock::now();
    // TRANSPORT_STUDY_CALLGRIND=1 under `valgrind --tool=callgrind --instr-atstart=no`: instructions
    // of frames 2.. only (the set-up of a large model runs uninstrumented).
    const bool callgrind = std::getenv("TRANSPORT_STUDY_CALLGRIND") != nullptr;
    while (!sc.done()) {
        const auto tf = Clock::now();
#ifdef VDBCLAY_HAVE_CALLGRIND
        if (callgrind && sc.frame() == 1) CALLGRIND_START_INSTRUMENTATION;
#endif
        const FrameReport r = sc.runFrame();
        out.frameSeconds.push_back(std::chrono::duration<double>(Clock::now() - tf).count());
        out.steps += r.settle.steps;
        out.blocks += r.settle.blocksUpdated;
        out.transportSeconds += r.transport.seconds;
        if (std::getenv("TRANSPORT_STUDY_PROFILE"))
            std::printf(
                "  frame %llu: %.2f ms (global layer %.2f ms)  entered %llu contact %.1f  reach %lld  "
                "overload %lld  unknowns %llu  solves %llu  iterations %llu  steps %llu (try %llu)\n",
                (unsigned long long)r.frame, 1e3 * out.frameSeconds.back(), 1e3 * r.transport.seconds,
                (unsigned long long)r.push.voxelsPushed, r.push.contactSize, (long long)r.transport.reach,
                (long long)r.transport.overloadBefore, (unsigned long long)r.transport.unknowns,
                (unsigned long long)r.transport.solves, (unsigned long long)r.transport.iterations,
                (unsigned long long)r.settle.steps, (unsigned long long)r.trySteps);
    }
#ifdef VDBCLAY_HAVE_CALLGRIND
    if (callgrind) CALLGRIND_STOP_INSTRUMENTATION;
#else
    if (callgrind) std::fprintf(stderr, "transport_study: built without valgrind/callgrind.h\n");
#endif
    out.seconds = std::chrono::duration<double>(Clock::now() - t0).count();
    out.mass = sc.mass();
    out.drift = totalMass(*sc.mass()) - m0;
    return out;
}

std::string combo(const std::string& transport, const std::string& push)
{
    return R"("transport": ")" + transport + R"(", "push": ")" + push + R"(", )";
}

const char* kCombos[4][2] = {
    {"local", "surface"}, {"local", "compress"}, {"global", "surface"}, {"global", "compress"}};

bool wanted(const std::string& only, const char* t, const char* p)
{
    return only.empty() || only.find(std::string(t) + "-" + p) != std::string::npos;
}

void squeeze(int r0, const std::string& only)
{
    const int h0 = 2 * r0, h = r0;
    for (auto& c : kCombos) {
        if (!wanted(only, c[0], c[1])) continue;
        char json[2048];
        std::snprintf(json, sizeof json, R"({"threshold": 1000, "rule": "prorata", "seed": 1, %s
            "clay": [{"shape": "cylinder", "center": [0, %g, 0], "radius": %d, "height": %d, "mass": 1000}],
            "tools": [{"shape": "box", "min": [-%d, %d, -%d], "max": [%d, %d, %d], "path": [{"translate": [0, -1, 0], "frames": %d}]}],
            "obstacles": [{"shape": "box", "min": [-%d, -3, -%d], "max": [%d, -1, %d]}],
            "settle": {"max_steps": 5000000}})",
                      combo(c[0], c[1]).c_str(), (h0 - 1) / 2.0, r0, h0, 4 * r0, h0, 4 * r0, 4 * r0, h0 + 3,
                      4 * r0, h0 - h, 6 * r0, 6 * r0, 6 * r0, 6 * r0);
        const Run run = runScene(parseScene(json, "squeeze", ""));
        const double R = r0 * std::sqrt(double(h0) / h);
        const ShapePtr ref = makeCylinder({{0, (h - 1) / 2.0, 0}}, R, h, 1);
        const ShapeError e = compareShapes(*run.mass, 1000, *ref, 3);
        // Equivalent radius of each layer: sqrt(occupied voxels / pi).
        std::vector<int64_t> layer(size_t(h0 + 1), 0);
        int64_t occupied = 0;
        for (auto it = run.mass->tree().cbeginValueOn(); it; ++it) {
            if (*it * 2 < 1000) continue;
            ++occupied;
            const int y = it.getCoord().y();
            if (y >= 0 && y <= h0) ++layer[size_t(y)];
        }
        auto radius = [&](int y) { return std::sqrt(double(layer[size_t(y)]) / M_PI); };
        const double mid = 0.5 * (radius(h / 2 - 1) + radius(h / 2));
        // Against the clay's own volume (mass / Tc, exact): the voxelised start cylinder holds less
        // than pi R0^2 H0 (R0 16: -1.40 %, 24: -1.14 %, 32: -0.37 %), an error of the start, not of the
        // squeeze.
        const double clay = double(totalMass(*run.mass)) / 1000.0, Rclay = std::sqrt(clay / (M_PI * h));
        std::printf(
            "squeeze R0 %d %-6s %-8s  IoU %.3f  mid radius %.2f (%+.1f %%)  top/mid %.3f  floor/mid %.3f  "
            "volume %+.2f %%  vs clay: radius %+.1f %% volume %+.2f %%  steps %llu  blocks %llu  %.2f s "
            "(global layer %.2f s)  drift %lld\n",
            r0, c[0], c[1], e.iou, mid, 100 * (mid / R - 1), radius(h - 1) / mid, radius(0) / mid,
            100 * (double(occupied) / (M_PI * R * R * h) - 1), 100 * (mid / Rclay - 1),
            100 * (double(occupied) / clay - 1), (unsigned long long)run.steps,
            (unsigned long long)run.blocks, run.seconds, run.transportSeconds, (long long)run.drift);
        if (std::getenv("TRANSPORT_STUDY_PROFILE")) {
            std::printf("  layer radii:");
            for (int y = 0; y < h; ++y)
                std::printf(" %.1f", radius(y));
            std::printf("\n");
        }
        std::fflush(stdout);
    }
}

void poke(const std::string& only)
{
    for (auto& c : kCombos) {
        if (!wanted(only, c[0], c[1])) continue;
        const std::string json =
            std::string(R"({"threshold": 1000, "rule": "prorata", "seed": 1, )") + combo(c[0], c[1]) +
            R"("clay": [{"shape": "box", "min": [0, 0, 0], "max": [95, 39, 95], "mass": 1000}],
            "tools": [{"shape": "sphere", "center": [48, 46, 48], "radius": 6, "path": [{"translate": [0, -1, 0], "frames": 8}]}],
            "obstacles": [{"shape": "box", "min": [-60, -3, -60], "max": [160, -1, 160]}],
            "settle": {"max_steps": 5000000}})";
        const Run run = runScene(parseScene(json, "poke", ""));
        // Clay outside the slab: where the displaced clay went.
        int64_t outside = 0, near = 0, far = 0;
        for (auto it = run.mass->tree().cbeginValueOn(); it; ++it) {
            const openvdb::Coord p = it.getCoord();
            if (p.x() >= 0 && p.x() <= 95 && p.y() >= 0 && p.y() <= 39 && p.z() >= 0 && p.z() <= 95) continue;
            outside += *it;
            const double d = std::hypot(p.x() - 48.0, p.z() - 48.0);
            (d <= 24 ? near : far) += *it;
        }
        std::printf(
            "poke %-6s %-8s  outside the slab %lld: within 4 radii %.1f %%, beyond %.1f %%  steps %llu  "
            "%.2f s  drift %lld\n",
            c[0], c[1], (long long)outside, 100.0 * double(near) / double(std::max<int64_t>(outside, 1)),
            100.0 * double(far) / double(std::max<int64_t>(outside, 1)), (unsigned long long)run.steps,
            run.seconds, (long long)run.drift);
        std::fflush(stdout);
    }
}

/// The stroke on a sphere W wide, or (@a slab) on the flat top of a W x 64 x W slab: the same tool
/// and path, dipped 9 voxels, with no curvature (the slab's frames cost the same at any W if the
/// work follows the tool and not the model).
void stroke(int width, int mass, bool slab, const std::string& only)
{
    const double R = width / 2.0;
    for (auto& c : kCombos) {
        if (!wanted(only, c[0], c[1])) continue;
        char clay[256];
        if (slab)
            std::snprintf(clay, sizeof clay,
                          R"({"shape": "box", "min": [0, 0, 0], "max": [%d, 63, %d], "mass": %d})", width - 1,
                          width - 1, mass);
        else
            std::snprintf(clay, sizeof clay,
                          R"({"shape": "sphere", "center": [%g, %g, %g], "radius": %g, "mass": %d})", R, R, R,
                          R, mass);
        const double top = slab ? 64.0 : 2 * R; // the clay's top surface
        char json[2048];
        std::snprintf(json, sizeof json, R"({"threshold": 1000, "rule": "prorata", "seed": 1, %s
            "clay": [%s],
            "tools": [{"shape": "sphere", "center": [%g, %g, %g], "radius": 6, "path": [{"translate": [2, 0, 0], "frames": 12}]}],
            "settle": {"max_steps": 5000000}, "memory_budget": "none"})",
                      combo(c[0], c[1]).c_str(), clay, R - 12, top + 6 - 9, R);
        const Run run = runScene(parseScene(json, "stroke", ""));
        std::vector<double> f(run.frameSeconds.begin() + 1, run.frameSeconds.end()); // frame 1 dips
        std::sort(f.begin(), f.end());
        std::printf(
            "stroke %d%s (m0 %d) %-6s %-8s  median frame %.2f ms (frames 2..12)  steps %llu  drift %lld  "
            "hash %016llx\n",
            width, slab ? " slab" : "", mass, c[0], c[1], 1e3 * f[f.size() / 2],
            (unsigned long long)run.steps, (long long)run.drift, (unsigned long long)contentHash(*run.mass));
        std::fflush(stdout);
    }
}

void sceneFile(const std::string& path, const std::string& only)
{
    for (auto& c : kCombos) {
        if (!wanted(only, c[0], c[1])) continue;
        Scene s = loadScene(path);
        s.transport = parseTransport(c[0]);
        s.push = parsePushMode(c[1]);
        const Run run = runScene(s);
        std::vector<double> f(run.frameSeconds.begin() + (run.frameSeconds.size() > 1 ? 1 : 0),
                              run.frameSeconds.end());
        std::sort(f.begin(), f.end());
        std::printf(
            "%s %-6s %-8s  steps %llu  blocks %llu  %.3f s (global layer %.3f s)  median frame %.2f ms  "
            "drift %lld  hash %016llx\n",
            path.c_str(), c[0], c[1], (unsigned long long)run.steps, (unsigned long long)run.blocks,
            run.seconds, run.transportSeconds, 1e3 * f[f.size() / 2], (long long)run.drift,
            (unsigned long long)contentHash(*run.mass));
        std::fflush(stdout);
    }
}

} // namespace

int main(int argc, char** argv)
{
    openvdb::initialize();
    if (argc < 2) {
        std::fprintf(
            stderr,
            "usage: transport_study squeeze R0 | poke | stroke W [--mass M] [--body slab] | scene FILE  "
            "[--only local-surface,...]\n");
        return 2;
    }
    std::string only;
    int mass = 1000;
    bool slab = false;
    for (int i = 1; i + 1 < argc; ++i) {
        if (!std::strcmp(argv[i], "--only")) only = argv[i + 1];
        if (!std::strcmp(argv[i], "--mass")) mass = std::atoi(argv[i + 1]);
        if (!std::strcmp(argv[i], "--body")) slab = !std::strcmp(argv[i + 1], "slab");
    }
    const std::string what = argv[1];
    if (what == "squeeze")
        squeeze(argc > 2 ? std::atoi(argv[2]) : 16, only);
    else if (what == "poke")
        poke(only);
    else if (what == "scene" && argc > 2)
        sceneFile(argv[2], only);
    else if (what == "stroke")
        stroke(argc > 2 && argv[2][0] != '-' ? std::atoi(argv[2]) : 128, mass, slab, only);
    else
        return 2;
    return 0;
}
