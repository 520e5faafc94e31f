// bench_kernels: the per-block rules on typical 3D blocks (2x2x2, Tc = 1000), Google Benchmark.
//
// For each rule, three blocks:
//   OneOver  one over cell (1900) among seven under cells (950, 940, ...): the common case in a
//            settling lump, E < A.
//   EOverA   more excess than room: four cells at 3000, four at 990 (E > A; for prorata and sorted
//            the "fill every room, then share equally" branch).
//   NoOver   every cell at or under Tc: the early exit, which is what most candidate blocks hit.
// Each is timed through the public, out-of-line vdbclay::repartitionBlock and through the inline
// rules_internal::repartition that the automaton's kernel uses (lib/src/automaton/RulesImpl.h). The
// step in the key changes every iteration so the remainder hash is not hoisted out of the loop.
//
// Pass: the automaton's kernel (lib/src/automaton/Kernel.h, processRange) on a 32^3 cube of random
// clay, every block of the phase a candidate, on its SIMD path (with the over-cell filter chosen at
// run time, the SSE2 filter, or none: kernel_testing::Paths::filter; mode 4: the pass's baseline
// build where the CPU would run its AVX2 build, Paths::avx2 off) and on its portable path
// (Paths::portable),
// one pass per iteration on a fresh copy of the grid (the copy is not timed). items_per_second
// counts updated blocks: 1e9 / items_per_second is the kernel's ns per updated block.
//   surplus  cells 900-1600 (Tc 1000): most blocks have more excess than room (E > A), as in a
//            settling press.
//   spread   cells 0-1000 with one in eight at 1000-4000: most blocks have room for their excess.
//   sparse   cells 950-1000 with one in 60 at 1001-1400: most candidate blocks hold no over cell
//            (a settling press examines ~4 such blocks per updated one: the over-cell filter's case).
#include "automaton/Kernel.h"
#include "automaton/KernelTesting.h"
#include "automaton/OverFilter.h"
#include "automaton/RulesImpl.h"
#include "vdbclay/Rules.h"

#include <openvdb/openvdb.h>

#include <benchmark/benchmark.h>

#include <cstdint>
#include <memory>
#include <string>
#include <vector>

