// Writes the small .vdb seeds of tests/fuzz/corpus/vdb (clay files from the tool are ~150 KB: their
// density and surface grids hold hundreds of nodes). Not part of the build; run by hand:
//   c++ -std=c++17 -O1 tests/fuzz/make_vdb_seeds.cc -o /tmp/make_vdb_seeds -lopenvdb -ltbb -lImath-3_1 \
//     && /tmp/make_vdb_seeds tests/fuzz/corpus/vdb
#include <openvdb/openvdb.h>

#include <string>

namespace {

void addClayMeta(openvdb::GridBase& g, int dims)
{
    g.insertMeta("vdbclay_threshold", openvdb::Int32Metadata(100));
    g.insertMeta("vdbclay_rule", openvdb::StringMetadata("prorata"));
    g.insertMeta("vdbclay_alpha", openvdb::DoubleMetadata(0.5));
    g.insertMeta("vdbclay_seed", openvdb::Int64Metadata(7));
    g.insertMeta("vdbclay_steps", openvdb::Int64Metadata(3));
    g.insertMeta("vdbclay_frames", openvdb::Int64Metadata(1));
    g.insertMeta("vdbclay_dimensions", openvdb::Int32Metadata(dims));
    g.insertMeta("vdbclay_voxel_size", openvdb::DoubleMetadata(1.0));
    g.insertMeta("vdbclay_version", openvdb::StringMetadata("0.1.0"));
}

void write(const std::string& path, const openvdb::GridPtrVec& grids, uint32_t compression)
{
    openvdb::io::File f(path);
    f.setCompression(compression);
    f.write(grids);
    f.close();
}

} // namespace

int main(int argc, char** argv)
{
    openvdb::initialize();
    const std::string dir = argc > 1 ? argv[1] : ".";
    const uint32_t blosc = openvdb::io::COMPRESS_BLOSC | openvdb::io::COMPRESS_ACTIVE_MASK;
    const uint32_t zip = openvdb::io::COMPRESS_ZIP | openvdb::io::COMPRESS_ACTIVE_MASK;

    write(dir + "/no-grids.vdb", {}, blosc);

    auto empty = openvdb::Int32Grid::create(0);
    empty->setName("mass");
    addClayMeta(*empty, 3);
    write(dir + "/mass-empty.vdb", {empty}, blosc);

    // A few voxels of clay in one leaf, as the tool writes them (blosc), and zip-compressed.
    auto mass = openvdb::Int32Grid::create(0);
    mass->setName("mass");
    addClayMeta(*mass, 2);
    for (int x = 0; x < 3; ++x) {
        for (int y = 0; y < 2; ++y)
            mass->tree().setValueOn(openvdb::Coord(x, y, 0), 40 + 10 * x + y);
    }
    write(dir + "/mass-leaf-blosc.vdb", {mass}, blosc);
    write(dir + "/mass-leaf-zip.vdb", {mass}, zip);

    // Clay beside a float grid (describeVdb reports both).
    auto fog = openvdb::FloatGrid::create(0.f);
    fog->setName("density");
    fog->setGridClass(openvdb::GRID_FOG_VOLUME);
    fog->tree().setValueOn(openvdb::Coord(1, 1, 1), 0.5f);
    auto one = openvdb::Int32Grid::create(0);
    one->setName("mass");
    one->tree().setValueOn(openvdb::Coord(1, 1, 1), 50);
    write(dir + "/mass-and-fog.vdb", {one, fog}, zip);
    return 0;
}
