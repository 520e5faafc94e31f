// Bytes an OpenVDB tree's nodes take, for the memory estimates (Sculpt.cc's scene estimate, the mesh
// check in ShapesMesh.cc): each node as allocated, glibc's per-allocation overhead included.
#pragma once

#include <openvdb/openvdb.h>

#include <cstdint>
#include <type_traits>

namespace vdbclay {
namespace tree_bytes {

/// glibc's per-allocation overhead (chunk header, 16-byte rounding), counted once per node and
/// once per leaf buffer.
constexpr uint64_t kMallocOverhead = 16;

/// Bytes of one leaf of tree type T: the node, and for value trees its separately allocated buffer.
template <typename TreeT> constexpr uint64_t leafBytes()
{
    using Leaf = typename TreeT::LeafNodeType;
    using V = typename TreeT::ValueType;
    const bool separateBuffer = !std::is_same<V, bool>::value && !std::is_same<V, openvdb::ValueMask>::value;
    return sizeof(Leaf) + kMallocOverhead + (separateBuffer ? Leaf::SIZE * sizeof(V) + kMallocOverhead : 0);
}

} // namespace tree_bytes
} // namespace vdbclay