namespace {

using vdbclay::Rule;

enum Case { OneOver = 0, EOverA = 1, NoOver = 2 };

const int32_t kBlocks[3][8] = {
    {1900, 950, 940, 960, 930, 950, 945, 955},
    {3000, 990, 3000, 990, 3000, 990, 3000, 990},
    {950, 1000, 940, 960, 930, 950, 945, 999},
};

vdbclay::CompiledRule compiled(Rule r)
{
    vdbclay::RuleParams p;
    p.rule = r;
    p.threshold = 1000;
    p.alpha = 0.5;
    return vdbclay::compileRule(p);
}

template <bool Inline> void BM_Block(benchmark::State& state)
{
    const vdbclay::CompiledRule rule = compiled(Rule(state.range(0)));
    const int32_t* mass = kBlocks[state.range(1)];
    vdbclay::BlockKey key{10, 20, 30, 0, 1};
    int64_t out[8];
    uint64_t changed = 0;
    for (auto _ : state) {
        ++key.step;
        benchmark::DoNotOptimize(mass);
        uint32_t c;
        if constexpr (Inline)
            c = vdbclay::rules_internal::repartition(rule, 8, mass, 0xFFu, key, out);
        else
            c = vdbclay::repartitionBlock(rule, 8, mass, 0xFFu, key, out);
        changed += c;
        benchmark::DoNotOptimize(out);
    }
    benchmark::DoNotOptimize(changed);
    state.SetItemsProcessed(int64_t(state.iterations()));
    static const char* ruleNames[] = {"arata", "bingham", "sorted", "prorata"};
    static const char* caseNames[] = {"one-over", "E>A", "no-over"};
    state.SetLabel(std::string(ruleNames[state.range(0)]) + "/" + caseNames[state.range(1)]);
}

void Args(benchmark::internal::Benchmark* b)
{
    b->ArgNames({"rule", "case"});
    for (int r = 0; r < 4; ++r)
        for (int c = 0; c < 3; ++c)
            b->Args({r, c});
}

/// The cube of BM_Pass: 32^3 voxels, values from a fixed xorshift sequence.
/// kind: 0 surplus, 1 spread, 2 sparse.
std::shared_ptr<openvdb::Int32Tree> passGrid(int kind)
{
    openvdb::initialize();
    auto tree = std::make_shared<openvdb::Int32Tree>(0);
    const bool surplus = kind == 0;
    uint64_t x = surplus ? 88172645463325252ull : kind == 1 ? 1234567ull : 7654321ull;
    auto next = [&x] {
        x ^= x << 13;
        x ^= x >> 7;
        x ^= x << 17;
        return x;
    };
    for (int i = 0; i < 32; ++i)
        for (int j = 0; j < 32; ++j)
            for (int k = 0; k < 32; ++k) {
                int v;
                if (surplus)
                    v = 900 + int(next() % 701);
                else if (kind == 2)
                    v = (next() % 60 == 0) ? 1001 + int(next() % 400) : 950 + int(next() % 51);
                else
                    v = (next() % 8 == 0) ? 1000 + int(next() % 3001) : int(next() % 1001);
                tree->setValue(openvdb::Coord(i, j, k), v);
            }
    return tree;
}

void BM_Pass(benchmark::State& state)
{
    using namespace vdbclay::automaton_internal;
    // mode: 0 SIMD (filter chosen at run time), 1 SIMD with the SSE2 filter, 2 SIMD without the
    // filter, 3 portable, 4 SIMD in the baseline build (filter chosen at run time).
    const int mode = int(state.range(0)), kind = int(state.range(1));
    const bool portable = mode == 3;
    const int phase = int(state.range(2));
    const auto grid = passGrid(kind);
    std::vector<WorkItem> work;
    for (int y = 0; y < 5; ++y)
        for (int z = 0; z < 5; ++z)
            for (int x = 0; x < 5; ++x)
                work.push_back(WorkItem{Origin(8 * x, 8 * y, 8 * z), ~0ull, 0});
    vdbclay::RuleParams p;
    p.rule = Rule::Prorata;
    p.threshold = 1000;
    PassInput in;
    in.rule = vdbclay::compileRule(p);
    in.phase = phase;
    in.step = uint64_t(phase);
    in.seed = 1;
    kernel_testing::Paths paths;
    paths.portable = portable;
    paths.avx2 = mode != 4;
    paths.filter = mode == 1 ? OverFilter::Sse2 : mode == 2 ? OverFilter::None : OverFilter::Auto;
    uint64_t updated = 0;
    for (auto _ : state) {
        state.PauseTiming();
        openvdb::Int32Tree tree(*grid);
        in.tree = &tree;
        in.step += 2; // a new remainder hash each pass, same parity as the phase
        PassTotals tot;
        state.ResumeTiming();
        kernel_testing::processRange(in, paths, work.data(), 0, work.size(), tot);
        updated += tot.updated;
        benchmark::DoNotOptimize(tot.overloadDelta);
    }
    state.SetItemsProcessed(int64_t(updated));
    const OverFilter f = (mode == 0 || mode == 4) ? bestOverFilter() : paths.filter;
    const char* filter = portable                ? ""
                         : f == OverFilter::Avx2 ? "+avx2"
                         : f == OverFilter::Sse2 ? "+sse2"
                                                 : "+nofilter";
    const char* kinds[] = {"surplus", "spread", "sparse"};
    const char* build = portable                                     ? ""
                        : (paths.avx2 && kernel_testing::avx2Pass()) ? "[avx2 build]"
                                                                     : "[baseline build]";
    state.SetLabel(std::string(portable ? "portable" : "simd") + build + filter + "/" + kinds[kind] +
                   "/phase " + std::to_string(phase));
}

} // namespace

BENCHMARK(BM_Pass)
    ->Name("processRange")
    ->ArgNames({"mode", "case", "phase"})
    ->ArgsProduct({{0, 1, 2, 3, 4}, {0, 1, 2}, {0, 1}});
BENCHMARK_TEMPLATE(BM_Block, false)->Name("repartitionBlock")->Apply(Args);
BENCHMARK_TEMPLATE(BM_Block, true)->Name("rules_internal::repartition")->Apply(Args);

BENCHMARK_MAIN();
