/// @file AtomicFile.h
/// @brief Private: write a file atomically (temp file beside it, fsync, rename). No OpenVDB here.
#pragma once

#include <functional>
#include <iosfwd>
#include <string>

namespace vdbclay {
namespace io_internal {

/// Creates a unique temporary file PATH.tmp-XXXXXX in @a path's directory, lets @a write fill it
/// through a binary std::ostream, flushes and fsyncs it, gives it the mode of an existing @a path
/// (else 0644), then renames it over @a path and fsyncs the directory.
/// @throw Error "cannot write PATH: REASON" on any failure (including an exception thrown by
///        @a write); the temporary file is then removed and an existing @a path is untouched.
void writeAtomically(const std::string& path, const std::function<void(std::ostream&)>& write);

/// The lower-case extension of @a path including the dot (".obj"), or "" if there is none.
std::string extensionOf(const std::string& path);

} // namespace io_internal
} // namespace vdbclay
