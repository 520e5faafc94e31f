/// @file VdbCheck.h
/// @brief Private: checks a .vdb file's layout, byte by byte, before OpenVDB reads it.
///
/// OpenVDB 10 trusts the sizes a file records: a damaged length makes it allocate gigabytes, and a
/// damaged compressed-block size makes it copy past the end of a node's buffer (a heap overflow,
/// found by tests/fuzz/fuzz_vdb). checkVdbLayout() walks the same layout OpenVDB reads (header,
/// file metadata, grid descriptors, and for each grid its metadata, transform, tree topology and
/// leaf buffers) without allocating by any recorded size, and refuses any file whose sizes,
/// counts or positions do not fit, before OpenVDB sees it. No OpenVDB include: pure bytes.
#pragma once

#include <cstdint>
#include <string>
#include <vector>

namespace vdbclay {
namespace io_internal {

/// One grid of a checked file.
struct VdbGridLayout {
    std::string name;
    std::string type;         ///< OpenVDB's tree type name, e.g. "Tree_int32_5_4_3"
    bool treeChecked = false; ///< its tree was walked (a value type checkVdbLayout knows)
    /// When treeChecked: the nodes its topology really holds (not what its metadata claims).
    uint64_t leaves = 0, lowerNodes = 0, upperNodes = 0;
    /// The name OpenVDB looks the grid up by: the unique name up to its "\x1e" suffix.
    std::string baseName() const { return name.substr(0, name.find('\x1e')); }
};

/// The grid types whose trees checkVdbLayout walks: 5-4-3 trees of int32, int64, float, double,
/// vec3i, vec3s, vec3d values (the float types also saved as half floats).
bool treeTypeKnown(const std::string& type);

/// Checks the file at @a path. @return its grids, in file order.
/// @throw Error "what is wrong, at which byte" (without the path: callers prefix it) if the file is
///        not a seekable .vdb of format 222..224 or any recorded size, count or position is
///        inconsistent with the file.
std::vector<VdbGridLayout> checkVdbLayout(const std::string& path);

} // namespace io_internal
} // namespace vdbclay
