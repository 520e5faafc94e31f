// Running a scene frame by frame: move the tools, push clay out of them, settle.
#include "vdbclay/Sculpt.h"

#include "vdbclay/IO.h"
#include "vdbclay/Metrics.h"

#include "Format.h"

#include <openvdb/openvdb.h>

#include <algorithm>
#include <chrono>
#include <climits>
#include <sstream>

namespace vdbclay {

namespace {

/// Adds every voxel of @a src into @a dst, refusing sums that overflow a cell.
void addClay(openvdb::Int32Grid& dst, const openvdb::Int32Grid& src, const std::string& field)
{
    auto acc = dst.getAccessor();
    for (auto it = src.tree().cbeginValueOn(); it; ++it) {
        if (!it.isVoxelValue()) {
            throw Error(field + ": clay tiles are not supported; voxelize the grid");
        }
        const int64_t sum = int64_t(acc.getValue(it.getCoord())) + int64_t(*it);
        if (sum > INT32_MAX) {
            throw Error(field + ": overlapping clay at voxel " + coordStr(it.getCoord()) + " adds up to " +
                        std::to_string(sum) + ", more than a voxel holds (" + std::to_string(INT32_MAX) + ")");
        }
        acc.setValue(it.getCoord(), int32_t(sum));
    }
}

/// Every voxel whose centre lies inside @a shape (only z = 0 in 2D) becomes an obstacle.
void rasterize(openvdb::MaskGrid& mask, const Shape& shape, int dims)
{
    const Box b = shape.bounds();
    if (b.empty()) return;
    auto acc = mask.getAccessor();
    const int z0 = dims == 2 ? 0 : b.min[2], z1 = dims == 2 ? 0 : b.max[2];
    if (dims == 2 && (b.min[2] > 0 || b.max[2] < 0)) return;
    for (int x = b.min[0]; x <= b.max[0]; ++x)
        for (int y = b.min[1]; y <= b.max[1]; ++y)
            for (int z = z0; z <= z1; ++z)
                if (shape.distance(Vec3{{double(x), double(y), double(z)}}) < 0) {
                    acc.setValueOn(openvdb::Coord(x, y, z));
                }
}

} // namespace

struct Sculptor::Impl {
    Scene scene;
    MassGridPtr mass;
    openvdb::MaskGrid::Ptr obstacles; ///< static obstacles only
    std::unique_ptr<Automaton> automaton;
    uint64_t frame = 0;
    std::vector<openvdb::Coord> toolCells; ///< cells that are obstacles because a tool is there
    Box toolRegion;                        ///< bounds of the tools as placed now

    std::vector<ShapePtr> toolsAt(uint64_t f) const
    {
        std::vector<ShapePtr> tools;
        for (const ToolSpec& t : scene.tools) tools.push_back(makeTransformed(t.shape.shape, t.poseAt(f)));
        return tools;
    }

