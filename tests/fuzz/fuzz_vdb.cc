// libFuzzer target: bytes as a .vdb file through vdbclay::readClayFile, vdbclay::describeVdb and
// vdbclay::loadLevelSet. Each takes a path, so each input is written to one temporary file (in $TMPDIR,
// removed at exit).
#include "FuzzCheck.h"
#include "FuzzFile.h"

#include "vdbclay/IO.h"
#include "vdbclay/Shapes.h"

#include <cstddef>
#include <cstdint>
#include <string>

namespace {

std::string gPath;

} // namespace

extern "C" int LLVMFuzzerInitialize(int*, char***)
{
    gPath = vdbclay::fuzz::makeTempFile("");
    return 0;
}

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size)
{
    vdbclay::fuzz::writeFile(gPath, data, size);
    vdbclay::fuzz::expectOnlyErrors([&] { (void)vdbclay::readClayFile(gPath); });
    vdbclay::fuzz::expectOnlyErrors([&] { (void)vdbclay::describeVdb(gPath); });
    vdbclay::fuzz::expectOnlyErrors([&] { (void)vdbclay::loadLevelSet(gPath); });
    return 0;
}
