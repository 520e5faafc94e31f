// vdbclay demo: the automaton alone on a built-in overloaded lump of clay on a floor.
#include "cli.h"

#include "vdbclay/Automaton.h"
#include "vdbclay/IO.h"
#include "vdbclay/MemoryEstimate.h"
#include "vdbclay/Metrics.h"
#include "vdbclay/Scene.h"
#include "vdbclay/Shapes.h"

#include <openvdb/openvdb.h>

#include <algorithm>
#include <chrono>
#include <climits>
#include <cstdio>
#include <iostream>
#include <memory>
#include <string>

namespace vdbclay_cli {
namespace {

struct DemoArgs {
    int size = 32;
    int overload = 3;
    vdbclay::AutomatonOptions opts;
    uint64_t maxSteps = 200000;
    std::string out;
    std::string rule; ///< --rule: empty keeps the default
};

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

/// Checks the arguments, then the memory, before any grid is built.
void checkDemo(DemoArgs& a)
{
    if (!a.rule.empty())
        a.opts.rule.rule = parsedOption("--rule", [&] { return vdbclay::parseRule(a.rule); });
    vdbclay::validate(a.opts.rule);
    if (int64_t(a.overload) * a.opts.rule.threshold > INT32_MAX) {
        throw vdbclay::Error("--overload x --threshold exceeds the int32 range of a cell");
    }
    checkOutputs({{"-o", a.out}}, {});
    checkFormatName({"-o", a.out}, ".vdb", "a clay .vdb (OpenVDB)");
    checkDemoMemory(a);
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

} // namespace

Subcommand addDemoCommand(CLI::App& app)
{
    auto a = std::make_shared<DemoArgs>();
    CLI::App* demo =
        app.add_subcommand("demo", "Settle a built-in overloaded lump of clay (the automaton alone)");
    demo->add_option("--size", a->size, "cube edge in voxels")->check(integerIn(2, 4096));
    demo->add_option("--overload", a->overload, "the core holds this many times Tc per voxel")
        ->check(integerIn(1, 1000));
    demo->add_option("--rule", a->rule, "arata, bingham, sorted, prorata")->check(nonEmpty("a rule name"));
    demo->add_option("--threshold", a->opts.rule.threshold, "Tc")->check(integerIn(1, INT32_MAX));
    demo->add_option("--alpha", a->opts.rule.alpha, "arata's rate in (0,1)")->check(finiteIn(0, 1, true));
    demo->add_option("--dims", a->opts.dimensions, "2 or 3")->check(integerIn(2, 3));
    demo->add_option("--threads", a->opts.threads, "worker threads, 0 = all")
        ->check(integerIn(0, kMaxThreads));
    demo->add_option("--seed", a->opts.seed, "remainder hash seed")->check(integerIn(0, INT64_MAX));
    demo->add_option("--max-steps", a->maxSteps, "step budget")->check(integerIn(0, UINT64_MAX));
    demo->add_option("-o,--output", a->out, "write the settled clay to this .vdb")->check(fileName());
    return {demo, [a] {
                checkDemo(*a);
                return runDemo(*a);
            }};
}

} // namespace vdbclay_cli
