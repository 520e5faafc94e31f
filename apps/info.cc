// vdbclay info: what a .vdb file holds (grids, voxels, bounds, total mass, metadata).
#include "cli.h"

#include "vdbclay/IO.h"

#include <iostream>
#include <memory>
#include <string>

namespace vdbclay_cli {

Subcommand addInfoCommand(CLI::App& app)
{
    auto path = std::make_shared<std::string>();
    CLI::App* inf =
        app.add_subcommand("info", "Describe a .vdb file: grids, voxels, bounds, total mass, metadata");
    inf->add_option("file", *path, "a .vdb file")->required()->check(fileName());
    return {inf, [path] {
                std::cout << vdbclay::describeVdb(*path);
                return 0;
            }};
}

} // namespace vdbclay_cli
