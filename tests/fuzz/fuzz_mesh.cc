// libFuzzer target: bytes as a mesh file through vdbclay::loadMesh (OBJ, ASCII and binary STL, PLY
// in ASCII and both binary orders). The first byte picks the file's extension (.obj, .stl, .ply or
// none, when the format is told by the content alone); the rest is the file, written to one
// temporary file per extension (in $TMPDIR, removed at exit). A budget of 16 MiB keeps meshes that
// would voxelize to gigabytes as refusals.
#include "FuzzCheck.h"
#include "FuzzFile.h"

#include "vdbclay/Shapes.h"

#include <array>
#include <cstddef>
#include <cstdint>
#include <string>

namespace {

constexpr std::array<const char*, 4> kExtensions = {".obj", ".stl", ".ply", ""};
std::array<std::string, 4> gPaths;

} // namespace

extern "C" int LLVMFuzzerInitialize(int*, char***)
{
    for (size_t i = 0; i < kExtensions.size(); ++i)
        gPaths[i] = vdbclay::fuzz::makeTempFile(kExtensions[i]);
    return 0;
}

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size)
{
    if (size == 0) return 0;
    const std::string& path = gPaths[data[0] % kExtensions.size()];
    vdbclay::fuzz::writeFile(path, data + 1, size - 1);
    vdbclay::fuzz::expectOnlyErrors([&] {
        (void)vdbclay::loadMesh(path, 1.0, vdbclay::UpAxis::Y, vdbclay::Placement(), uint64_t(16) << 20);
    });
    return 0;
}
