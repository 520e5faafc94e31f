// bench_kernels: the per-block rules on typical 3D blocks (2x2x2, Tc = 1000), Google Benchmark.
//
// For each rule, three blocks:
//   OneOver  one over cell (1900) among seven under cells (950, 940, ...): the common case in a
//            settling lump, E < A.
//   EOverA   more excess than room: four cells at 3000, four at 990 (E > A; for prorata and sorted
//            the "fill every room, then share equally" branch).
//   NoOver   every cell at or under Tc: the early exit, which is what most candidate blocks hit.
// Each is timed through the public, out-of-line vdbclay::repartitionBlock and through the inline
// rules_internal::repartition that the automaton's kernel uses (lib/src/RulesImpl.h). The step in
// the key changes every iteration so the remainder hash is not hoisted out of the loop.
#include "RulesImpl.h"
#include "vdbclay/Rules.h"

#include <benchmark/benchmark.h>

#include <cstdint>

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

} // namespace

BENCHMARK_TEMPLATE(BM_Block, false)->Name("repartitionBlock")->Apply(Args);
BENCHMARK_TEMPLATE(BM_Block, true)->Name("rules_internal::repartition")->Apply(Args);

BENCHMARK_MAIN();
