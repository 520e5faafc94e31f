// vdbclay command-line tool. Until scene files land, `vdbclay demo` (also what `vdbclay` with no
// arguments runs) settles a built-in scene: an overloaded lump of clay resting on a floor.

#include "vdbclay/Automaton.h"
#include "vdbclay/Metrics.h"

#include <openvdb/openvdb.h>

#include <cerrno>
#include <chrono>
#include <climits>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <iostream>
#include <string>

namespace {

const char* kUsage =
    "usage: vdbclay demo [options]\n"
    "  Settles the built-in demo: a cube of clay at the threshold Tc with an overloaded core,\n"
    "  resting on a floor obstacle. Prints what happened.\n"
    "options:\n"
    "  --size N        cube edge in voxels (default 32)\n"
    "  --overload K    the core (edge N/4) holds K x Tc per voxel (default 3)\n"
    "  --rule R        arata | bingham | sorted | prorata (default prorata)\n"
    "  --threshold T   Tc (default 1000)\n"
    "  --alpha A       arata's rate in (0,1) (default 0.5)\n"
    "  --dims D        2 or 3 (default 3)\n"
    "  --threads N     worker threads, 0 = all (default 0)\n"
    "  --seed S        remainder hash seed (default 0)\n"
    "  --max-steps N   step budget (default 200000)\n"
    "  -o FILE.vdb     write the settled grid (\"mass\", Int32) to FILE.vdb\n"
    "  -h, --help      this text\n";

struct DemoArgs {
    int size = 32;
    int overload = 3;
    vdbclay::AutomatonOptions opts;
    uint64_t maxSteps = 200000;
    std::string out;
};

long long parseInt(const std::string& flag, const char* v, long long lo, long long hi)
{
    char* end = nullptr;
    errno = 0;
    const long long x = std::strtoll(v, &end, 10);
    if (errno || !end || *end || end == v || x < lo || x > hi) {
        throw vdbclay::Error(flag + ": expected an integer in [" + std::to_string(lo) + ", " +
                             std::to_string(hi) + "], got \"" + v + "\"");
    }
    return x;
}

DemoArgs parseDemo(int argc, char** argv, int first)
{
    DemoArgs a;
    for (int i = first; i < argc; ++i) {
        const std::string f = argv[i];
        auto next = [&]() -> const char* {
            if (i + 1 >= argc) throw vdbclay::Error(f + ": missing value");
            return argv[++i];
        };
        if (f == "-h" || f == "--help") {
            std::cout << kUsage;
            std::exit(0);
        } else if (f == "--size") a.size = int(parseInt(f, next(), 2, 4096));
        else if (f == "--overload") a.overload = int(parseInt(f, next(), 1, 1000));
        else if (f == "--rule") a.opts.rule.rule = vdbclay::parseRule(next());
        else if (f == "--threshold") a.opts.rule.threshold = int32_t(parseInt(f, next(), 1, INT32_MAX));
        else if (f == "--alpha") {
            const char* v = next();
            char* end = nullptr;
            a.opts.rule.alpha = std::strtod(v, &end);
            if (!end || *end) throw vdbclay::Error(f + ": expected a number, got \"" + v + "\"");
        } else if (f == "--dims") a.opts.dimensions = int(parseInt(f, next(), 2, 3));
        else if (f == "--threads") a.opts.threads = int(parseInt(f, next(), 0, 4096));
        else if (f == "--seed") a.opts.seed = uint64_t(parseInt(f, next(), 0, INT64_MAX));
        else if (f == "--max-steps") a.maxSteps = uint64_t(parseInt(f, next(), 0, INT64_MAX));
        else if (f == "-o") a.out = next();
        else throw vdbclay::Error("unknown option \"" + f + "\" (see vdbclay demo --help)");
    }
    vdbclay::validate(a.opts.rule);
    if (int64_t(a.overload) * a.opts.rule.threshold > INT32_MAX) {
        throw vdbclay::Error("--overload x --threshold exceeds the int32 range of a cell");
    }
    return a;
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
        const std::string tmp = a.out + ".tmp";
        GridPtrVec grids{mass};
        mass->insertMeta("vdbclay_threshold", Int32Metadata(tc));
        mass->insertMeta("vdbclay_rule", StringMetadata(vdbclay::ruleName(a.opts.rule.rule)));
        mass->insertMeta("vdbclay_steps", Int64Metadata(int64_t(r.steps)));
        io::File(tmp).write(grids);
        if (std::rename(tmp.c_str(), a.out.c_str()) != 0) {
            std::remove(tmp.c_str());
            throw vdbclay::Error("cannot write " + a.out + ": " + std::strerror(errno));
        }
        std::cout << "  wrote " << a.out << "\n";
    }
    return m1 == m0 ? 0 : 3;
}

} // namespace

int main(int argc, char** argv)
{
    try {
        openvdb::initialize();
        std::string cmd = argc > 1 ? argv[1] : "demo";
        if (cmd == "-h" || cmd == "--help" || cmd == "help") {
            std::cout << kUsage;
            return 0;
        }
        if (cmd == "demo") return runDemo(parseDemo(argc, argv, argc > 1 ? 2 : 1));
        if (cmd.size() && cmd[0] == '-') return runDemo(parseDemo(argc, argv, 1));
        std::cerr << "vdbclay: unknown command \"" << cmd << "\" (try: vdbclay demo --help)\n";
        return 2;
    } catch (const std::exception& e) {
        std::cerr << "vdbclay: error: " << e.what() << "\n";
        return 1;
    }
}
