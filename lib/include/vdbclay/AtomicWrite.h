/// @file AtomicWrite.h
/// @brief Writing files as vdbclay writes its own (a temporary file beside the target, renamed over
///        it), and the clean-up a program's signal handler calls when a write is interrupted.
///
/// Every file the library writes (clay files, meshes, pictures) goes this way; these are for a
/// program's own outputs (the vdbclay command's --stats JSON) and its signal handler.
#pragma once

#include <string>

namespace vdbclay {

/// Writes @a text to @a path as writeClayFile writes a .vdb: atomically for a regular file, through
/// it for a device or FIFO (never replacing it). @throw Error "cannot write PATH: REASON".
void writeTextFile(const std::string& path, const std::string& text);

/// For a signal handler that ends the process during a write: removes the temporary file of the
/// write in progress, if any. Async-signal-safe (one unlink(2) of a name kept in a fixed buffer).
void removePendingTempFile() noexcept;

} // namespace vdbclay
