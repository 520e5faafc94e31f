/// @file Png.h
/// @brief Private: 8-bit RGB PNG files through libpng, written atomically. No OpenVDB here.
#pragma once

#include <cstdint>
#include <string>
#include <vector>

namespace vdbclay {
namespace io_internal {

/// Writes @a rgb (@a height rows of @a width pixels, 3 bytes each, top row first) to @a path.
/// @throw Error naming the path if the encoding or the write fails.
void writePngRgb(const std::string& path, int width, int height, const std::vector<uint8_t>& rgb);

} // namespace io_internal
} // namespace vdbclay
