// vdbclay render: a clay .vdb (or a fog volume or level set) as a PNG: a density map in 2D, a shaded
// surface in 3D.
#include "cli.h"

#include "vdbclay/IO.h"
#include "vdbclay/Render.h"

#include <climits>
#include <cstdio>
#include <memory>
#include <string>

namespace vdbclay_cli {
namespace {

/// Largest image side render accepts (a 16384^2 RGB image is 768 MiB).
constexpr int kMaxImageSide = 16384;

struct RenderArgs {
    std::string in, out;
    vdbclay::RenderOptions options;
    int dims = 0;
    int32_t threshold = 0;
};

int render(const RenderArgs& a)
{
    checkOutputs({{"-o", a.out}}, {{{"the input file", a.in}, {}}});
    checkFormatName({"-o", a.out}, ".png", "a PNG picture");
    std::string note;
    const vdbclay::ClayFile f = vdbclay::readAsClay(a.in, note);
    if (!note.empty()) std::printf("note: %s\n", note.c_str());
    const int dims = a.dims ? a.dims : f.meta.dimensions;
    gWriting.store(true);
    vdbclay::renderPng(a.out, *f.mass, thresholdOf(f, a.threshold), dims, a.options);
    std::printf("wrote %s\n", a.out.c_str());
    return 0;
}

} // namespace

Subcommand addRenderCommand(CLI::App& app)
{
    auto a = std::make_shared<RenderArgs>();
    vdbclay::RenderOptions& ro = a->options;
    CLI::App* ren =
        app.add_subcommand("render", "Render a clay .vdb to PNG (2D density map or 3D shaded surface)");
    ren->add_option("file", a->in,
                    "a clay .vdb (grid \"mass\"), else its first fog volume, else its first level set")
        ->required()
        ->check(fileName());
    ren->add_option("-o,--output", a->out, "OUT.png")->required()->check(fileName());
    ren->add_option("--width", ro.width, "image width")->check(integerIn(1, kMaxImageSide));
    ren->add_option("--height", ro.height, "image height")->check(integerIn(1, kMaxImageSide));
    ren->add_option("--azimuth", ro.azimuthDeg, "3D camera azimuth, degrees")->check(finiteIn(-1e6, 1e6));
    ren->add_option("--elevation", ro.elevationDeg, "3D camera elevation, degrees")
        ->check(finiteIn(-89.9, 89.9));
    ren->add_option("--dims", a->dims, "2 or 3, if the file does not record it")->check(integerIn(2, 3));
    ren->add_option("--threshold", a->threshold, "Tc, if the file does not record it")
        ->check(integerIn(1, INT32_MAX));
    return {ren, [a] { return render(*a); }};
}

} // namespace vdbclay_cli
