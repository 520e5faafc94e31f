#include "AtomicFile.h"

#include "vdbclay/Types.h"

#include <cctype>
#include <cerrno>
#include <cstdio>
#include <cstring>
#include <fstream>
#include <vector>

#include <fcntl.h>
#include <sys/stat.h>
#include <unistd.h>

namespace vdbclay {
namespace io_internal {

namespace {

std::string directoryOf(const std::string& path)
{
    const size_t slash = path.find_last_of('/');
    if (slash == std::string::npos) return ".";
    if (slash == 0) return "/";
    return path.substr(0, slash);
}

std::string errnoText(int err) { return err != 0 ? std::strerror(err) : "unknown error"; }

/// Removes the temporary file unless released; closes its descriptor.
struct TempFile {
    std::string path;
    int fd = -1;
    bool keep = false;
    ~TempFile()
    {
        if (fd >= 0) ::close(fd);
        if (!keep && !path.empty()) ::unlink(path.c_str());
    }
};

} // namespace

std::string extensionOf(const std::string& path)
{
    const size_t slash = path.find_last_of('/');
    const size_t dot = path.find_last_of('.');
    if (dot == std::string::npos || (slash != std::string::npos && dot < slash)) return "";
    std::string ext = path.substr(dot);
    for (char& c : ext) c = char(std::tolower(static_cast<unsigned char>(c)));
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
        mode = existing.st_mode & 07777;
    }

    TempFile tmp;
    std::vector<char> name(path.begin(), path.end());
    const char suffix[] = ".tmp-XXXXXX";
    name.insert(name.end(), suffix, suffix + sizeof(suffix)); // includes the terminating 0
    tmp.fd = ::mkstemp(name.data());
    if (tmp.fd < 0) {
        const int err = errno;
        throw Error(prefix + "cannot create a temporary file in " + directoryOf(path) + ": " +
                    errnoText(err));
    }
    tmp.path = name.data();

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
    if (::rename(tmp.path.c_str(), path.c_str()) != 0) {
        const int err = errno;
        throw Error(prefix + "cannot rename " + tmp.path + " over it: " + errnoText(err));
    }
    tmp.keep = true;

    // Make the rename durable; a failure here leaves a complete file, so it is not an error.
    const int dirFd = ::open(directoryOf(path).c_str(), O_RDONLY | O_DIRECTORY);
    if (dirFd >= 0) {
        (void)::fsync(dirFd);
        ::close(dirFd);
    }
}

} // namespace io_internal
} // namespace vdbclay
