// Tools that add and take away clay (Deposit.h). Both visit the voxels a tool covers, each with the
// fraction of it the tool covers (forEachVoxelCovered, Voxels.h: the coverage makeClay gives shapes
// that keep their volume), in coordinate order, compute every changed voxel's new mass read-only,
// then write them through Automaton::setMasses over the changed voxels' bounds: the automaton's
// totals follow each cell's old and new mass, and the blocks around them wake. Nothing is written
// when nothing changes (the automaton's quiet-step count is kept).
#include "vdbclay/Deposit.h"
#include "vdbclay/Automaton.h"

#include "shapes/Voxels.h"

#include <openvdb/openvdb.h>

#include <algorithm>
#include <cmath>
#include <memory>

namespace vdbclay {

const char* toolActionName(ToolAction action)
{
    switch (action) {
    case ToolAction::Add: return "add";
    case ToolAction::Remove: return "remove";
    case ToolAction::Smooth: return "smooth";
    case ToolAction::Push: break;
    }
    return "push";
}

ToolAction parseToolAction(const std::string& name)
{
    if (name == "push") return ToolAction::Push;
    if (name == "add") return ToolAction::Add;
    if (name == "remove") return ToolAction::Remove;
    if (name == "smooth") return ToolAction::Smooth;
    throw Error("unknown action \"" + name + "\" (expected one of: push, add, remove, smooth)");
}

bool toolIsSolid(ToolAction action)
{
    return action == ToolAction::Push || action == ToolAction::Remove;
}

namespace {

using openvdb::Coord;

struct Covered {
    Coord c;
    double fraction;
};

std::vector<Covered> coveredVoxels(const Shape& tool, int dimensions)
{
    std::vector<Covered> out;
    shapes_internal::forEachVoxelCovered(tool, dimensions, [&](int32_t x, int32_t y, int32_t z, double f) {
        out.push_back(Covered{Coord(x, y, z), f});
    });
    return out;
}

/// Writes @a cells (each listed once) through setMasses over their bounds.
DepositReport write(Automaton& automaton, const std::vector<Automaton::CellMass>& cells, int64_t mass)
{
    DepositReport r;
    if (cells.empty()) return r;
    for (const Automaton::CellMass& c : cells)
        r.region = unite(r.region, Box{c.at, c.at});
    automaton.setMasses(r.region, cells);
    r.mass = mass;
    r.voxels = cells.size();
    return r;
}

} // namespace

DepositReport deposit(Automaton& automaton, const Shape& tool, int32_t massPerVoxel,
                      const std::vector<ShapePtr>& solids)
{
    if (massPerVoxel <= 0)
        throw Error("deposit: the mass per voxel must be > 0, not " + std::to_string(massPerVoxel));
    const std::vector<Covered> covered = coveredVoxels(tool, automaton.options().dimensions);
    std::vector<Automaton::CellMass> cells;
    int64_t added = 0;
    {
        auto acc = automaton.mass()->getConstAccessor();
        std::unique_ptr<openvdb::tree::ValueAccessor<const ObstacleGrid::TreeType>> oacc;
        if (const ObstacleGridPtr& obs = automaton.obstacles())
            oacc = std::make_unique<openvdb::tree::ValueAccessor<const ObstacleGrid::TreeType>>(
                obs->constTree());
        for (const Covered& v : covered) {
            const int64_t want =
                std::min<int64_t>(std::llround(double(massPerVoxel) * v.fraction), massPerVoxel);
            if (want <= 0) continue;
            const int32_t old = acc.getValue(v.c);
            if (old >= want) continue;
            if (oacc && oacc->isValueOn(v.c)) continue;
            const Vec3 p{{double(v.c.x()), double(v.c.y()), double(v.c.z())}};
            bool solid = false;
            for (const ShapePtr& s : solids) {
                const Box b = s->bounds();
                if (v.c.x() < b.min[0] || v.c.x() > b.max[0] || v.c.y() < b.min[1] || v.c.y() > b.max[1] ||
                    v.c.z() < b.min[2] || v.c.z() > b.max[2])
                    continue;
                if (s->distance(p) < 0) {
                    solid = true;
                    break;
                }
            }
            if (solid) continue;
            cells.push_back(Automaton::CellMass{{{v.c.x(), v.c.y(), v.c.z()}}, int32_t(want)});
            added += want - old;
        }
    }
    return write(automaton, cells, added);
}

DepositReport carve(Automaton& automaton, const Shape& tool)
{
    const std::vector<Covered> covered = coveredVoxels(tool, automaton.options().dimensions);
    std::vector<Automaton::CellMass> cells;
    int64_t removed = 0;
    {
        auto acc = automaton.mass()->getConstAccessor();
        for (const Covered& v : covered) {
            const int32_t old = acc.getValue(v.c);
            if (old <= 0) continue;
            const int64_t take =
                v.fraction >= 1 ? old : std::min<int64_t>(std::llround(double(old) * v.fraction), old);
            if (take <= 0) continue;
            cells.push_back(Automaton::CellMass{{{v.c.x(), v.c.y(), v.c.z()}}, int32_t(old - take)});
            removed += take;
        }
    }
    return write(automaton, cells, removed);
}

} // namespace vdbclay
