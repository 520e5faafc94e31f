// The file a fuzz target hands a reader that takes a path: made once in $TMPDIR (with the name's
// ending the reader needs), rewritten with each input, removed at exit.
#pragma once

#include <unistd.h>

#include <cstddef>
#include <cstdint>
#include <cstdio>
#include <cstdlib>
#include <string>
#include <vector>

namespace vdbclay::fuzz {

/// A new empty file "$TMPDIR/vdbclay-fuzz-XXXXXX@a suffix", removed when the target exits.
inline std::string makeTempFile(const std::string& suffix)
{
    static std::vector<std::string> made;
    const char* dir = std::getenv("TMPDIR");
    std::string path = std::string(dir && *dir ? dir : "/tmp") + "/vdbclay-fuzz-XXXXXX" + suffix;
    const int fd = ::mkstemps(path.data(), int(suffix.size()));
    if (fd < 0) {
        std::perror("mkstemps");
        std::abort();
    }
    ::close(fd);
    if (made.empty()) {
        std::atexit([] {
            for (const std::string& p : made)
                ::unlink(p.c_str());
        });
    }
    made.push_back(path);
    return path;
}

/// Replaces the content of @a path with @a size bytes of @a data.
inline void writeFile(const std::string& path, const uint8_t* data, size_t size)
{
    FILE* f = std::fopen(path.c_str(), "wb");
    if (!f || (size && std::fwrite(data, 1, size, f) != size) || std::fclose(f) != 0) {
        std::perror(path.c_str());
        std::abort();
    }
}

} // namespace vdbclay::fuzz
