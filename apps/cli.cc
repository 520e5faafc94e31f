// The command-line tool's shared parts (cli.h): argument checks, output checks, signal handling.
#include "cli.h"

#include "vdbclay/AtomicWrite.h"
#include "vdbclay/IO.h"

#include <signal.h>
#include <sys/stat.h>
#include <unistd.h>

#include <algorithm>
#include <cctype>
#include <cerrno>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <filesystem>

namespace vdbclay_cli {

vdbclay::BatchHeap gHeap;

std::string printable(const std::string& text)
{
    return vdbclay::printableText(text);
}

CLI::Validator nonEmpty(const char* what)
{
    return CLI::Validator(
        [what](std::string& v) {
            return v.empty() ? std::string("expected ") + what + ", got an empty string" : std::string();
        },
        "", "non-empty");
}

CLI::Validator fileName()
{
    return nonEmpty("a file name");
}

CLI::Validator finiteIn(double lo, double hi, bool open)
{
    return CLI::Validator(
        [=](std::string& v) -> std::string {
            double d = 0;
            size_t used = 0;
            try {
                d = std::stod(v, &used);
            } catch (const std::exception&) {
                used = 0;
            }
            char range[96];
            std::snprintf(range, sizeof range, open ? "a number in (%g, %g)" : "a number in [%g, %g]", lo,
                          hi);
            const bool in = open ? (d > lo && d < hi) : (d >= lo && d <= hi);
            if (used == 0 || used != v.size() || !std::isfinite(d) || !in)
                return "expected " + std::string(range) + ", got " + v;
            return "";
        },
        "", "finite");
}

CLI::Validator integerIn(int64_t lo, uint64_t hi)
{
    const std::string range = "[" + std::to_string(lo) + ", " + std::to_string(hi) + "]";
    return CLI::Validator(
        [=](std::string& v) -> std::string {
            const std::string refused = "expected an integer in " + range + ", got " + v;
            size_t i = 0;
            const bool negative = !v.empty() && v[0] == '-';
            if (!v.empty() && (v[0] == '-' || v[0] == '+')) i = 1;
            if (i == v.size() || v.find_first_not_of("0123456789", i) != std::string::npos) return refused;
            // Exact to 2^64 and beyond: digits past 20 are out of every range an option has.
            const size_t first = std::min(v.find_first_not_of('0', i), v.size());
            if (v.size() - first > 20) return refused;
            __int128 value = 0;
            for (size_t k = first; k < v.size(); ++k)
                value = value * 10 + (v[k] - '0');
            if (negative) value = -value;
            return value >= __int128(lo) && value <= __int128(hi) ? "" : refused;
        },
        "INT in " + range, "integer");
}

vdbclay::UpAxis upOption(const std::string& up)
{
    return parsedOption("--up", [&] { return vdbclay::parseUpAxis(up); });
}

int32_t thresholdOf(const vdbclay::ClayFile& f, int32_t override)
{
    if (override > 0) return override;
    return f.meta.rule.threshold;
}

namespace {

/// What makes two paths the same file: device and inode for an existing regular file, the
/// directory's device and inode plus the name for a file to be created; "" for an existing file
/// that is not regular (a device such as /dev/null may take several outputs).
std::string fileIdentity(const std::string& path)
{
    struct stat st;
    if (::stat(path.c_str(), &st) == 0) {
        if (!S_ISREG(st.st_mode)) return "";
        return "f" + std::to_string(st.st_dev) + ":" + std::to_string(st.st_ino);
    }
    const auto slash = path.find_last_of('/');
    const std::string dir = slash == std::string::npos ? "." : (slash == 0 ? "/" : path.substr(0, slash));
    const std::string name = slash == std::string::npos ? path : path.substr(slash + 1);
    if (::stat(dir.c_str(), &st) == 0)
        return "d" + std::to_string(st.st_dev) + ":" + std::to_string(st.st_ino) + "/" + name;
    return "p" + path;
}

/// Refuses, before any work, an output that cannot be written: a directory, a path through a
/// missing directory or a symbolic-link loop, an unwritable directory. A device or FIFO that
/// exists is written through (never replaced), so it only has to be writable.
void checkWritable(const FileArg& o)
{
    if (o.path.empty()) return;
    const std::string& path = o.path;
    struct stat st;
    std::string dirOf = path;
    if (::stat(path.c_str(), &st) == 0) {
        if (S_ISDIR(st.st_mode)) throw vdbclay::Error(o.text() + ": is a directory, expected a file name");
        if (!S_ISREG(st.st_mode)) {
            if (::access(path.c_str(), W_OK) != 0)
                throw vdbclay::Error("cannot write " + path + ": " + std::strerror(errno));
            return;
        }
        if (char* real = ::realpath(path.c_str(), nullptr)) { // a link: the file it points to is replaced
            dirOf = real;
            std::free(real);
        }
    } else if (errno != ENOENT) {
        throw vdbclay::Error("cannot write " + path + ": " + std::strerror(errno));
    }
    const auto slash = dirOf.find_last_of('/');
    const std::string dir = slash == std::string::npos ? "." : (slash == 0 ? "/" : dirOf.substr(0, slash));
    if (::access(dir.c_str(), W_OK) != 0) {
        throw vdbclay::Error("cannot write " + path + ": directory " + dir + ": " + std::strerror(errno));
    }
}

} // namespace

void checkOutputs(const std::vector<FileArg>& outputs, const std::vector<InputArg>& inputs)
{
    for (const FileArg& o : outputs)
        checkWritable(o);
    for (size_t i = 0; i < outputs.size(); ++i) {
        if (outputs[i].path.empty()) continue;
        const std::string id = fileIdentity(outputs[i].path);
        if (id.empty()) continue;
        for (size_t j = 0; j < i; ++j) {
            if (!outputs[j].path.empty() && fileIdentity(outputs[j].path) == id) {
                throw vdbclay::Error(outputs[i].text() + ": the same file as " + outputs[j].text() +
                                     "; give each output its own file");
            }
        }
        for (const InputArg& in : inputs) {
            if (in.file.path.empty() || fileIdentity(in.file.path) != id) continue;
            if (std::find(in.mayReplace.begin(), in.mayReplace.end(), outputs[i].option) !=
                in.mayReplace.end())
                continue;
            throw vdbclay::Error(outputs[i].text() + ": that is " + in.file.text() +
                                 "; refusing to write over an input");
        }
    }
}

void checkInsideWorkingDirectory(const FileArg& o, const char* flag)
{
    if (o.path.empty()) return;
    // Where it lands: the existing part resolved (links followed: the file a link names is the one
    // replaced), the rest (a file or directories still to be made) normalised, ".." included.
    namespace fs = std::filesystem;
    std::error_code ec;
    const fs::path base = fs::canonical(fs::current_path(ec), ec);
    if (ec) throw vdbclay::Error("cannot resolve the current directory: " + ec.message());
    const fs::path landed = fs::weakly_canonical(base / o.path, ec);
    if (ec) throw vdbclay::Error("cannot write " + o.path + ": " + ec.message());
    if (std::mismatch(base.begin(), base.end(), landed.begin(), landed.end()).first != base.end()) {
        throw vdbclay::Error(o.text() +
                             ": outside the current directory; a scene writes only inside it (name the "
                             "file on the command line, or pass " +
                             flag + "); it resolves to " + landed.string());
    }
}

namespace {

/// The extension of @a path's file name, lower case, with its dot; "" when it has none.
std::string extensionOf(const std::string& path)
{
    const auto slash = path.find_last_of('/');
    const auto dot = path.find_last_of('.');
    std::string ext =
        dot == std::string::npos || (slash != std::string::npos && dot < slash) ? "" : path.substr(dot);
    for (char& c : ext)
        c = char(std::tolower(static_cast<unsigned char>(c)));
    return ext;
}

} // namespace

void checkFormatName(const FileArg& o, const char* ext, const char* format)
{
    const std::string e = extensionOf(o.path);
    if (o.path.empty() || e.empty() || e == ext) return;
    throw vdbclay::Error(o.text() + ": this output is " + format + "; name it " + ext + " (\"" + e +
                         "\" names another format)");
}

void checkMeshName(const FileArg& o)
{
    if (o.path.empty()) return;
    const std::string ext = extensionOf(o.path);
    if (ext != ".obj" && ext != ".ply" && ext != ".stl") {
        throw vdbclay::Error(o.text() + ": unknown mesh format \"" + ext + "\" (use .obj, .ply or .stl)");
    }
}

// ---- signals -------------------------------------------------------------------------------------

std::atomic<int> gStopSignal{0};
std::atomic<bool> gStopAtOnce{true};
std::atomic<bool> gWriting{false};
static_assert(std::atomic<int>::is_always_lock_free, "the signal flag must be lock-free");

namespace {

extern "C" void onStopSignal(int sig)
{
    if (gStopAtOnce.load() || gStopSignal.load() != 0) {
        vdbclay::removePendingTempFile();
        if (gWriting.load()) {
            static const char msg[] =
                "vdbclay: interrupted while writing an output; that file was left as it was\n";
            (void)!::write(2, msg, sizeof msg - 1);
        }
        ::signal(sig, SIG_DFL);
        ::raise(sig); // delivered when this handler returns: the process ends as killed by @a sig
        return;
    }
    gStopSignal.store(sig, std::memory_order_relaxed);
}

} // namespace

void catchSignals()
{
    ::signal(SIGXFSZ, SIG_IGN);
    struct sigaction sa;
    std::memset(&sa, 0, sizeof sa);
    sa.sa_handler = onStopSignal;
    sigemptyset(&sa.sa_mask);
    sa.sa_flags = SA_RESTART; // no EINTR in the middle of writing a file
    for (int sig : {SIGINT, SIGTERM}) {
        struct sigaction old;
        if (::sigaction(sig, nullptr, &old) == 0 && sig == SIGINT && old.sa_handler == SIG_IGN) continue;
        ::sigaction(sig, &sa, nullptr);
    }
}

} // namespace vdbclay_cli
