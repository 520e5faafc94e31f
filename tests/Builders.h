/// @file Builders.h
/// @brief What the tests build over and over: a box of clay, automaton options, a scene from
/// data/scenes, a whole run of it, and the checks on an Error's message and on every clay voxel.
///
/// A test executable that includes this header is compiled with VDBCLAY_SCENES_DIR, the absolute
/// path of data/scenes (tests/CMakeLists.txt sets it).
#pragma once

#include <vdbclay/Automaton.h>
#include <vdbclay/Scene.h>
#include <vdbclay/Sculpt.h>
#include <vdbclay/Types.h>

#include <openvdb/openvdb.h>

#include <gtest/gtest.h>

#include <string>
#include <vector>

#ifndef VDBCLAY_SCENES_DIR
#error "VDBCLAY_SCENES_DIR (the path of data/scenes) must be defined for tests that include Builders.h"
#endif

namespace vdbclay_test {

/// A mass grid with @a m in every voxel of [lo, hi] (voxels, no tiles; the grid has no name).
inline vdbclay::MassGridPtr clayBox(const openvdb::Coord& lo, const openvdb::Coord& hi, int32_t m)
{
    auto g = openvdb::Int32Grid::create(0);
    g->tree().fill(openvdb::CoordBBox(lo, hi), m, true);
    g->tree().voxelizeActiveTiles();
    return g;
}

/// Automaton options with rule @a rule, Tc @a tc, @a dims dimensions and @a threads threads; the
/// other fields keep their defaults (alpha 0.5, seed 0).
inline vdbclay::AutomatonOptions automatonOptions(vdbclay::Rule rule, int32_t tc, int dims = 3,
                                                  int threads = 0)
{
    vdbclay::AutomatonOptions o;
    o.dimensions = dims;
    o.rule.rule = rule;
    o.rule.threshold = tc;
    o.threads = threads;
    return o;
}

/// The four rules, in the order of vdbclay::Rule.
inline constexpr vdbclay::Rule kAllRules[] = {vdbclay::Rule::Arata, vdbclay::Rule::Bingham,
                                              vdbclay::Rule::Sorted, vdbclay::Rule::Prorata};

/// The path of @a relative inside data/scenes, e.g. sceneFile("test/trapped-piston2d.json").
inline std::string sceneFile(const std::string& relative)
{
    return std::string(VDBCLAY_SCENES_DIR) + "/" + relative;
}

/// The scene data/scenes/@a relative, as `vdbclay run` reads it.
inline vdbclay::Scene loadTestScene(const std::string& relative)
{
    return vdbclay::loadScene(sceneFile(relative));
}

/// The scene data/scenes/test/@a name, run with @a rule.
inline vdbclay::Scene testSceneWithRule(const std::string& name, vdbclay::Rule rule)
{
    vdbclay::Scene s = loadTestScene("test/" + name);
    s.rule.rule = rule;
    return s;
}

/// Runs @a scene to its end on @a threads threads; @a frames collects every frame's report, the
/// final clay goes to @a out.
inline vdbclay::RunSummary runScene(const vdbclay::Scene& scene,
                                    std::vector<vdbclay::FrameReport>* frames = nullptr,
                                    vdbclay::MassGridPtr* out = nullptr, int threads = 2)
{
    vdbclay::Sculptor sc(scene, threads);
    const vdbclay::RunSummary s = sc.run(0, [&](const vdbclay::FrameReport& r) {
        if (frames) frames->push_back(r);
    });
    if (out) *out = sc.mass();
    return s;
}

/// Runs the scene given as JSON text (see runScene above).
inline vdbclay::RunSummary runSceneJson(const std::string& json,
                                        std::vector<vdbclay::FrameReport>* frames = nullptr,
                                        vdbclay::MassGridPtr* out = nullptr, int threads = 2)
{
    return runScene(vdbclay::parseScene(json, "inline.json", ""), frames, out, threads);
}

/// The message of the vdbclay::Error @a fn throws ("" if it throws none).
template <typename Fn> std::string errorOf(Fn&& fn)
{
    try {
        fn();
    } catch (const vdbclay::Error& e) {
        return e.what();
    }
    return "";
}

/// Expects @a fn to throw a vdbclay::Error whose message contains @a needle.
template <typename Fn> void expectError(Fn&& fn, const std::string& needle)
{
    try {
        fn();
        ADD_FAILURE() << "no error; expected one containing \"" << needle << "\"";
    } catch (const vdbclay::Error& e) {
        EXPECT_NE(std::string(e.what()).find(needle), std::string::npos) << e.what();
    }
}

/// Every clay voxel (active, nonzero) of @a g satisfies @a pred (called with its coordinate).
template <typename Pred> bool allClay(const vdbclay::MassGrid& g, Pred&& pred)
{
    for (auto it = g.tree().cbeginValueOn(); it; ++it)
        if (*it != 0 && !pred(it.getCoord())) return false;
    return true;
}

} // namespace vdbclay_test
