// vdbclay: the command-line tool. Subcommands: run (scenes), info, mesh, render, import, demo, one
// file each (cli.h). Every error ends in one line on stderr and a non-zero exit code.
#include "cli.h"

#include "vdbclay/BatchHeap.h"

#include <openvdb/openvdb.h>

#include <iostream>
#include <new>
#include <string>
#include <vector>

namespace {

using namespace vdbclay_cli;

/// CLI11 takes an unknown word for a stray argument and says only "A subcommand is required": a
/// first argument that is no option and names no subcommand is refused here, by name (exit 2).
/// Returns 0 when the first argument is fine.
int refuseUnknownSubcommand(const CLI::App& app, int argc, char** argv)
{
    if (argc <= 1 || argv[1][0] == '-') return 0;
    const std::string word = argv[1];
    for (const CLI::App* sub : app.get_subcommands([](const CLI::App*) { return true; }))
        if (sub->check_name(word)) return 0;
    std::cerr << "vdbclay: error: unknown subcommand \"" << printable(word)
              << "\" (expected one of: run, info, mesh, render, import, demo; see vdbclay --help)\n";
    return 2;
}

/// Runs the subcommand the command line chose; an error it throws ends in one line on stderr.
int dispatch(const std::vector<Subcommand>& subcommands)
{
    try {
        openvdb::initialize();
        for (const Subcommand& sub : subcommands)
            if (*sub.app) return sub.run();
    } catch (const std::bad_alloc&) {
        std::cerr
            << "vdbclay: error: out of memory (the memory estimate fell short; lower --memory-budget or "
               "shrink the input)\n";
        return 1;
    } catch (const std::exception& e) {
        std::cerr << "vdbclay: error: " << printable(e.what()) << "\n";
        return 1;
    }
    return 0;
}

} // namespace

int main(int argc, char** argv)
{
    try {
        gHeap = vdbclay::configureBatchHeap(); // before the first large allocation
    } catch (const vdbclay::Error& e) {
        std::cerr << "vdbclay: error: " << printable(e.what()) << "\n";
        return 2;
    }
    CLI::App app{"vdbclay: virtual clay in sparse OpenVDB volumes (Druon, Crosnier, Brigandat 2003)"};
    app.require_subcommand(1);
    app.set_version_flag("--version", std::string("vdbclay ") + VDBCLAY_VERSION);
    // In this order in --help.
    const std::vector<Subcommand> subcommands{addRunCommand(app),    addInfoCommand(app),
                                              addMeshCommand(app),   addRenderCommand(app),
                                              addImportCommand(app), addDemoCommand(app)};
    if (const int rc = refuseUnknownSubcommand(app, argc, argv)) return rc;
    try {
        app.parse(argc, argv);
    } catch (const CLI::ParseError& e) {
        if (e.get_exit_code() == 0) return app.exit(e); // --help
        std::cerr << "vdbclay: error: " << printable(e.what()) << " (see vdbclay --help)\n";
        return e.get_exit_code();
    }
    catchSignals();
    return dispatch(subcommands);
}
