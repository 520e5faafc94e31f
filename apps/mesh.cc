// vdbclay mesh: the clay surface of a clay .vdb (or of a fog volume or level set) as OBJ or PLY.
#include "cli.h"

#include "vdbclay/IO.h"
#include "vdbclay/SurfaceMesh.h"

#include <climits>
#include <cstdio>
#include <memory>
#include <string>

namespace vdbclay_cli {
namespace {

struct MeshArgs {
    std::string in, out, up;
    double iso = 0.5;
    int32_t threshold = 0;
    bool keepVolume = false;
};

int writeMesh(const MeshArgs& a)
{
    checkMeshName({"-o", a.out});
    checkOutputs({{"-o", a.out}}, {{{"the input file", a.in}, {}}});
    std::string note;
    const vdbclay::ClayFile f = vdbclay::readAsClay(a.in, note);
    if (!note.empty()) std::printf("note: %s\n", note.c_str());
    if (!a.up.empty()) vdbclay::setClayTransform(*f.mass, f.meta.voxelSize, upOption(a.up));
    gWriting.store(true);
    vdbclay::writeSurfaceMesh(a.out, *f.mass, thresholdOf(f, a.threshold), a.iso, a.keepVolume);
    std::printf("wrote %s\n", a.out.c_str());
    return 0;
}

} // namespace

Subcommand addMeshCommand(CLI::App& app)
{
    auto a = std::make_shared<MeshArgs>();
    CLI::App* mesh = app.add_subcommand("mesh", "Write the clay surface of a clay .vdb as OBJ, PLY or STL");
    mesh->add_option("file", a->in,
                     "a clay .vdb (grid \"mass\"), else its first fog volume, else its first level set")
        ->required()
        ->check(fileName());
    mesh->add_option("-o,--output", a->out, "OUT.obj, OUT.ply or OUT.stl (binary)")
        ->required()
        ->check(fileName());
    mesh->add_option("--isovalue", a->iso, "surface where density (mass / Tc) equals this (default 0.5)")
        ->check(finiteIn(1e-9, 1e9));
    mesh->add_option("--threshold", a->threshold, "Tc, if the file does not record it")
        ->check(integerIn(1, INT32_MAX));
    mesh->add_option("--up", a->up, "y or z: orient the mesh for this up axis (default: the file's)");
    mesh->add_flag("--keep-volume", a->keepVolume,
                   "move the surface along its normals (at most half a voxel) to enclose the clay's volume");
    return {mesh, [a] { return writeMesh(*a); }};
}

} // namespace vdbclay_cli