    /// While clay settles, the voxels a tool occupies are obstacles: otherwise clay would flow back
    /// into the tool that just pushed it out. Moves those obstacle cells to @a tools' placement.
    void placeTools(const std::vector<ShapePtr>& tools)
    {
        Box region;
        for (const ShapePtr& t : tools) region = unite(region, t->bounds());
        if (scene.dimensions == 2) {
            region.min[2] = std::max(region.min[2], 0);
            region.max[2] = std::min(region.max[2], 0);
        }
        const Box both = unite(region, toolRegion);
        if (both.empty()) return;
        automaton->editObstacles(both, [&](ObstacleGrid& grid) {
            auto acc = grid.getAccessor();
            auto fixed = obstacles->getConstAccessor();
            for (const openvdb::Coord& c : toolCells) {
                if (!fixed.isValueOn(c)) acc.setValueOff(c);
            }
            toolCells.clear();
            for (const ShapePtr& t : tools) {
                const Box b = t->bounds();
                const int z0 = scene.dimensions == 2 ? 0 : b.min[2], z1 = scene.dimensions == 2 ? 0 : b.max[2];
                if (b.empty() || (scene.dimensions == 2 && (b.min[2] > 0 || b.max[2] < 0))) continue;
                for (int x = b.min[0]; x <= b.max[0]; ++x)
                    for (int y = b.min[1]; y <= b.max[1]; ++y)
                        for (int z = z0; z <= z1; ++z) {
                            const openvdb::Coord c(x, y, z);
                            if (acc.isValueOn(c)) continue;
                            if (t->distance(Vec3{{double(x), double(y), double(z)}}) < 0) {
                                acc.setValueOn(c);
                                toolCells.push_back(c);
                            }
                        }
            }
            grid.tree().prune();
        });
        toolRegion = region;
    }
};

Sculptor::Sculptor(const Scene& scene, int threads) : mImpl(std::make_unique<Impl>())
{
    openvdb::initialize();
    Impl& im = *mImpl;
    im.scene = scene;
    AutomatonOptions opt;
    opt.dimensions = scene.dimensions;
    opt.rule = scene.rule;
    opt.seed = scene.seed;
    opt.threads = threads;

    uint64_t steps = 0;
    if (!scene.start.empty()) {
        ClayFile f = readClayFile(scene.start);
        if (f.hasMeta && f.meta.dimensions != scene.dimensions) {
            throw Error(scene.source + ": start: " + scene.start + " holds " + std::to_string(f.meta.dimensions) +
                        "D clay but the scene is " + std::to_string(scene.dimensions) + "D");
        }
        im.mass = f.mass;
        steps = f.meta.steps;
        im.frame = f.meta.frames;
    } else {
        im.mass = openvdb::Int32Grid::create(0);
        for (const ClaySpec& c : scene.clay) {
            const std::string field = scene.source + ": " + c.shape.field;
            if (c.shape.kind == "vdb") {
                ClayFile f = readClayFile(c.shape.file, c.shape.grid);
                addClay(*im.mass, *f.mass, field);
            } else {
                MassGridPtr g;
                try {
                    g = makeClay(*c.shape.shape, c.mass, scene.dimensions);
                } catch (const Error& e) {
                    throw Error(field + ": " + e.what());
                }
                addClay(*im.mass, *g, field);
            }
        }
    }
    im.mass->setName("mass");
    im.mass->setTransform(openvdb::math::Transform::createLinearTransform(scene.voxelSize));

    im.obstacles = openvdb::MaskGrid::create(false);
    im.obstacles->setName("obstacles");
    for (const ShapeSpec& o : scene.obstacles) rasterize(*im.obstacles, *o.shape, scene.dimensions);
    if (!scene.obstacles.empty()) {
        auto oacc = im.obstacles->getConstAccessor();
        for (auto it = im.mass->tree().cbeginValueOn(); it; ++it) {
            if (*it != 0 && oacc.isValueOn(it.getCoord())) {
                std::string which;
                const openvdb::Coord c = it.getCoord();
                for (const ShapeSpec& o : scene.obstacles) {
                    if (o.shape->distance(Vec3{{double(c.x()), double(c.y()), double(c.z())}}) < 0) {
                        which = o.field;
                        break;
                    }
                }
                throw Error(scene.source + ": clay at voxel " + coordStr(c) + " lies inside " + which +
                            "; obstacles are cells clay never enters");
            }
        }
    }
    // The automaton's obstacles: the static ones, plus the tools' voxels (placeTools).
    im.automaton = std::make_unique<Automaton>(im.mass, opt, im.obstacles->deepCopy());
    if (steps) im.automaton->setStepCount(steps);
    if (!scene.tools.empty()) im.placeTools(im.toolsAt(im.frame));
}

Sculptor::~Sculptor() = default;

bool Sculptor::done() const { return mImpl->frame >= mImpl->scene.frames; }
uint64_t Sculptor::frame() const { return mImpl->frame; }
uint64_t Sculptor::totalFrames() const { return mImpl->scene.frames; }
const Scene& Sculptor::scene() const { return mImpl->scene; }
Automaton& Sculptor::automaton() { return *mImpl->automaton; }
const MassGridPtr& Sculptor::mass() const { return mImpl->mass; }

FrameReport Sculptor::runFrame()
{
    Impl& im = *mImpl;
    if (done()) throw Error("the scene has no frame left to run (" + std::to_string(im.scene.frames) + " run)");
    FrameReport rep;
    rep.frame = ++im.frame;
    if (!im.scene.tools.empty()) {
        const std::vector<ShapePtr> tools = im.toolsAt(im.frame);
        im.placeTools(tools);
        rep.push = push(*im.automaton, tools);
    }
    rep.settle = im.automaton->settle(im.scene.settle.maxSteps, im.scene.settle.tolerance);
    return rep;
}

RunSummary Sculptor::run(uint64_t maxFrames, const std::function<void(const FrameReport&)>& onFrame)
{
    using Clock = std::chrono::steady_clock;
    RunSummary s;
    s.massInitial = mImpl->automaton->totalMass();
    const auto t0 = Clock::now();
    while (!done() && (maxFrames == 0 || s.frames < maxFrames)) {
        const auto tf = Clock::now();
        const FrameReport r = runFrame();
        const double frameSecs = std::chrono::duration<double>(Clock::now() - tf).count();
        s.pushSeconds += frameSecs - r.settle.seconds.total();
        ++s.frames;
        s.steps += r.settle.steps;
        s.blocksVisited += r.settle.blocksVisited;
        s.blocksUpdated += r.settle.blocksUpdated;
        s.massTrapped = r.push.massTrapped; // clay inside tools now (it is retried every frame)
        if (r.settle.reason == StopReason::StepBudget || r.settle.reason == StopReason::NoRoom) ++s.framesUnsettled;
        if (r.settle.reason == StopReason::NoRoom) ++s.framesNoRoom;
        s.stages.gather += r.settle.seconds.gather;
        s.stages.repartition += r.settle.seconds.repartition;
        s.stages.grow += r.settle.seconds.grow;
        s.stages.bookkeeping += r.settle.seconds.bookkeeping;
        if (onFrame) onFrame(r);
    }
    s.seconds = std::chrono::duration<double>(Clock::now() - t0).count();
    s.massFinal = totalMass(*mImpl->mass);
    s.massDrift = s.massFinal - s.massInitial;
    s.metrics = measureClay(*mImpl->mass, mImpl->scene.rule.threshold, mImpl->automaton->obstacles().get(),
                            mImpl->scene.dimensions);
    s.residualOverload = mImpl->automaton->residualOverload();
    s.settled = mImpl->automaton->settled();
    return s;
}

} // namespace vdbclay
