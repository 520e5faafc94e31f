// How every reader opens its input file (InputFile.h): seekable files checked before they open,
// streams read whole without blocking on a FIFO that has no writer.
#include "core/InputFile.h"

#include "vdbclay/MemoryBudget.h"
#include "vdbclay/Types.h"

#include <fcntl.h>
#include <sys/stat.h>
#include <unistd.h>

#include <cerrno>
#include <cstring>

namespace vdbclay {
namespace io_internal {

namespace {

std::string reasonOf(int err)
{
    return err == ENOENT ? std::string("no such file") : std::string(std::strerror(err));
}

/// Closes the descriptor it holds (never standard input) when the read ends, thrown or not.
struct Descriptor {
    int fd = -1;
    bool owned = true;
    ~Descriptor()
    {
        if (owned && fd >= 0) ::close(fd);
    }
};

} // namespace

void requireSeekableFile(const std::string& path, const std::string& what)
{
    struct stat st;
    if (::stat(path.c_str(), &st) != 0) {
        const int err = errno;
        throw Error(path + ": " + reasonOf(err));
    }
    if (S_ISDIR(st.st_mode)) throw Error(path + " is a directory, not " + what);
    // A FIFO without a writer would block the open; a device or pipe cannot be seeked in, and
    // /dev/zero never ends.
    if (!S_ISREG(st.st_mode))
        throw Error(path + " is not a regular file (" + what + " is read by seeking in it)");
}

std::string readStreamable(const std::string& path, const std::string& what, uint64_t maxBytes,
                           bool allowStdin)
{
    const bool fromStdin = allowStdin && path == "-";
    const std::string name = fromStdin ? std::string("standard input") : path;
    Descriptor in;
    bool fifo = false;
    if (fromStdin) {
        in.fd = STDIN_FILENO;
        in.owned = false;
        struct stat st;
        if (::fstat(in.fd, &st) != 0) {
            const int err = errno;
            throw Error(name + ": cannot read " + what + ": " + std::strerror(err));
        }
        if (S_ISDIR(st.st_mode)) throw Error(name + " is a directory, expected a " + what);
    } else {
        struct stat st;
        if (::stat(path.c_str(), &st) != 0) {
            const int err = errno;
            throw Error(path + ": cannot open " + what + ": " + reasonOf(err));
        }
        if (S_ISDIR(st.st_mode)) throw Error(path + ": is a directory, expected a " + what);
        if (S_ISREG(st.st_mode) && uint64_t(st.st_size) > maxBytes) {
            throw Error(path + ": " + std::to_string(st.st_size) + " bytes, more than a " + what +
                        " may hold (" + formatBytes(maxBytes) + ")");
        }
        // Opened without blocking: a FIFO's open waits for a writer, which may never come.
        fifo = S_ISFIFO(st.st_mode);
        in.fd = ::open(path.c_str(), O_RDONLY | O_CLOEXEC | (fifo ? O_NONBLOCK : 0));
        if (in.fd < 0) {
            const int err = errno;
            throw Error(path + ": cannot open " + what + ": " + reasonOf(err));
        }
    }
    std::string data;
    char buf[65536];
    bool waiting = fifo; // a FIFO opened without blocking: no byte and no writer seen yet
    for (;;) {
        const ssize_t n = ::read(in.fd, buf, sizeof buf);
        if (n < 0) {
            const int err = errno;
            if (err == EINTR) continue;
            if (err == EAGAIN || err == EWOULDBLOCK) {
                // A writer holds the FIFO and has written nothing yet: wait for its bytes.
                const int flags = ::fcntl(in.fd, F_GETFL);
                if (flags < 0 || ::fcntl(in.fd, F_SETFL, flags & ~O_NONBLOCK) < 0) {
                    const int e = errno;
                    throw Error(name + ": cannot read " + what + ": " + std::strerror(e));
                }
                waiting = false;
                continue;
            }
            throw Error(name + ": cannot read " + what + ": " + std::strerror(err));
        }
        if (n == 0) {
            if (waiting) {
                throw Error(path +
                            ": a FIFO with no writer, nothing to read; start the program that writes it "
                            "first, or give a file");
            }
            break;
        }
        waiting = false;
        if (data.size() + size_t(n) > maxBytes) {
            throw Error(name + ": more than " + formatBytes(maxBytes) + " of data, more than a " + what +
                        " may hold (is it a " + what + "?)");
        }
        data.append(buf, size_t(n));
    }
    return data;
}

} // namespace io_internal
} // namespace vdbclay
