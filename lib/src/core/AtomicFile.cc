// Writing files so that a failure never leaves half a file: a regular file (or a new one) is written
// to a temporary file beside it, fsynced and renamed over it. A path that is not a regular file (a
// device such as /dev/null or /dev/stdout, a FIFO, a process substitution) is never replaced: the
// bytes are written through it, and a failed write (ENOSPC on /dev/full) is an error. A symbolic
// link stays a link: the file it points to is the one replaced.
//
// A signal handler that ends the process in the middle of a write calls removePendingTempFile()
// (async-signal-safe), so an interrupted write leaves nothing behind either.
#include "core/AtomicFile.h"

#include "vdbclay/AtomicWrite.h"
#include "vdbclay/Types.h"

#include <atomic>
#include <algorithm>
#include <cctype>
#include <cerrno>
#include <cstdio>
#include <cstring>
#include <cstdlib>
#include <fstream>
#include <sstream>
#include <vector>

#include <fcntl.h>
#include <sys/stat.h>
#include <unistd.h>

namespace vdbclay {

namespace {

/// The temporary file of the write in progress, for removePendingTempFile(): a fixed buffer, since
/// a signal handler may read it at any time (it is written only while gPendingSet is false).
char gPendingTemp[4096];
std::atomic<bool> gPendingSet{false};
static_assert(std::atomic<bool>::is_always_lock_free, "read from a signal handler");

void setPendingTemp(const std::string& path)
{
    gPendingSet.store(false);
    if (path.size() >= sizeof gPendingTemp) return; // not removable from a handler; still removed on errors
    std::memcpy(gPendingTemp, path.c_str(), path.size() + 1);
    gPendingSet.store(true);
}

} // namespace

void removePendingTempFile() noexcept
{
    if (gPendingSet.load()) ::unlink(gPendingTemp);
}

void writeTextFile(const std::string& path, const std::string& text)
{
    io_internal::writeAtomically(path, [&](std::ostream& os) { os << text; });
}

namespace io_internal {

namespace {

std::string directoryOf(const std::string& path)
{
    const size_t slash = path.find_last_of('/');
    if (slash == std::string::npos) return ".";
    if (slash == 0) return "/";
    return path.substr(0, slash);
}

std::string errnoText(int err)
{
    return err != 0 ? std::strerror(err) : "unknown error";
}

/// Removes the temporary file unless released; closes its descriptor.
struct TempFile {
    std::string path;
    int fd = -1;
    bool keep = false;
    ~TempFile()
    {
        if (fd >= 0) ::close(fd);
        if (!keep && !path.empty()) ::unlink(path.c_str());
        gPendingSet.store(false);
    }
};

/// Writes @a write's bytes through the existing non-regular file @a path (a device, a FIFO): they
/// are built in memory first (a .vdb archive seeks back to record offsets; a pipe cannot), then
/// written with write(2), so that every failure (ENOSPC, EPIPE, EIO) is reported.
void writeThrough(const std::string& path, const std::function<void(std::ostream&)>& write)
{
    const std::string prefix = "cannot write " + path + ": ";
    std::ostringstream buffer(std::ios::out | std::ios::binary);
    try {
        write(buffer);
    } catch (const Error&) {
        throw;
    } catch (const std::exception& e) {
        throw Error(prefix + e.what());
    }
    if (!buffer) throw Error(prefix + "could not build its contents in memory");
    const std::string bytes = buffer.str();
    const int fd = ::open(path.c_str(), O_WRONLY | O_NOCTTY | O_CLOEXEC);
    if (fd < 0) {
        const int err = errno;
        throw Error(prefix + errnoText(err));
    }
    size_t done = 0;
    while (done < bytes.size()) {
        const ssize_t n = ::write(fd, bytes.data() + done, std::min<size_t>(bytes.size() - done, 1 << 20));
        if (n < 0 && errno == EINTR) continue;
        if (n <= 0) {
            const int err = n < 0 ? errno : EIO;
            ::close(fd);
            throw Error(prefix + "write failed: " + errnoText(err));
        }
        done += size_t(n);
    }
    if (::close(fd) != 0 && errno != EINTR) {
        const int err = errno;
        throw Error(prefix + "write failed on close: " + errnoText(err));
    }
}

} // namespace

std::string extensionOf(const std::string& path)
{
    const size_t slash = path.find_last_of('/');
    const size_t dot = path.find_last_of('.');
    if (dot == std::string::npos || (slash != std::string::npos && dot < slash)) return "";
    std::string ext = path.substr(dot);
    for (char& c : ext)
        c = char(std::tolower(static_cast<unsigned char>(c)));
    return ext;
}

void writeAtomically(const std::string& path, const std::function<void(std::ostream&)>& write)
{
    const std::string prefix = "cannot write " + path + ": ";
    if (path.empty()) throw Error("cannot write a file with an empty name");

    struct stat existing;
    mode_t mode = 0644;
    if (::stat(path.c_str(), &existing) == 0) {
        if (S_ISDIR(existing.st_mode)) throw Error(prefix + "it is a directory");
        if (!S_ISREG(existing.st_mode)) return writeThrough(path, write);
        mode = existing.st_mode & 07777;
    }
    // A symbolic link to a file: replace the file, keep the link.
    std::string target = path;
    struct stat link;
    if (::lstat(path.c_str(), &link) == 0 && S_ISLNK(link.st_mode)) {
        if (char* real = ::realpath(path.c_str(), nullptr)) {
            target = real;
            std::free(real);
        }
    }

    TempFile tmp;
    std::vector<char> name(target.begin(), target.end());
    const char suffix[] = ".tmp-XXXXXX";
    name.insert(name.end(), suffix, suffix + sizeof(suffix)); // includes the terminating 0
    tmp.fd = ::mkstemp(name.data());
    if (tmp.fd < 0) {
        const int err = errno;
        throw Error(prefix + "cannot create a temporary file in " + directoryOf(target) + ": " +
                    errnoText(err));
    }
    tmp.path = name.data();
    setPendingTemp(tmp.path);

    try {
        std::ofstream os;
        os.exceptions(std::ios::goodbit);
        os.open(tmp.path, std::ios::out | std::ios::binary | std::ios::trunc);
        if (!os) {
            const int err = errno;
            throw Error(prefix + "cannot open " + tmp.path + ": " + errnoText(err));
        }
        errno = 0;
        write(os);
        os.flush();
        if (!os) {
            const int err = errno;
            throw Error(prefix + "write failed: " + errnoText(err));
        }
        os.close();
        if (os.fail()) {
            const int err = errno;
            throw Error(prefix + "write failed on close: " + errnoText(err));
        }
    } catch (const Error&) {
        throw;
    } catch (const std::exception& e) {
        throw Error(prefix + e.what());
    }

    if (::fchmod(tmp.fd, mode) != 0) {
        const int err = errno;
        throw Error(prefix + "cannot set the mode of " + tmp.path + ": " + errnoText(err));
    }
    if (::fsync(tmp.fd) != 0) {
        const int err = errno;
        throw Error(prefix + "fsync failed: " + errnoText(err));
    }
    const int fd = tmp.fd;
    tmp.fd = -1;
    if (::close(fd) != 0) {
        const int err = errno;
        throw Error(prefix + "close failed: " + errnoText(err));
    }
    if (::rename(tmp.path.c_str(), target.c_str()) != 0) {
        const int err = errno;
        throw Error(prefix + "cannot rename " + tmp.path + " over it: " + errnoText(err));
    }
    tmp.keep = true;

    // Make the rename durable; a failure here leaves a complete file, so it is not an error.
    const int dirFd = ::open(directoryOf(target).c_str(), O_RDONLY | O_DIRECTORY);
    if (dirFd >= 0) {
        (void)::fsync(dirFd);
        ::close(dirFd);
    }
}

} // namespace io_internal
} // namespace vdbclay
