// A separate project that uses an installed vdbclay through find_package: it builds a grid with
// OpenVDB (exported as vdbclay's public dependency), settles an overloaded lump with an Automaton,
// then runs a scene through the Sculptor, and checks the exact results.
#include <vdbclay/Automaton.h>
#include <vdbclay/Rules.h>
#include <vdbclay/Scene.h>
#include <vdbclay/Sculpt.h>

#include <openvdb/openvdb.h>

#include <cstdio>

namespace {
int failed(const char* what)
{
    std::printf("consumer: FAILED: %s\n", what);
    return 1;
}
} // namespace

int main()
{
    // A pure rule on one block.
    vdbclay::RuleParams p;
    p.rule = vdbclay::parseRule("bingham");
    const vdbclay::CompiledRule r = vdbclay::compileRule(p);
    const int32_t m[4] = {1600, 0, 0, 0};
    int64_t out[4];
    vdbclay::repartitionBlock(r, 4, m, 0xF, vdbclay::BlockKey{}, out);
    if (out[0] + out[1] + out[2] + out[3] != 1600 || out[0] != 1000) return failed("bingham block");

    // The automaton: an 8^3 cube at Tc with 8000 extra units on one cell settles with mass exact.
    openvdb::initialize();
    auto mass = openvdb::Int32Grid::create(0);
    mass->tree().fill(openvdb::CoordBBox({0, 0, 0}, {7, 7, 7}), 1000, true);
    mass->tree().setValue({4, 4, 4}, 9000);
    vdbclay::AutomatonOptions opt;
    opt.threads = 2;
    vdbclay::Automaton clay(mass, opt);
    const vdbclay::StepReport s = clay.settle(100000);
    if (!s.settled || s.residualOverload != 0) return failed("the lump did not settle");
    if (clay.totalMass() != 512 * 1000 + 8000) return failed("automaton mass");

    // A scene: the built-in default (a cube pressed by a plate), all frames.
    vdbclay::Sculptor sculptor(vdbclay::defaultScene(), 2);
    const vdbclay::RunSummary run = sculptor.run();
    if (run.massDrift != 0 || run.massFinal != run.massInitial || run.massInitial <= 0)
        return failed("scene mass");
    if (!run.settled || run.frames != sculptor.totalFrames()) return failed("scene did not finish settled");

    std::printf("consumer: ok (automaton %llu steps, scene %llu frames, %llu steps)\n",
                (unsigned long long)s.steps, (unsigned long long)run.frames, (unsigned long long)run.steps);
    return 0;
}
