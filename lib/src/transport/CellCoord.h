// A cell's integer coordinates without OpenVDB: the global transport's cells (Domain.h) and the
// multigrid's rows (Multigrid.h; on a coarse level, their blocks). Ordered as openvdb::Coord is: by x,
// then y, then z.
#pragma once

#include <algorithm>
#include <cstdint>

namespace vdbclay {
namespace transport_internal {

struct CellCoord {
    int32_t x = 0, y = 0, z = 0;

    CellCoord offsetBy(int32_t dx, int32_t dy, int32_t dz) const { return CellCoord{x + dx, y + dy, z + dz}; }
    /// Each coordinate the smaller (minComponent) or the larger (maxComponent) of this one's and @a o's.
    void minComponent(const CellCoord& o)
    {
        x = std::min(x, o.x);
        y = std::min(y, o.y);
        z = std::min(z, o.z);
    }
    void maxComponent(const CellCoord& o)
    {
        x = std::max(x, o.x);
        y = std::max(y, o.y);
        z = std::max(z, o.z);
    }
    int32_t operator[](int axis) const { return axis == 0 ? x : axis == 1 ? y : z; }
    bool operator==(const CellCoord& o) const { return x == o.x && y == o.y && z == o.z; }
    bool operator!=(const CellCoord& o) const { return !(*this == o); }
    bool operator<(const CellCoord& o) const
    {
        if (x != o.x) return x < o.x;
        if (y != o.y) return y < o.y;
        return z < o.z;
    }
};

} // namespace transport_internal
} // namespace vdbclay
