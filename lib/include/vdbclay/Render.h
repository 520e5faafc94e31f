/// @file Render.h
/// @brief Pictures of clay: PNG files a person can look at.
#pragma once

#include "vdbclay/Fwd.h"

#include <cstdint>
#include <string>

namespace vdbclay {

struct RenderOptions {
    int width = 800; ///< image width in pixels (3D); 2D images scale each voxel to whole pixels
    int height = 600;
    /// 3D camera: azimuth and elevation in degrees around the clay's bounding box centre.
    double azimuthDeg = 35.0;
    double elevationDeg = 25.0;
};

/// Renders @a mass to a PNG at @a path (written atomically). 2D (@a dimensions == 2): the density
/// map m / Tc of the z = 0 layer, coloured like the paper's figures (empty white, then a colour ramp
/// up to Tc, and a distinct colour for cells over Tc), with a legend strip. 3D: a shaded picture of
/// the clay surface (the level set at density 0.5) ray-traced with openvdb::tools::LevelSetRayTracer.
/// @throw Error if the grid holds no clay, the size is not positive, or the file cannot be written.
void renderPng(const std::string& path, const MassGrid& mass, int32_t threshold, int dimensions,
               const RenderOptions& options = RenderOptions());

} // namespace vdbclay
