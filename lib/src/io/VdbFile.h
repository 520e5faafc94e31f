/// @file VdbFile.h
/// @brief Private: what the readers of .vdb files share (ClayFile.cc, Import.cc, Describe.cc): the
///        checked open, the messages about damaged files, typed metadata, and the one definition of
///        the clay in a file.
#pragma once

#include "core/VdbCheck.h"

#include "vdbclay/Types.h"

#include <openvdb/io/File.h>
#include <openvdb/openvdb.h>

#include <cstdint>
#include <exception>
#include <memory>
#include <string>
#include <vector>

namespace vdbclay {
namespace io_internal {

/// An exception's text fit for a message: OpenVDB's errors on damaged files quote whatever bytes
/// it read (a "grid type" of garbage and kilobytes of blanks), so keep printable characters,
/// collapse runs of blanks and cut it short.
std::string reason(const std::exception& e);

/// The start of every message about a file OpenVDB could not read.
std::string damaged(const std::string& path);

/// "int32" for "Tree_int32_5_4_3": the value type, as openvdb::GridBase::valueType() names it.
std::string valueTypeOf(const std::string& treeType);

/// Opens @a path for reading with every check readClayFile promises; grids are read in full
/// (no delayed loading), so the file may be replaced afterwards. OpenVDB trusts the sizes a file
/// records (a damaged one makes it allocate gigabytes or overrun a buffer), so the layout is
/// checked byte by byte first (core/VdbCheck.h). @return the grids the check found.
/// @throw Error naming the file if it is missing, not a regular file, unreadable or damaged.
std::vector<VdbGridLayout> openChecked(openvdb::io::File& file, const std::string& path);

/// The names of an open file's grids, quoted and separated by commas ("none" for no grid).
std::string gridNames(openvdb::io::File& file);

/// Reads the metadata @a name of @a grid into @a out when it is there; returns whether it was.
/// @throw Error naming the file if it is there with another type than @a MetaT (@a typeName).
template <typename T, typename MetaT>
bool readMeta(const openvdb::GridBase& grid, const char* name, T& out, const std::string& path,
              const char* typeName)
{
    const auto m = grid[name];
    if (!m) return false;
    const auto typed = std::dynamic_pointer_cast<const MetaT>(m);
    if (!typed) {
        throw Error(path + ": metadata " + name + " is a " + m->typeName() + ", expected " + typeName);
    }
    out = T(typed->value());
    return true;
}

/// "(x, y, z)".
std::string coordText(const openvdb::Coord& c);

/// One definition of "the clay in a file", used by every command: every voxel holding a non-zero
/// value, active or not, is clay, as totalMass() and clayVoxelCount() count it. So inactive voxels
/// and tiles holding mass become active (tiles stay tiles: uniform clay, automaton/Tiles.h), and a
/// non-zero background (clay in all of space) is refused, as is clay outside +-2^30.
/// @throw Error naming @a path and @a gridName when the grid is refused.
void normalizeClay(openvdb::Int32Grid& grid, const std::string& path, const std::string& gridName);

} // namespace io_internal
} // namespace vdbclay
