/// @file InputFile.h
/// @brief Private: how every reader opens its input file, so that none waits forever.
///
/// Two kinds of input. A `.vdb` (clay, a level set, a fog volume) is read by seeking: it must be a
/// regular file, and a FIFO, a device or a directory is refused at once, before anything opens it
/// (opening a FIFO that has no writer blocks). A streamable input (a scene's JSON, an OBJ, STL or
/// PLY mesh) is read whole, front to back: a regular file, a pipe or process substitution
/// (`<(generate)`), a FIFO whose writer is there, or standard input (`-`, where the caller allows
/// it). A FIFO nobody writes to is refused at once, a directory too, and a stream that runs past the
/// caller's limit (/dev/zero) is refused when it does. No OpenVDB include: plain POSIX.
#pragma once

#include <cstdint>
#include <string>

namespace vdbclay {
namespace io_internal {

/// Refuses anything but an existing regular file at @a path.
/// @throw Error "PATH: no such file" / "PATH is a directory, not a WHAT" / "PATH is not a regular
///        file (a WHAT is read by seeking in it)", @a what naming the input ("a .vdb file").
void requireSeekableFile(const std::string& path, const std::string& what);

/// The whole content of the streamable input @a path; "-" is standard input when @a allowStdin.
/// @throw Error naming @a path and @a what ("scene file", "mesh") when it is missing, a directory,
///        a FIFO with no writer, unreadable, or longer than @a maxBytes.
std::string readStreamable(const std::string& path, const std::string& what, uint64_t maxBytes,
                           bool allowStdin = false);

} // namespace io_internal
} // namespace vdbclay
