// libFuzzer target: bytes as a .vdb file through vdbclay::readClayFile, vdbclay::describeVdb and
// vdbclay::loadLevelSet. Each takes a path, so each input is written to one temporary file (in $TMPDIR,
// removed at exit).
#include "FuzzCheck.h"

#include "vdbclay/IO.h"
#include "vdbclay/Shapes.h"

#include <unistd.h>

#include <cstddef>
#include <cstdint>
#include <cstdio>
#include <cstdlib>
#include <string>

namespace {

std::string gPath;

void removeTempFile()
{
    ::unlink(gPath.c_str());
}

void writeInput(const uint8_t* data, size_t size)
{
    FILE* f = std::fopen(gPath.c_str(), "wb");
    if (!f || (size && std::fwrite(data, 1, size, f) != size) || std::fclose(f) != 0) {
        std::perror(gPath.c_str());
        std::abort();
    }
}

} // namespace

extern "C" int LLVMFuzzerInitialize(int*, char***)
{
    const char* dir = std::getenv("TMPDIR");
    std::string tmpl = std::string(dir && *dir ? dir : "/tmp") + "/vdbclay-fuzz-XXXXXX";
    const int fd = ::mkstemp(tmpl.data());
    if (fd < 0) {
        std::perror("mkstemp");
        std::abort();
    }
    ::close(fd);
    gPath = tmpl;
    std::atexit(removeTempFile);
    return 0;
}

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size)
{
    writeInput(data, size);
    vdbclay::fuzz::expectOnlyErrors([&] { (void)vdbclay::readClayFile(gPath); });
    vdbclay::fuzz::expectOnlyErrors([&] { (void)vdbclay::describeVdb(gPath); });
    vdbclay::fuzz::expectOnlyErrors([&] { (void)vdbclay::loadLevelSet(gPath); });
    return 0;
}
