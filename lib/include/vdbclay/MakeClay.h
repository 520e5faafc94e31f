/// @file MakeClay.h
/// @brief makeClay() (Shapes.h) that a caller can stop, e.g. on Ctrl-C (the Python module does).
#pragma once

#include "vdbclay/Fwd.h"
#include "vdbclay/Shapes.h"

#include <cstdint>
#include <functional>

namespace vdbclay {

/// makeClay(shape, massPerVoxel, dimensions) that a caller can stop: @a stop (when not empty) is
/// called on the calling thread before each batch of 2^14 leaf slots an analytic shape's bounds are
/// cut into, and after every 4096 voxels a volume-keeping shape covers. Once it returns true,
/// makeClay returns null at once (the clay built so far is freed). The clay it returns otherwise is
/// makeClay's. @throw Error as makeClay().
MassGridPtr makeClay(const Shape& shape, int32_t massPerVoxel, int dimensions,
                     const std::function<bool()>& stop);

} // namespace vdbclay
