// libFuzzer target: bytes as scene JSON through vdbclay::parseScene.
//
// File names inside a scene resolve against tests/fuzz/files (a tiny level set and mesh), so the
// fuzzer reaches the shapes that load files. Inputs naming device or system paths are skipped: a
// scene that names /dev/zero as its mesh reads forever, as any program reading that file would.
#include "FuzzCheck.h"

#include "vdbclay/Scene.h"

#include <cstddef>
#include <cstdint>
#include <string>

#ifndef VDBCLAY_FUZZ_FILES
#define VDBCLAY_FUZZ_FILES ""
#endif

namespace {

bool namesSystemPath(const std::string& text)
{
    // "\/" and "\u" escapes could spell the same paths.
    for (const char* p : {"/dev", "/proc", "/sys", "\\/", "\\u"}) {
        if (text.find(p) != std::string::npos) return true;
    }
    return false;
}

} // namespace

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size)
{
    const std::string text(reinterpret_cast<const char*>(data), size);
    if (namesSystemPath(text)) return -1; // not added to the corpus
    vdbclay::fuzz::expectOnlyErrors([&] {
        const vdbclay::Scene scene = vdbclay::parseScene(text, "fuzz.json", VDBCLAY_FUZZ_FILES);
        // What a run asks of a parsed scene before it builds grids.
        for (const vdbclay::ToolSpec& t : scene.tools) {
            (void)t.poseAt(scene.frames);
            if (t.shape.shape) (void)t.shape.shape->bounds();
        }
        for (const vdbclay::ClaySpec& c : scene.clay) {
            if (c.shape.shape) (void)c.shape.shape->bounds();
        }
    });
    return 0;
}
