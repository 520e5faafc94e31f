// The metadata names of a clay file's "mass" grid (and "density"): written by writeClayFile (ClayFile.cc,
// checkpoints too), read back by readClayFile and, without the voxels, by the memory estimate
// (MemoryEstimate.cc). They are the file format: docs/INTEROP.md lists them, and tests pin them.
#pragma once

namespace vdbclay {
namespace io_internal {

constexpr const char* kMetaThreshold = "vdbclay_threshold";
constexpr const char* kMetaRule = "vdbclay_rule";
constexpr const char* kMetaAlpha = "vdbclay_alpha";
constexpr const char* kMetaSeed = "vdbclay_seed";
constexpr const char* kMetaSteps = "vdbclay_steps";
constexpr const char* kMetaFrames = "vdbclay_frames";
constexpr const char* kMetaFrameSteps = "vdbclay_frame_steps";
constexpr const char* kMetaDimensions = "vdbclay_dimensions";
constexpr const char* kMetaVoxelSize = "vdbclay_voxel_size";
constexpr const char* kMetaVersion = "vdbclay_version";
constexpr const char* kMetaUp = "vdbclay_up";
constexpr const char* kMetaMassAdded = "vdbclay_mass_added";     ///< int64, only when > 0
constexpr const char* kMetaMassRemoved = "vdbclay_mass_removed"; ///< int64, only when > 0
constexpr const char* kMetaChangedClay = "vdbclay_changed_clay"; ///< string, only when not empty
constexpr const char* kMetaMaxMass = "vdbclay_max_mass";         ///< the largest cell, int64

} // namespace io_internal
} // namespace vdbclay
