// Byte sizes for budgets and messages, and the default budget: this process's memory (see
// vdbclay/MemoryBudget.h).
#include "vdbclay/MemoryBudget.h"

#include "vdbclay/Types.h"

#include <unistd.h>

#include <algorithm>
#include <cctype>
#include <cmath>
#include <cstdio>
#include <fstream>

namespace vdbclay {

uint64_t parseByteSize(const std::string& text)
{
    auto bad = [&](const std::string& why) -> Error {
        return Error("\"" + text + "\" is not a size: " + why +
                     " (expected e.g. 8G, 512M, 1.5GiB, a number of bytes, or none)");
    };
    std::string t;
    for (char c : text) {
        if (c != ' ') t += char(std::tolower(static_cast<unsigned char>(c)));
    }
    if (t == "none" || t == "unlimited") return kNoMemoryBudget;
    size_t used = 0;
    double value = 0;
    if (t.empty() || !(std::isdigit(static_cast<unsigned char>(t[0])) || t[0] == '.')) throw bad("no number");
    try {
        value = std::stod(t, &used);
    } catch (const std::exception&) {
        throw bad("no number");
    }
    std::string unit = t.substr(used);
    if (!unit.empty() && unit.back() == 'b') unit.pop_back();
    if (!unit.empty() && unit.back() == 'i') unit.pop_back();
    double scale = 1;
    if (unit == "k")
        scale = 1024.0;
    else if (unit == "m")
        scale = 1024.0 * 1024;
    else if (unit == "g")
        scale = 1024.0 * 1024 * 1024;
    else if (unit == "t")
        scale = 1024.0 * 1024 * 1024 * 1024;
    else if (!unit.empty())
        throw bad("unknown unit \"" + t.substr(used) + "\"");
    const double bytes = std::floor(value * scale);
    if (!std::isfinite(bytes) || bytes < 1) throw bad("it must be at least one byte");
    if (bytes >= 9.2e18) throw bad("too large");
    return uint64_t(bytes);
}

std::string formatBytes(uint64_t bytes)
{
    const char* units[] = {"B", "KiB", "MiB", "GiB", "TiB", "PiB", "EiB"};
    double v = double(bytes);
    int u = 0;
    while (v >= 1024 && u < 6) {
        v /= 1024;
        ++u;
    }
    char buf[32];
    if (u == 0)
        std::snprintf(buf, sizeof buf, "%llu B", (unsigned long long)bytes);
    else
        std::snprintf(buf, sizeof buf, "%.*f %s", v < 10 ? 2 : (v < 100 ? 1 : 0), v, units[u]);
    return buf;
}

uint64_t defaultMemoryBudget()
{
    uint64_t avail = uint64_t(::sysconf(_SC_PHYS_PAGES)) * uint64_t(::sysconf(_SC_PAGE_SIZE));
    // A container's limit (cgroup v2, then v1) where it is lower than the machine's memory.
    for (const char* f : {"/sys/fs/cgroup/memory.max", "/sys/fs/cgroup/memory/memory.limit_in_bytes"}) {
        std::ifstream in(f);
        uint64_t limit = 0;
        if (in >> limit && limit > 0) avail = std::min(avail, limit);
    }
    if (avail == 0) avail = uint64_t(16) << 30; // sysconf failed: assume 16 GiB
    return avail / 4 * 3;
}

} // namespace vdbclay
