/// @file Fwd.h
/// @brief Forward declarations of the OpenVDB grid types vdbclay's API uses.
///
/// Including <openvdb/openvdb.h> costs several seconds of compile time in every translation unit
/// that sees it. vdbclay's public headers name grids only through these declarations, so a tool
/// that links vdbclay pays for OpenVDB only in the files that build or read grids. The aliases are
/// checked against OpenVDB's own (static_assert in lib/src/automaton/Automaton.cc).
#pragma once

#include <openvdb/version.h>

#include <cstdint>
#include <memory>

namespace openvdb {
OPENVDB_USE_VERSION_NAMESPACE
namespace OPENVDB_VERSION_NAME {
class ValueMask;
namespace tree {
template <typename T, uint32_t Log2Dim> class LeafNode;
template <typename ChildT, uint32_t Log2Dim> class InternalNode;
template <typename ChildT> class RootNode;
template <typename RootNodeType> class Tree;
} // namespace tree
template <typename TreeT> class Grid;
} // namespace OPENVDB_VERSION_NAME
} // namespace openvdb

namespace vdbclay {

/// The tree configuration of openvdb::Int32Grid / openvdb::MaskGrid (5-4-3).
template <typename T>
using Tree543 = openvdb::tree::Tree<openvdb::tree::RootNode<
    openvdb::tree::InternalNode<openvdb::tree::InternalNode<openvdb::tree::LeafNode<T, 3>, 4>, 5>>>;

/// Clay: an integer mass per voxel. Same type as openvdb::Int32Grid.
using MassGrid = openvdb::Grid<Tree543<int32_t>>;
using MassGridPtr = std::shared_ptr<MassGrid>;
/// Obstacles: active voxels are cells clay never enters and never leaves. Same as openvdb::MaskGrid.
using ObstacleGrid = openvdb::Grid<Tree543<openvdb::ValueMask>>;
using ObstacleGridPtr = std::shared_ptr<ObstacleGrid>;

} // namespace vdbclay
