// The size limit of the global layer's dense cell index (Transport.cc, Solver::resetIndex), which the
// memory estimate (MemoryEstimate.cc) counts.
#pragma once

#include <cstdint>

namespace vdbclay {
namespace transport_internal {

/// The layer's dense cell index holds at most this many entries of 4 bytes (32 MiB); a larger box
/// uses the tree alone.
constexpr int64_t kDenseIndexMax = int64_t(1) << 23;

} // namespace transport_internal
} // namespace vdbclay
