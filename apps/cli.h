// The command-line tool's shared parts: the subcommands main() dispatches (one file each), the
// checks of arguments and output files made before any work, and the signal handling that lets a
// run stop where it resumes exactly. Thin: parsing and printing here, all work in the library.
#pragma once

#include "vdbclay/BatchHeap.h"
#include "vdbclay/IO.h"
#include "vdbclay/Types.h"

#include <CLI/CLI.hpp>

#include <atomic>
#include <cstdint>
#include <functional>
#include <string>
#include <vector>

namespace vdbclay_cli {

// ---- subcommands (run.cc, info.cc, mesh.cc, render.cc, import.cc, demo.cc) -----------------------

/// A subcommand as main() dispatches it: its CLI11 subcommand, and what runs it once the command
/// line is parsed (returns the exit code; throws vdbclay::Error for main to print).
struct Subcommand {
    CLI::App* app = nullptr;
    std::function<int()> run;
};

Subcommand addRunCommand(CLI::App& app);
Subcommand addInfoCommand(CLI::App& app);
Subcommand addMeshCommand(CLI::App& app);
Subcommand addRenderCommand(CLI::App& app);
Subcommand addImportCommand(CLI::App& app);
Subcommand addDemoCommand(CLI::App& app);

/// What configureBatchHeap() did (main sets it first thing; run's --stats reports it).
extern vdbclay::BatchHeap gHeap;

// ---- arguments -----------------------------------------------------------------------------------

/// Most worker threads an option may ask for: beyond this TBB only warns and clamps.
constexpr int kMaxThreads = 256;

/// @a text with control and non-UTF-8 bytes escaped, for messages (vdbclay::printableText).
std::string printable(const std::string& text);

/// A CLI11 check that an option's value is not an empty string ("" would silently mean "none").
CLI::Validator nonEmpty(const char* what);
/// nonEmpty("a file name"): every option that names a file.
CLI::Validator fileName();
/// A CLI11 check that a number is finite and within [@a lo, @a hi] (open at both ends when @a open):
/// CLI11's own range checks accept nan and print the limits of double in full.
CLI::Validator finiteIn(double lo, double hi, bool open = false);
/// A CLI11 check that an integer option's value is a decimal integer within [@a lo, @a hi], checked
/// on its digits before CLI11 converts it: a value past the limits of its type is refused, never
/// clamped, "-3" is not wrapped around, and "1e3", "0x10" or "12abc" are not integers.
CLI::Validator integerIn(int64_t lo, uint64_t hi);

/// @a parse(), its Error prefixed with @a option ("--rule: unknown rule ..."): for option values
/// that the library parses.
template <typename F> auto parsedOption(const char* option, F parse) -> decltype(parse())
{
    try {
        return parse();
    } catch (const vdbclay::Error& e) {
        throw vdbclay::Error(std::string(option) + ": " + e.what());
    }
}

/// --up's value as an axis. @throw Error "--up: ..." if it is not y or z.
vdbclay::UpAxis upOption(const std::string& up);

/// The Tc to read @a f with: @a override when given (> 0), else the file's.
int32_t thresholdOf(const vdbclay::ClayFile& f, int32_t override);

// ---- output files --------------------------------------------------------------------------------

/// A file an option names, as messages refer to it: "-o out.vdb".
struct FileArg {
    std::string option; ///< "-o", "--png", "the scene file", ...
    std::string path;
    std::string text() const { return option + " " + path; }
};

/// An input file, and the options of the outputs allowed to write over it (a start file continued
/// in place by -o).
struct InputArg {
    FileArg file;
    std::vector<std::string> mayReplace;
};

/// Checks every output before any work: each writable (not a directory, not through a missing
/// directory, its directory writable; a device or FIFO only has to be writable), no two the same
/// file, none of them one of @a inputs unless that input allows it.
/// @throw Error naming the option and the file.
void checkOutputs(const std::vector<FileArg>& outputs, const std::vector<InputArg>& inputs);

/// Refuses a file a scene names for writing that lies outside the current directory: an absolute
/// path, a ".." that leaves it, or a symbolic link (of the file or a directory on its way) that
/// points out of it. A scene received from someone else writes only where the user works; the
/// command line's own options name files anywhere. @a flag names the option that lifts the rule.
void checkInsideWorkingDirectory(const FileArg& o, const char* flag);

/// Refuses a mesh output whose extension names no format vdbclay writes (.obj, .ply, .stl).
void checkMeshName(const FileArg& o);

/// Refuses an output whose name ends in an extension other than @a ext (".vdb", ".png"): the file
/// would hold @a format under another format's name. A name with no extension (a device, a FIFO)
/// is written as it is.
void checkFormatName(const FileArg& o, const char* ext, const char* format);

// ---- signals -------------------------------------------------------------------------------------
// While a scene runs, SIGINT and SIGTERM only set a flag (a lock-free atomic store is
// async-signal-safe); the run polls it between automaton steps, stops where a checkpoint resumes
// exactly, and writes one. At any other time (building the scene, writing outputs, a second signal)
// the signal ends the process at once, as it would without vdbclay's handler, but first removes the
// temporary file of a write in progress: the file being written keeps its old contents.

/// The signal that asked a run to stop (0: none yet).
extern std::atomic<int> gStopSignal;
/// True outside a run's steps: a signal ends the process at once.
extern std::atomic<bool> gStopAtOnce;
/// True once outputs are being written: a signal then says the file was left as it was.
extern std::atomic<bool> gWriting;

/// Catches SIGINT and SIGTERM (a SIGINT the caller ignores, as in a background job of a script,
/// stays ignored). SIGXFSZ is ignored, so that a write over the file size limit (ulimit -f) fails
/// with EFBIG and is reported, instead of killing the process with a temporary file left behind.
void catchSignals();

} // namespace vdbclay_cli
