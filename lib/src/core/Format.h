// Small formatting helpers for error messages (private).
#pragma once

#include <string>

namespace vdbclay {

/// "(x, y, z)" for any coordinate type with x(), y(), z() (openvdb::Coord).
template <typename CoordT> std::string coordStr(const CoordT& c)
{
    return "(" + std::to_string(c.x()) + ", " + std::to_string(c.y()) + ", " + std::to_string(c.z()) + ")";
}

} // namespace vdbclay
