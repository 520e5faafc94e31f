// What the readers of .vdb files share (VdbFile.h).
#include "io/VdbFile.h"

#include "core/InputFile.h"

#include <fcntl.h>
#include <unistd.h>

#include <cerrno>
#include <cstring>
#include <new>
#include <sstream>

namespace vdbclay {
namespace io_internal {

namespace {

/// Clay voxels may lie at most this far from the origin along each axis: shapes' bounds (Shapes.h)
/// and the automaton's search margins stay inside int32 from there.
constexpr int32_t kMaxClayCoord = 1 << 30;

} // namespace

std::string reason(const std::exception& e)
{
    if (dynamic_cast<const std::bad_alloc*>(&e)) return "it records a size larger than the memory available";
    std::string out;
    const char* p = e.what();
    for (; *p && out.size() < 200; ++p) {
        const unsigned char c = static_cast<unsigned char>(*p);
        const char ch = (c >= 32 && c < 127) ? char(c) : ' ';
        if (ch == ' ' && (out.empty() || out.back() == ' ')) continue;
        out += ch;
    }
    while (!out.empty() && out.back() == ' ')
        out.pop_back();
    if (*p) out += "...";
    return out.empty() ? "unreadable data" : out;
}

std::string damaged(const std::string& path)
{
    return path + " is not a .vdb file or is truncated or damaged: ";
}

std::string valueTypeOf(const std::string& treeType)
{
    std::string t = treeType;
    if (t.rfind("Tree_", 0) == 0) t = t.substr(5);
    const auto cut = t.find("_5_4_3");
    return cut == std::string::npos ? t : t.substr(0, cut);
}

std::vector<VdbGridLayout> openChecked(openvdb::io::File& file, const std::string& path)
{
    requireSeekableFile(path, "a .vdb file");
    {
        const int fd = ::open(path.c_str(), O_RDONLY | O_CLOEXEC);
        if (fd < 0) {
            const int err = errno;
            throw Error(path + ": cannot open it: " + std::strerror(err));
        }
        ::close(fd);
    }
    const std::string prefix = damaged(path);
    std::vector<VdbGridLayout> grids;
    try {
        grids = checkVdbLayout(path);
    } catch (const Error& e) {
        throw Error(prefix + e.what());
    }
    try {
        file.open(/*delayLoad=*/false);
    } catch (const std::exception& e) {
        throw Error(prefix + reason(e));
    }
    return grids;
}

std::string gridNames(openvdb::io::File& file)
{
    std::string names;
    for (auto it = file.beginName(); it != file.endName(); ++it) {
        if (!names.empty()) names += ", ";
        names += "\"" + it.gridName() + "\"";
    }
    return names.empty() ? "none" : names;
}

std::string coordText(const openvdb::Coord& c)
{
    std::ostringstream s;
    s << "(" << c.x() << ", " << c.y() << ", " << c.z() << ")";
    return s.str();
}

void normalizeClay(openvdb::Int32Grid& grid, const std::string& path, const std::string& gridName)
{
    const std::string what = path + ": grid \"" + gridName + "\"";
    if (grid.background() != 0) {
        throw Error(what + " has background value " + std::to_string(grid.background()) +
                    ", expected 0 (a non-zero background puts clay in every voxel of space)");
    }
    bool inactive = false;
    for (auto it = grid.tree().cbeginValueAll(); it; ++it) {
        if (*it != 0 && !it.isValueOn()) {
            inactive = true;
            break;
        }
    }
    if (inactive) {
        for (auto it = grid.tree().beginValueAll(); it; ++it) {
            if (*it != 0 && !it.isValueOn()) it.setActiveState(true);
        }
    }
    const openvdb::CoordBBox box = grid.evalActiveVoxelBoundingBox();
    if (!box.empty()) {
        for (int a = 0; a < 3; ++a) {
            if (box.min()[a] < -kMaxClayCoord || box.max()[a] > kMaxClayCoord) {
                throw Error(what + " holds clay from " + coordText(box.min()) + " to " +
                            coordText(box.max()) +
                            ", outside the coordinate range +-2^30 that vdbclay works in");
            }
        }
    }
}

} // namespace io_internal
} // namespace vdbclay
