// libFuzzer target: bytes as a mesh file through vdbclay::loadMesh (OBJ, ASCII and binary STL, PLY
// in ASCII and both binary orders). The first byte picks the file's extension (.obj, .stl, .ply or
// none, when the format is told by the content alone); the rest is the file, written to one
// temporary file per extension (in $TMPDIR, removed at exit). A budget of 16 MiB keeps meshes that
// would voxelize to gigabytes as refusals.
#include "FuzzCheck.h"

#include "vdbclay/Shapes.h"

#include <unistd.h>

#include <array>
#include <cstddef>
#include <cstdint>
#include <cstdio>
#include <cstdlib>
#include <string>

namespace {

constexpr std::array<const char*, 4> kExtensions = {".obj", ".stl", ".ply", ""};
std::array<std::string, 4> gPaths;

void removeTempFiles()
{
    for (const std::string& p : gPaths)
        if (!p.empty()) ::unlink(p.c_str());
}

void writeInput(const std::string& path, const uint8_t* data, size_t size)
{
    FILE* f = std::fopen(path.c_str(), "wb");
    if (!f || (size && std::fwrite(data, 1, size, f) != size) || std::fclose(f) != 0) {
        std::perror(path.c_str());
        std::abort();
    }
}

} // namespace

extern "C" int LLVMFuzzerInitialize(int*, char***)
{
    const char* dir = std::getenv("TMPDIR");
    const std::string base = std::string(dir && *dir ? dir : "/tmp") + "/vdbclay-fuzz-mesh-XXXXXX";
    for (size_t i = 0; i < kExtensions.size(); ++i) {
        std::string tmpl = base + kExtensions[i];
        const int fd = ::mkstemps(tmpl.data(), int(std::string(kExtensions[i]).size()));
        if (fd < 0) {
            std::perror("mkstemps");
            std::abort();
        }
        ::close(fd);
        gPaths[i] = tmpl;
    }
    std::atexit(removeTempFiles);
    return 0;
}

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size)
{
    if (size == 0) return 0;
    const std::string& path = gPaths[data[0] % kExtensions.size()];
    writeInput(path, data + 1, size - 1);
    vdbclay::fuzz::expectOnlyErrors([&] {
        (void)vdbclay::loadMesh(path, 1.0, vdbclay::UpAxis::Y, vdbclay::Placement(), uint64_t(16) << 20);
    });
    return 0;
}
