// A voxel coordinate's hash for the library's hash maps and sets of voxels and slots.
#pragma once

#include <openvdb/Types.h> // openvdb::Coord

#include <cstddef>
#include <cstdint>

namespace vdbclay {

/// A voxel's hash (std::hash<Coord>, OpenVDB's, keeps 20 bits: too few buckets for a large push).
struct CoordHash {
    size_t operator()(const openvdb::Coord& c) const
    {
        uint64_t h = uint64_t(uint32_t(c.x())) * 0x9E3779B97F4A7C15ull;
        h ^= uint64_t(uint32_t(c.y())) * 0xC2B2AE3D27D4EB4Full;
        h ^= uint64_t(uint32_t(c.z())) * 0x165667B19E3779F9ull;
        return size_t(h ^ (h >> 29));
    }
};

} // namespace vdbclay
