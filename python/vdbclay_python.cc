// The Python module `vdbclay` (pybind11): scenes, the automaton, shapes, clay files, numpy arrays.
//
// One translation unit over the C++ library. Clay crosses the boundary as a `Clay` object: the
// Int32 mass grid (shared, not copied) and the metadata a clay file records (Tc, dimensions, voxel
// size, ...). numpy arrays are dense boxes indexed [x, y, z]; the sparse grid never becomes dense
// unless asked for a box. Long calls (steps, settling, frames, make_clay) release the GIL and poll
// Ctrl-C after every step (KeyboardInterrupt, the state exact); progress callbacks run between frames
// with the GIL held. Calls on one grid from several threads run one after the other (GridLock).
// Errors from the library arrive as vdbclay.Error (a RuntimeError) with the library's message.
// Sculptor.run returns the run's report: the dict of the CLI's --stats file, parsed from the same
// JSON text (vdbclay/RunReport.h), so the two never differ in a key.
#include <vdbclay/Automaton.h>
#include <vdbclay/Deposit.h>
#include <vdbclay/IO.h>
#include <vdbclay/MakeClay.h>
#include <vdbclay/MemoryBudget.h>
#include <vdbclay/MemoryEstimate.h>
#include <vdbclay/Metrics.h>
#include <vdbclay/Push.h>
#include <vdbclay/Render.h>
#include <vdbclay/RunReport.h>
#include <vdbclay/Scene.h>
#include <vdbclay/Sculpt.h>
#include <vdbclay/Shapes.h>
#include <vdbclay/Smooth.h>
#include <vdbclay/SurfaceMesh.h>

#include <openvdb/openvdb.h>

#include <pybind11/functional.h>
#include <pybind11/numpy.h>
#include <pybind11/pybind11.h>
#include <pybind11/stl.h>

#include <atomic>
#include <chrono>
#include <climits>
#include <cmath>
#include <condition_variable>
#include <memory>
#include <mutex>
#include <optional>
#include <string>
#include <thread>
#include <vector>

namespace py = pybind11;
using namespace vdbclay;

namespace {

// ---- threads and Ctrl-C ---------------------------------------------------------------------------
//
// Every Python object that reaches a mass grid (Clay, Automaton, Sculptor) carries that grid's
// GridLock, shared by every object on the same grid (an Automaton's clay, a Sculptor's clay, an
// Automaton built on either). Each call that reads or changes the grid holds the lock for its whole
// length (GridGuard): calls on one grid from several threads run one after the other, the later ones
// waiting with the GIL released (and Ctrl-C honoured while they wait). A call made on the thread
// that already holds the lock (from a progress callback or a signal handler, which run between steps
// or frames) may read the grid; one that would change it raises vdbclay.Error.

/// The lock of one mass grid.
struct GridLock {
    std::mutex m; ///< guards the fields below; held only for a few instructions, never with a wait
    std::condition_variable freed;
    std::thread::id owner; ///< the thread whose call holds the grid (none: free)
    unsigned depth = 0;    ///< that thread's nested calls (progress callbacks, signal handlers)
    /// Calls that changed the grid. An Automaton or Sculptor remembers the count after its own last
    /// change; when another object changed the grid since, it rescans the grid first (resync), so
    /// that several automata on one grid stay exact.
    uint64_t changes = 0;
};
using GridLockPtr = std::shared_ptr<GridLock>;

/// Throws the pending Python error (KeyboardInterrupt from Ctrl-C) if a signal handler raised one.
/// Call with the GIL held; only the main thread sees signals.
void checkSignals()
{
    if (PyErr_CheckSignals() != 0) throw py::error_already_set();
}

/// Holds a grid for one call. Construct with the GIL held. @a change: the call changes the grid.
class GridGuard {
public:
    GridGuard(const GridLockPtr& lock, bool change) : mLock(lock)
    {
        GridLock& l = *mLock;
        const std::thread::id self = std::this_thread::get_id();
        std::unique_lock<std::mutex> lk(l.m);
        if (l.depth > 0 && l.owner == self) {
            if (change) {
                throw Error("this call would change clay that a call running on this thread holds (it was "
                            "made from that call's progress callback or a signal handler); make it after "
                            "that call returns");
            }
            ++l.depth;
            return;
        }
        while (l.depth > 0) {
            lk.unlock();
            {
                py::gil_scoped_release nogil;
                std::unique_lock<std::mutex> wait(l.m);
                // The timeout only lets Ctrl-C reach a call that waits for another.
                l.freed.wait_for(wait, std::chrono::milliseconds(50), [&l] { return l.depth == 0; });
            }
            checkSignals();
            lk.lock();
        }
        l.owner = self;
        l.depth = 1;
    }
    ~GridGuard()
    {
        GridLock& l = *mLock;
        std::lock_guard<std::mutex> lk(l.m);
        if (--l.depth == 0) {
            l.owner = std::thread::id();
            l.freed.notify_all();
        }
    }
    GridGuard(const GridGuard&) = delete;
    GridGuard& operator=(const GridGuard&) = delete;

private:
    GridLockPtr mLock;
};

/// The stop poll of a long call that runs with the GIL released: at most every 50 ms it takes the
/// GIL and runs Python's signal handlers (PyErr_CheckSignals). When one raised (Ctrl-C:
/// KeyboardInterrupt), the error is kept and the poll answers true from then on, so the library
/// stops at its next exact point; rethrow() then raises it, with the GIL held again.
class InterruptPoll {
public:
    /// Called by the library on the thread that made the call (the GIL released).
    bool operator()()
    {
        if (mError) return true;
        const auto now = std::chrono::steady_clock::now();
        if (now < mNext) return false;
        mNext = now + std::chrono::milliseconds(50);
        py::gil_scoped_acquire gil;
        if (PyErr_CheckSignals() == 0) return false;
        mError = std::make_unique<py::error_already_set>();
        return true;
    }
    bool interrupted() const { return mError != nullptr; }
    /// Raises the kept error, if any (GIL held).
    void rethrow()
    {
        if (!mError) return;
        py::error_already_set e = std::move(*mError);
        mError.reset();
        throw e;
    }

private:
    std::chrono::steady_clock::time_point mNext{};
    std::unique_ptr<py::error_already_set> mError;
};

/// Clay as Python sees it: the exact mass grid, its lock, and what a clay file records beside it.
struct Clay {
    MassGridPtr mass;
    ClayMeta meta;
    GridLockPtr lock = std::make_shared<GridLock>();
};

using Int3 = std::array<int32_t, 3>;

Box boxOf(const Int3& lo, const Int3& hi)
{
    Box b;
    b.min = lo;
    b.max = hi;
    return b;
}

/// The grids @a names names (none: @a byDefault). @throw Error (clayGridsOf's) naming the argument.
ClayGrids gridsOf(const std::optional<std::vector<std::string>>& names, const ClayGrids& byDefault)
{
    if (!names) return byDefault;
    try {
        return clayGridsOf(*names);
    } catch (const Error& e) {
        throw Error(std::string("grids: ") + e.what());
    }
}

/// The active voxels' bounding box, or the box the caller gave.
Box regionOf(const Clay& c, const std::optional<Int3>& lo, const std::optional<Int3>& hi)
{
    if (lo.has_value() != hi.has_value()) throw Error("give both min and max, or neither");
    if (lo) {
        const Box b = boxOf(*lo, *hi);
        if (b.empty()) throw Error("min must not exceed max");
        return b;
    }
    const openvdb::CoordBBox bb = c.mass->evalActiveVoxelBoundingBox();
    if (bb.empty()) return Box();
    return boxOf({bb.min().x(), bb.min().y(), bb.min().z()}, {bb.max().x(), bb.max().y(), bb.max().z()});
}

std::array<py::ssize_t, 3> shapeOf(const Box& b)
{
    if (b.empty()) return {0, 0, 0};
    std::array<py::ssize_t, 3> s;
    for (int a = 0; a < 3; ++a)
        s[a] = py::ssize_t(int64_t(b.max[a]) - b.min[a] + 1);
    if (s[0] * s[1] * s[2] > (py::ssize_t(1) << 32)) {
        throw Error("the box holds more than 2^32 voxels; ask for a smaller box (min, max)");
    }
    return s;
}

template <typename T, typename F> py::array_t<T> dense(const Clay& c, const Box& b, F value)
{
    const auto s = shapeOf(b);
    py::array_t<T> out({s[0], s[1], s[2]});
    auto r = out.template mutable_unchecked<3>();
    auto acc = c.mass->getConstAccessor();
    for (py::ssize_t x = 0; x < s[0]; ++x)
        for (py::ssize_t y = 0; y < s[1]; ++y)
            for (py::ssize_t z = 0; z < s[2]; ++z)
                r(x, y, z) = value(acc.getValue(
                    openvdb::Coord(b.min[0] + int32_t(x), b.min[1] + int32_t(y), b.min[2] + int32_t(z))));
    return out;
}

using IntArray = py::array_t<int64_t, py::array::c_style | py::array::forcecast>;

/// @a obj (a numpy array or nested lists) as int64 masses: integer and boolean dtypes as they are;
/// a float array only when every value is a whole number (a cast would truncate 999.9 to 999
/// silently); any other dtype refused. @a what names the argument in the error.
IntArray integerArray(const py::object& obj, const std::string& what)
{
    py::array a = py::array::ensure(obj);
    if (!a) throw Error(what + ": expected a numpy array (or nested lists) of integers");
    const char kind = a.dtype().kind();
    if (kind == 'f') {
        const auto f = py::array_t<double, py::array::c_style | py::array::forcecast>::ensure(a);
        const double* p = f.data();
        for (py::ssize_t i = 0; i < f.size(); ++i) {
            if (std::isfinite(p[i]) && p[i] == std::floor(p[i]) && std::abs(p[i]) < 9e18) continue;
            std::string at;
            py::ssize_t rest = i;
            for (py::ssize_t d = f.ndim() - 1; d >= 0; --d) {
                at = std::to_string(rest % f.shape(d)) + (at.empty() ? "" : ", ") + at;
                rest /= f.shape(d);
            }
            const std::string v = py::repr(py::float_(p[i]));
            throw Error(what + (at.empty() ? "" : "[" + at + "]") + " is " + v +
                        ", not a whole number: masses are integers (round the array first, e.g. "
                        "numpy.rint(a).astype(numpy.int64))");
        }
    } else if (kind != 'i' && kind != 'u' && kind != 'b') {
        throw Error(what + ": expected an integer array, got dtype " + std::string(py::str(a.dtype())));
    }
    return IntArray::ensure(a);
}

/// Writes @a a (int, any integer dtype that fits int32) into @a grid at @a origin: replacing the
/// box's values, or adding to them; refuses negative results and int32 overflow before writing.
Box writeArray(MassGrid& grid, const py::array_t<int64_t, py::array::c_style | py::array::forcecast>& a,
               const Int3& origin, bool add)
{
    if (a.ndim() != 3)
        throw Error("expected a 3D array indexed [x, y, z], got " + std::to_string(a.ndim()) + "D");
    auto r = a.unchecked<3>();
    Box b;
    for (int i = 0; i < 3; ++i) {
        b.min[i] = origin[i];
        const int64_t hi = int64_t(origin[i]) + int64_t(a.shape(i)) - 1;
        if (hi > INT32_MAX) throw Error("the array reaches past the coordinate range");
        b.max[i] = int32_t(hi);
    }
    auto acc = grid.getAccessor();
    auto check = [&](bool apply) {
        for (py::ssize_t x = 0; x < a.shape(0); ++x)
            for (py::ssize_t y = 0; y < a.shape(1); ++y)
                for (py::ssize_t z = 0; z < a.shape(2); ++z) {
                    const openvdb::Coord c(origin[0] + int32_t(x), origin[1] + int32_t(y),
                                           origin[2] + int32_t(z));
                    const int64_t v = r(x, y, z) + (add ? int64_t(acc.getValue(c)) : 0);
                    if (!apply) {
                        if (v < 0 || v > INT32_MAX) {
                            throw Error("voxel (" + std::to_string(c.x()) + ", " + std::to_string(c.y()) +
                                        ", " + std::to_string(c.z()) + ") would hold " + std::to_string(v) +
                                        ", outside [0, 2^31 - 1]");
                        }
                    } else if (v != 0) {
                        acc.setValueOn(c, int32_t(v));
                    } else if (acc.isValueOn(c)) {
                        acc.setValueOff(c, 0);
                    }
                }
    };
    check(false);
    check(true);
    return b;
}

py::dict stepDict(const StepReport& r)
{
    py::dict d;
    d["steps"] = r.steps;
    d["blocks_visited"] = r.blocksVisited;
    d["blocks_updated"] = r.blocksUpdated;
    d["leaves_created"] = r.leavesCreated;
    d["residual_overload"] = r.residualOverload;
    d["settled"] = r.settled;
    d["reason"] = stopReasonName(r.reason);
    d["seconds"] = r.seconds.total();
    // How well the passes used their threads (StageSeconds): thread-seconds run and sat idle.
    d["pass_busy_seconds"] = r.seconds.passBusy;
    d["pass_idle_seconds"] = r.seconds.passIdle;
    return d;
}

py::dict pushDict(const PushReport& r)
{
    py::dict d;
    d["voxels_pushed"] = r.voxelsPushed;
    d["mass_moved"] = r.massMoved;
    d["voxels_trapped"] = r.voxelsTrapped;
    d["mass_trapped"] = r.massTrapped;
    return d;
}

py::dict frameDict(const FrameReport& r)
{
    py::dict d;
    d["frame"] = r.frame;
    d["push"] = pushDict(r.push);
    d["mass_added"] = r.massAdded;
    d["mass_removed"] = r.massRemoved;
    d["mass_smoothed"] = r.massSmoothed;
    d["tension_boxes"] = r.tensionBoxes;
    d["tension_voxels"] = r.tensionVoxels;
    d["tension_seconds"] = r.tensionSeconds;
    d["settle"] = stepDict(r.settle);
    d["finished"] = r.finished;
    return d;
}

Vec3 vec(const std::array<double, 3>& v)
{
    return Vec3{{v[0], v[1], v[2]}};
}

/// A shape for Python (pybind11 holders cannot be shared_ptr<const T>), with its kind as a scene
/// names it (sphere, box, cylinder, capsule, mesh, levelset; kept when moved or placed, as a
/// scene's "transform" keeps it), which the memory estimate reads.
struct PyShape {
    ShapePtr shape;
    std::string kind;
};

/// An Automaton that keeps its Clay's metadata (and the grid's lock) beside it.
struct PyAutomaton {
    std::unique_ptr<Automaton> automaton;
    Clay clay;
    uint64_t changesSeen = 0; ///< GridLock::changes after this automaton's last change
};

/// A Sculptor, with its grid's lock and what its run report tells beside the run's totals.
struct PySculptor {
    std::unique_ptr<Sculptor> sculptor;
    GridLockPtr lock = std::make_shared<GridLock>();
    uint64_t changesSeen = 0; ///< GridLock::changes after this sculptor's last change
    int threads = 0;
    double setupSeconds = 0; ///< the constructor's
};

/// Holds the grid for a call on an Automaton (@a automaton: an Automaton's, or a Sculptor's) that
/// reads it (@a change false) or changes it: first rescans the grid when another object changed it
/// since @a seen, so that the automaton's own state (its total, its overload, which blocks can change)
/// is the grid's; a change is counted.
class AutomatonGuard {
public:
    AutomatonGuard(const GridLockPtr& lock, uint64_t& seen, Automaton& automaton, bool change)
        : mGuard(lock, change), mLock(*lock), mSeen(seen), mChange(change)
    {
        if (mLock.changes != mSeen) {
            automaton.resync();
            mSeen = mLock.changes;
        }
    }
    ~AutomatonGuard()
    {
        if (mChange) mSeen = ++mLock.changes;
    }
    AutomatonGuard(const AutomatonGuard&) = delete;
    AutomatonGuard& operator=(const AutomatonGuard&) = delete;

private:
    GridGuard mGuard;
    GridLock& mLock;
    uint64_t& mSeen;
    bool mChange;
};

AutomatonGuard changing(PyAutomaton& a)
{
    return AutomatonGuard(a.clay.lock, a.changesSeen, *a.automaton, true);
}
AutomatonGuard reading(const PyAutomaton& a)
{
    auto& m = const_cast<PyAutomaton&>(a); // the automaton's state follows the grid
    return AutomatonGuard(m.clay.lock, m.changesSeen, *m.automaton, false);
}
AutomatonGuard changing(PySculptor& p)
{
    return AutomatonGuard(p.lock, p.changesSeen, p.sculptor->automaton(), true);
}
AutomatonGuard reading(const PySculptor& p)
{
    auto& m = const_cast<PySculptor&>(p);
    return AutomatonGuard(m.lock, m.changesSeen, m.sculptor->automaton(), false);
}

/// A memory budget as Python gives it: None (0: the scene's, else the default), a number of bytes,
/// or a size as scenes write it ("8G", "512M", "none": parseByteSize).
uint64_t budgetArg(const py::object& budget)
{
    if (budget.is_none()) return 0;
    if (py::isinstance<py::str>(budget)) return parseByteSize(budget.cast<std::string>());
    if (!py::isinstance<py::int_>(budget) || budget.cast<py::int_>() <= py::int_(0))
        throw Error("memory_budget: expected a positive number of bytes, a size such as \"8G\", or \"none\"");
    return budget.cast<uint64_t>();
}

/// set_memory_budget(): the budget of every call not given memory_budget (0: none set).
std::atomic<uint64_t> gModuleBudget{0};

/// The budget of a call given @a budget: @a budget, else the module's (set_memory_budget), else 0
/// (the scene's, else defaultMemoryBudget()).
uint64_t callBudget(const py::object& budget)
{
    const uint64_t b = budgetArg(budget);
    return b != 0 ? b : gModuleBudget.load(std::memory_order_relaxed);
}

/// Once the memory budget stopped a run: the error a Python caller gets.
void throwIfOutgrewBudget(const Sculptor& s)
{
    const uint64_t needs = s.outgrewBudget();
    if (needs == 0) return;
    throw Error("the clay outgrew the memory budget of " + formatBytes(s.memoryBudget()) +
                " (it needs about " + formatBytes(needs) +
                " now); write() saves the run where it stopped, and a Sculptor with a larger memory_budget "
                "continues it exactly from that file");
}

/// The run report (runReportJson) as a dict: the keys and values of the CLI's --stats file.
py::object reportDict(const RunReport& r)
{
    return py::module_::import("json").attr("loads")(runReportJson(r, -1));
}

/// The Sculptor's stop request for one call: @a poll (Ctrl-C), or @a stop (progress returned False).
struct StopRequest {
    Sculptor& s;
    StopRequest(Sculptor& sculptor, InterruptPoll& poll, const std::atomic<bool>* stop = nullptr)
        : s(sculptor)
    {
        s.setStopRequest([&poll, stop] { return poll() || (stop && stop->load(std::memory_order_relaxed)); });
    }
    ~StopRequest() { s.setStopRequest({}); }
    StopRequest(const StopRequest&) = delete;
    StopRequest& operator=(const StopRequest&) = delete;
};

/// Sculptor.run: Sculptor::run with the GIL released. Ctrl-C is polled after every step (the run
/// stops at the next exact point, then KeyboardInterrupt is raised); after each frame, with the GIL
/// held, progress is called. progress returning False asks the run to stop (a stop request: at the
/// next point a checkpoint resumes exactly, the frame's end almost always).
py::object runSculptor(PySculptor& p, uint64_t frames, const std::function<py::object(py::dict)>& progress)
{
    auto guard = changing(p);
    Sculptor& s = *p.sculptor;
    std::atomic<bool> stop{false};
    InterruptPoll poll;
    StopRequest request(s, poll, &stop);
    const uint64_t total = s.totalFrames();
    RunSummary summary;
    {
        py::gil_scoped_release nogil;
        summary = s.run(frames, [&](const FrameReport& r) {
            if (!progress || poll.interrupted()) return;
            py::gil_scoped_acquire gil;
            py::dict d = frameDict(r);
            d["total_frames"] = total;
            const py::object go = progress(d);
            if (!go.is_none() && !go.cast<bool>()) stop.store(true, std::memory_order_relaxed);
        });
    }
    poll.rethrow();
    throwIfOutgrewBudget(s);
    RunReport report = makeRunReport(s, summary, p.threads);
    report.setupSeconds = p.setupSeconds;
    report.heap = "system (a Python process keeps its own allocator)";
    return reportDict(report);
}

Clay sculptorClay(const PySculptor& p)
{
    Clay c;
    c.mass = p.sculptor->mass();
    c.meta = p.sculptor->checkpointMeta();
    c.lock = p.lock;
    return c;
}

/// Automaton.run and .settle: @a n steps, or settling, with the GIL released and Ctrl-C polled
/// after every step.
py::dict stepAutomaton(PyAutomaton& a, bool settle, uint64_t n, int64_t tolerance)
{
    auto guard = changing(a);
    Automaton& au = *a.automaton;
    InterruptPoll poll;
    StepReport r;
    {
        py::gil_scoped_release nogil;
        if (settle) {
            SettleOptions o;
            o.maxSteps = n;
            o.tolerance = tolerance;
            o.stop = [&poll](const Automaton&) { return poll(); };
            r = au.settle(o);
        } else {
            r.residualOverload = au.residualOverload();
            r.settled = au.settled();
            for (uint64_t i = 0; i < n && !poll(); ++i)
                r += au.step();
        }
    }
    poll.rethrow();
    return stepDict(r);
}

} // namespace

PYBIND11_MODULE(_vdbclay, m)
{
    openvdb::initialize();
    m.doc() = "vdbclay: virtual clay on sparse OpenVDB grids (Druon, Crosnier, Brigandat 2003).\n\n"
              "Clay is an exact integer mass per voxel; a cellular automaton moves the excess of cells "
              "over Tc to cells under it. Coordinates are voxel indices (y up unless a scene says "
              "otherwise); numpy arrays are dense boxes indexed [x, y, z].\n\n"
              "Threads: every object may be used from any thread. Calls on objects that share a grid (a "
              "Clay, the Automaton built on it and that automaton's clay; a Sculptor and its clay) are "
              "serialised: a call waits, with the GIL released, until the call running on that grid "
              "returns, so a thread reading clay.mass_array() while another runs Automaton.run gets the "
              "clay between two calls. Long calls (steps, settling, frames, make_clay, pushes) release "
              "the GIL, so other threads and other grids run meanwhile. From a progress callback or a "
              "signal handler (which run inside a call, between its steps) the clay may be read; a call "
              "that would change it raises vdbclay.Error.\n\n"
              "Ctrl-C: Sculptor.run and run_frame, Automaton.run and settle, make_clay, and a call "
              "waiting for another, stop within a step (checked every 50 ms) and raise "
              "KeyboardInterrupt; the object stays exact (a Sculptor goes on where it stopped, as an "
              "unbroken run would; an Automaton goes on from its last step). Only the main thread sees "
              "Ctrl-C.\n\n"
              "Memory: make_clay, mesh, Scene.load, Scene.from_json and Sculptor take memory_budget "
              "(bytes, \"8G\", \"none\") and refuse work estimated to need more, before building it; "
              "set_memory_budget() gives every call that is not given one a budget, as `vdbclay run "
              "--memory-budget` (it replaces a scene's \"memory_budget\"). Without either: the scene's, "
              "else 3/4 of the machine's memory, as the CLI.";
    py::register_exception<Error>(m, "Error", PyExc_RuntimeError);
    m.attr("Error").attr("__doc__") = "Every error vdbclay reports: bad input, refused states, I/O failures.";
    m.attr("__version__") = VDBCLAY_VERSION;
    m.attr("NO_MEMORY_BUDGET") = kNoMemoryBudget;
    m.def(
        "set_memory_budget",
        [](const py::object& budget) { gModuleBudget.store(budgetArg(budget), std::memory_order_relaxed); },
        py::arg("budget"),
        "The memory budget of every call not given memory_budget: bytes, a size such as \"8G\" or "
        "\"512M\", \"none\" (no check), or None (back to the default: a scene's own \"memory_budget\", "
        "else 3/4 of the machine's memory). Like `vdbclay run --memory-budget`, it replaces a scene's "
        "\"memory_budget\".");
    m.def(
        "memory_budget",
        [] {
            const uint64_t b = gModuleBudget.load(std::memory_order_relaxed);
            return b != 0 ? b : defaultMemoryBudget();
        },
        "The budget set_memory_budget() set, in bytes (NO_MEMORY_BUDGET: none); without one, the default "
        "(3/4 of the machine's memory, or of the cgroup's limit), which a scene's own \"memory_budget\" "
        "replaces.");

    // ---- shapes ----------------------------------------------------------------------------------
    py::class_<PyShape>(m, "Shape",
                        "A signed distance field in voxel index space (negative inside). Made by "
                        "sphere(), box(), cylinder(), capsule(), mesh(), level_set().")
        .def(
            "distance", [](const PyShape& s, std::array<double, 3> p) { return s.shape->distance(vec(p)); },
            py::arg("p"), "Signed distance at index-space point p (voxel units).")
        .def_property_readonly(
            "bounds",
            [](const PyShape& s) {
                const Box b = s.shape->bounds();
                return py::make_tuple(b.min, b.max);
            },
            "(min, max): a voxel box holding every voxel whose centre is inside.")
        .def(
            "moved",
            [](const PyShape& ps, std::array<double, 3> translate, std::array<double, 3> rotate,
               std::optional<std::array<double, 3>> pivot) {
                const ShapePtr& s = ps.shape;
                Pose p;
                p.translation = vec(translate);
                p.rotationDeg = vec(rotate);
                if (pivot) {
                    p.pivot = vec(*pivot);
                } else {
                    const Box b = s->bounds();
                    for (int a = 0; a < 3; ++a)
                        p.pivot[a] = 0.5 * (double(b.min[a]) + double(b.max[a]));
                }
                return PyShape{makeTransformed(s, p), ps.kind};
            },
            py::arg("translate") = std::array<double, 3>{0, 0, 0},
            py::arg("rotate") = std::array<double, 3>{0, 0, 0}, py::arg("pivot") = py::none(),
            "This shape rotated (degrees about x, then y, then z, around pivot; default the centre of its "
            "bounds), then translated (voxels).")
        .def(
            "placed",
            [](const PyShape& s, std::array<double, 3> translate, std::array<double, 3> rotate,
               py::object scale, std::array<double, 3> pivot) {
                Placement pl;
                pl.translate = vec(translate);
                pl.rotateDeg = vec(rotate);
                pl.pivot = vec(pivot);
                if (py::isinstance<py::float_>(scale) || py::isinstance<py::int_>(scale)) {
                    const double k = scale.cast<double>();
                    pl.scale = {{k, k, k}};
                } else {
                    pl.scale = vec(scale.cast<std::array<double, 3>>());
                }
                return PyShape{makePlaced(s.shape, pl), s.kind};
            },
            py::arg("translate") = std::array<double, 3>{0, 0, 0},
            py::arg("rotate") = std::array<double, 3>{0, 0, 0}, py::arg("scale") = 1.0,
            py::arg("pivot") = std::array<double, 3>{0, 0, 0},
            "A scene's \"transform\": scale (number or per axis) about pivot, rotate, translate.")
        .def("__repr__", [](const PyShape& s) { return "<vdbclay.Shape " + s.shape->describe() + ">"; });

    m.def(
        "sphere",
        [](std::array<double, 3> c, double r) {
            return PyShape{makeSphere(vec(c), r), "sphere"};
        },
        py::arg("center"), py::arg("radius"), "A ball of radius (voxels) around center (voxel indices).");
    m.def(
        "box",
        [](std::array<double, 3> lo, std::array<double, 3> hi) {
            return PyShape{makeBox(vec(lo), vec(hi)), "box"};
        },
        py::arg("min"), py::arg("max"), "The voxels min..max, inclusive.");
    m.def(
        "cylinder",
        [](std::array<double, 3> c, double r, double h, int axis) {
            return PyShape{makeCylinder(vec(c), r, h, axis), "cylinder"};
        },
        py::arg("center"), py::arg("radius"), py::arg("height"), py::arg("axis") = 1,
        "A cylinder along axis 0 (x), 1 (y) or 2 (z).");
    m.def(
        "capsule",
        [](std::array<double, 3> a, std::array<double, 3> b, double r) {
            return PyShape{makeCapsule(vec(a), vec(b), r), "capsule"};
        },
        py::arg("a"), py::arg("b"), py::arg("radius"), "All points within radius of the segment a-b.");
    m.def(
        "mesh",
        [](const std::string& path, double vs, const std::string& up, const py::object& budget) {
            const uint64_t b = callBudget(budget);
            py::gil_scoped_release nogil;
            return PyShape{loadMesh(path, vs, parseUpAxis(up), Placement(), b), "mesh"};
        },
        py::arg("path"), py::arg("voxel_size") = 1.0, py::arg("up") = "y",
        py::arg("memory_budget") = py::none(),
        "A triangle mesh (OBJ, STL or PLY) in world units with up axis 'y' or 'z', at voxel_size world "
        "units per voxel. The level set it becomes must fit memory_budget (bytes or a size such as "
        "\"8G\"; None: the module's, set_memory_budget(), else the default, 3/4 of memory; \"none\": no "
        "check), as `vdbclay import --memory-budget`.");
    m.def(
        "level_set",
        [](const std::string& path, double vs, const std::string& grid, const std::string& up) {
            return PyShape{loadLevelSet(path, vs, grid, parseUpAxis(up)), "levelset"};
        },
        py::arg("path"), py::arg("voxel_size") = 1.0, py::arg("grid") = "", py::arg("up") = "y",
        "A FloatGrid level set from a .vdb (grid: its name; empty: the first level set).");

    // ---- clay ------------------------------------------------------------------------------------
    py::class_<Clay>(m, "Clay",
                     "Clay: an exact Int32 mass per voxel and what a clay .vdb records with it (Tc, "
                     "dimensions, voxel size, rule, seed, steps, frames).")
        .def_property_readonly(
            "threshold", [](const Clay& c) { return c.meta.rule.threshold; }, "Tc")
        .def_property_readonly("dimensions", [](const Clay& c) { return c.meta.dimensions; })
        .def_property_readonly("voxel_size", [](const Clay& c) { return c.meta.voxelSize; })
        .def_property(
            "up", [](const Clay& c) { return std::string(upAxisName(c.meta.up)); },
            [](Clay& c, const std::string& up) { c.meta.up = parseUpAxis(up); },
            "'y' or 'z': the up axis written into the file's transform (and meshes).")
        .def_property_readonly("rule", [](const Clay& c) { return std::string(ruleName(c.meta.rule.rule)); })
        .def_property_readonly("seed", [](const Clay& c) { return c.meta.seed; })
        .def_property_readonly("steps", [](const Clay& c) { return c.meta.steps; })
        .def_property_readonly("frames", [](const Clay& c) { return c.meta.frames; })
        .def(
            "total_mass",
            [](const Clay& c) {
                GridGuard g(c.lock, false);
                return totalMass(*c.mass);
            },
            "Sum of all voxels' mass (exact).")
        .def(
            "voxel_count",
            [](const Clay& c) {
                GridGuard g(c.lock, false);
                return clayVoxelCount(*c.mass);
            },
            "Voxels holding clay.")
        .def(
            "content_hash",
            [](const Clay& c) {
                GridGuard g(c.lock, false);
                return contentHash(*c.mass);
            },
            "A hash of every voxel's coordinates and mass: equal hashes, equal clay.")
        .def_property_readonly(
            "bounds",
            [](const Clay& c) {
                GridGuard g(c.lock, false);
                const Box b = regionOf(c, std::nullopt, std::nullopt);
                return py::make_tuple(b.min, b.max);
            },
            "(min, max) of the voxels holding clay (inclusive); min > max when there is none.")
        .def(
            "mass_array",
            [](const Clay& c, std::optional<Int3> lo, std::optional<Int3> hi) {
                GridGuard g(c.lock, false);
                const Box b = regionOf(c, lo, hi);
                return dense<int32_t>(c, b, [](int32_t v) { return v; });
            },
            py::arg("min") = py::none(), py::arg("max") = py::none(),
            "The mass of the box min..max (default: the clay's bounds) as an int32 array [x, y, z].")
        .def(
            "density_array",
            [](const Clay& c, std::optional<Int3> lo, std::optional<Int3> hi) {
                GridGuard g(c.lock, false);
                const Box b = regionOf(c, lo, hi);
                const double tc = c.meta.rule.threshold;
                return dense<float>(c, b, [tc](int32_t v) { return float(double(v) / tc); });
            },
            py::arg("min") = py::none(), py::arg("max") = py::none(),
            "mass / Tc over the box min..max (default: the clay's bounds) as a float32 array [x, y, z].")
        .def(
            "copy",
            [](const Clay& c) {
                GridGuard g(c.lock, false);
                return Clay{c.mass->deepCopy(), c.meta};
            },
            "An independent copy.")
        .def(
            "write",
            [](const Clay& c, const std::string& path, const std::optional<std::vector<std::string>>& grids) {
                const ClayGrids named = gridsOf(grids, ClayGrids());
                GridGuard g(c.lock, false);
                writeClayFile(path, *c.mass, c.meta, named);
            },
            py::arg("path"), py::arg("grids") = py::none(),
            "Writes a clay .vdb atomically with this clay's metadata, holding the grids named (a list of "
            "\"mass\", \"density\", \"surface\"; default: all three).")
        .def(
            "write_mesh",
            [](const Clay& c, const std::string& path, double iso, bool keepVolume) {
                // In world units through this clay's voxel size and up axis, like write().
                GridGuard g(c.lock, false);
                MassGridPtr view = c.mass->copy(); // shares the tree
                setClayTransform(*view, c.meta.voxelSize, c.meta.up);
                writeSurfaceMesh(path, *view, c.meta.rule.threshold, iso, keepVolume);
            },
            py::arg("path"), py::arg("isovalue") = 0.5, py::arg("keep_volume") = false,
            "Writes the surface where density = isovalue as .obj or .ply, in world units; keep_volume "
            "moves it along its normals (at most half a voxel) to enclose the clay's volume.")
        .def(
            "render",
            [](const Clay& c, const std::string& path, int width, int height, double az, double el) {
                GridGuard g(c.lock, false);
                RenderOptions o;
                o.width = width;
                o.height = height;
                o.azimuthDeg = az;
                o.elevationDeg = el;
                renderPng(path, *c.mass, c.meta.rule.threshold, c.meta.dimensions, o);
            },
            py::arg("path"), py::arg("width") = 800, py::arg("height") = 600, py::arg("azimuth") = 35.0,
            py::arg("elevation") = 25.0, "Renders a PNG (2D: density map; 3D: shaded surface).")
        .def("__repr__", [](const Clay& c) {
            GridGuard g(c.lock, false);
            return "<vdbclay.Clay " + std::to_string(clayVoxelCount(*c.mass)) + " voxels, mass " +
                   std::to_string(totalMass(*c.mass)) + ", Tc " + std::to_string(c.meta.rule.threshold) + ">";
        });

    m.def(
        "from_array",
        [](const py::object& array, Int3 origin, int32_t threshold, double voxelSize, int dimensions) {
            const IntArray a = integerArray(array, "from_array: mass");
            RuleParams rp;
            rp.threshold = threshold;
            validate(rp);
            Clay c;
            c.mass = openvdb::Int32Grid::create(0);
            c.mass->setName("mass");
            writeArray(*c.mass, a, origin, false);
            c.meta.rule = rp;
            c.meta.voxelSize = voxelSize;
            c.meta.dimensions = dimensions;
            return c;
        },
        py::arg("mass"), py::arg("origin") = Int3{0, 0, 0}, py::arg("threshold") = 1000,
        py::arg("voxel_size") = 1.0, py::arg("dimensions") = 3,
        "Clay from a dense integer array [x, y, z] whose element [0, 0, 0] is voxel origin (a float array "
        "only if it holds whole numbers: anything else raises vdbclay.Error, never truncated).");
    m.def(
        "make_clay",
        [](const PyShape& s, int32_t mass, int dimensions, int32_t threshold, double voxelSize,
           const std::string& up, const py::object& budget) {
            Clay c;
            c.meta.up = parseUpAxis(up);
            c.meta.rule.threshold = threshold;
            validate(c.meta.rule);
            c.meta.dimensions = dimensions;
            c.meta.voxelSize = voxelSize;
            const uint64_t b = callBudget(budget);
            InterruptPoll poll;
            {
                py::gil_scoped_release nogil;
                { // the clay must fit the memory budget, as `vdbclay import` checks it
                    Scene sc;
                    sc.source = "make_clay";
                    sc.dimensions = dimensions;
                    ClaySpec spec;
                    spec.shape.kind = s.kind;
                    spec.shape.field = "shape";
                    spec.shape.shape = s.shape;
                    spec.mass = mass;
                    sc.clay.push_back(spec);
                    sc.memoryBudget = b;
                    checkMemoryBudget(sc);
                }
                c.mass = makeClay(*s.shape, mass, dimensions, std::ref(poll));
            }
            poll.rethrow();
            return c;
        },
        py::arg("shape"), py::arg("mass"), py::arg("dimensions") = 3, py::arg("threshold") = 1000,
        py::arg("voxel_size") = 1.0, py::arg("up") = "y", py::arg("memory_budget") = py::none(),
        "Clay of `mass` per voxel in every voxel whose centre is inside shape (meshes and level sets: "
        "by the part of each voxel they cover). Refused (vdbclay.Error) before any voxel is made when "
        "it is estimated to need more than memory_budget (bytes or a size such as \"8G\"; None: the "
        "module's, set_memory_budget(), else the default, 3/4 of memory; \"none\": no check), as "
        "`vdbclay import --memory-budget`. Ctrl-C stops it (KeyboardInterrupt).");
    m.def(
        "read",
        [](const std::string& path, const std::string& grid) {
            ClayFile f = readClayFile(path, grid);
            return Clay{f.mass, f.meta};
        },
        py::arg("path"), py::arg("grid") = "mass", "Reads a clay .vdb (the Int32 grid, with its metadata).");
    m.def("describe", &describeVdb, py::arg("path"), "What `vdbclay info` prints about any .vdb.");

    // ---- the automaton ---------------------------------------------------------------------------
    py::class_<PyAutomaton>(m, "Automaton",
                            "The cellular automaton on a Clay (shares its grid: the clay changes in place).")
        .def(py::init([](const Clay& clay, std::optional<std::string> rule, std::optional<int32_t> threshold,
                         std::optional<double> alpha, uint64_t seed, int threads) {
                 auto a = std::make_unique<PyAutomaton>();
                 a->clay = clay;
                 AutomatonOptions o;
                 o.dimensions = clay.meta.dimensions;
                 o.rule = clay.meta.rule;
                 if (rule) o.rule.rule = parseRule(*rule);
                 if (threshold) o.rule.threshold = *threshold;
                 if (alpha) o.rule.alpha = *alpha;
                 o.seed = seed;
                 o.threads = threads;
                 a->clay.meta.rule = o.rule;
                 a->clay.meta.seed = seed;
                 // Reads the grid (and voxelizes its tiles over Tc, which an automaton already on it did).
                 GridGuard g(clay.lock, false);
                 {
                     py::gil_scoped_release nogil;
                     a->automaton = std::make_unique<Automaton>(clay.mass, o);
                 }
                 a->changesSeen = clay.lock->changes;
                 return a;
             }),
             py::arg("clay"), py::arg("rule") = py::none(), py::arg("threshold") = py::none(),
             py::arg("alpha") = py::none(), py::arg("seed") = 0, py::arg("threads") = 0,
             "rule (arata, bingham, sorted, prorata), threshold (Tc) and alpha default to the clay's.")
        .def(
            "step",
            [](PyAutomaton& a) {
                auto guard = changing(a);
                StepReport r;
                {
                    py::gil_scoped_release nogil;
                    r = a.automaton->step();
                }
                return stepDict(r);
            },
            "One step of the current Margolus phase; returns a report dict.")
        .def(
            "run", [](PyAutomaton& a, uint64_t n) { return stepAutomaton(a, false, n, 0); }, py::arg("n"),
            "n steps; returns a report dict. Ctrl-C stops it between two steps (KeyboardInterrupt; the "
            "automaton goes on from there).")
        .def(
            "settle",
            [](PyAutomaton& a, uint64_t maxSteps, int64_t tolerance) {
                return stepAutomaton(a, true, maxSteps, tolerance);
            },
            py::arg("max_steps") = 100000, py::arg("tolerance") = 0,
            "Steps until settled, residual overload <= tolerance, or max_steps; returns a report dict. "
            "Ctrl-C stops it between two steps (KeyboardInterrupt; the automaton goes on from there).")
        .def(
            "add_mass",
            [](PyAutomaton& a, const py::object& array, Int3 origin) {
                const IntArray arr = integerArray(array, "add_mass: mass");
                auto guard = changing(a);
                // Checked on a copy of the box first, so a refused edit changes nothing.
                Box region;
                for (int i = 0; i < 3; ++i) {
                    region.min[i] = origin[i];
                    region.max[i] = int32_t(int64_t(origin[i]) + (arr.ndim() == 3 ? arr.shape(i) : 1) - 1);
                }
                auto probe = openvdb::Int32Grid::create(0);
                auto src = a.automaton->mass()->getConstAccessor();
                auto dst = probe->getAccessor();
                for (int x = region.min[0]; x <= region.max[0]; ++x)
                    for (int y = region.min[1]; y <= region.max[1]; ++y)
                        for (int z = region.min[2]; z <= region.max[2]; ++z) {
                            const openvdb::Coord c(x, y, z);
                            if (src.isValueOn(c)) dst.setValueOn(c, src.getValue(c));
                        }
                writeArray(*probe, arr, origin, true);
                a.automaton->edit(region, [&](MassGrid& g) { writeArray(g, arr, origin, true); });
            },
            py::arg("mass"), py::arg("origin") = Int3{0, 0, 0},
            "Adds a dense integer array [x, y, z] (negative entries remove clay) at origin, through "
            "Automaton.edit, so the automaton wakes there. Refused, changing nothing, if a voxel would go "
            "negative or overflow, or if the array holds a value that is not a whole number.")
        .def(
            "push",
            [](PyAutomaton& a, const std::vector<PyShape>& tools, int maxSearch) {
                std::vector<ShapePtr> t;
                for (const PyShape& s : tools)
                    t.push_back(s.shape);
                auto guard = changing(a);
                PushReport r;
                {
                    py::gil_scoped_release nogil;
                    r = push(*a.automaton, t, maxSearch);
                }
                return pushDict(r);
            },
            py::arg("tools"), py::arg("max_search") = 16,
            "The paper's push: clay inside the tools moves out along their normals (mass exact).")
        .def(
            "deposit",
            [](PyAutomaton& a, const PyShape& tool, int32_t mass, const std::vector<PyShape>& solids) {
                std::vector<ShapePtr> s;
                for (const PyShape& p : solids)
                    s.push_back(p.shape);
                auto guard = changing(a);
                DepositReport r;
                {
                    py::gil_scoped_release nogil;
                    r = deposit(*a.automaton, *tool.shape, mass, s);
                }
                return r.mass;
            },
            py::arg("tool"), py::arg("mass"), py::arg("solids") = std::vector<PyShape>{},
            "An \"add\" tool: fills every voxel the tool covers to at least mass x the part of it "
            "covered (boundary voxels in proportion), never an obstacle or a voxel inside one of solids. "
            "Returns the clay added.")
        .def(
            "carve",
            [](PyAutomaton& a, const PyShape& tool) {
                auto guard = changing(a);
                DepositReport r;
                {
                    py::gil_scoped_release nogil;
                    r = carve(*a.automaton, *tool.shape);
                }
                return r.mass;
            },
            py::arg("tool"),
            "A \"remove\" tool: takes away the clay inside the tool (a boundary voxel's in proportion to "
            "the part of it covered). Returns the clay removed.")
        .def(
            "smooth",
            [](PyAutomaton& a, const PyShape& tool, double strength, int passes) {
                auto guard = changing(a);
                SmoothReport r;
                {
                    py::gil_scoped_release nogil;
                    r = smooth(*a.automaton, *tool.shape, strength, passes);
                }
                return r.massMoved;
            },
            py::arg("tool"), py::arg("strength") = 0.5, py::arg("passes") = 1,
            "A \"smooth\" tool: surface tension inside the tool (clay moves along the surface from bumps "
            "to hollows; mass exact; nothing outside the tool changes). Returns the clay moved.")
        .def(
            "surface_energy",
            [](const PyAutomaton& a, Int3 lo, Int3 hi) {
                auto g = reading(a);
                const Box b{{{lo[0], lo[1], lo[2]}}, {{hi[0], hi[1], hi[2]}}};
                return surfaceEnergy(*a.automaton->mass(), b, a.automaton->options().rule.threshold,
                                     a.automaton->options().dimensions);
            },
            py::arg("min"), py::arg("max"),
            "The roughness measure smoothing lowers (Smooth.h: the weighted count of broken bonds, in "
            "units of Tc) over the voxels min..max (inclusive).")
        .def_property_readonly(
            "clay",
            [](const PyAutomaton& a) {
                auto g = reading(a);
                Clay c = a.clay;
                c.meta.steps = a.automaton->stepCount();
                return c;
            },
            "The clay (the same grid and lock: it keeps changing as the automaton steps).")
        .def_property_readonly("step_count",
                               [](const PyAutomaton& a) {
                                   auto g = reading(a);
                                   return a.automaton->stepCount();
                               })
        .def_property_readonly("total_mass",
                               [](const PyAutomaton& a) {
                                   auto g = reading(a);
                                   return a.automaton->totalMass();
                               })
        .def_property_readonly("residual_overload",
                               [](const PyAutomaton& a) {
                                   auto g = reading(a);
                                   return a.automaton->residualOverload();
                               })
        .def_property_readonly("settled", [](const PyAutomaton& a) {
            auto g = reading(a);
            return a.automaton->settled();
        });

    // ---- scenes ----------------------------------------------------------------------------------
    py::class_<Scene>(m, "Scene", "A scene (docs/SCENES.md): clay, tools with paths, obstacles, settling.")
        .def_static(
            "load",
            [](const std::string& path, const py::object& budget) {
                const uint64_t b = callBudget(budget);
                py::gil_scoped_release nogil;
                return loadScene(path, b);
            },
            py::arg("path"), py::arg("memory_budget") = py::none(),
            "Reads a scene .json file. memory_budget (bytes, or a size such as \"8G\" or \"none\"; None: "
            "the module's, set_memory_budget(), if set), when given, replaces the scene's "
            "\"memory_budget\" (as `vdbclay run --memory-budget`): meshes are checked against it as they "
            "are read, and a Sculptor keeps it.")
        .def_static(
            "from_json",
            [](const std::string& text, const std::string& source, const std::string& baseDir,
               const py::object& budget) {
                const uint64_t b = callBudget(budget);
                py::gil_scoped_release nogil;
                return parseScene(text, source, baseDir, b);
            },
            py::arg("text"), py::arg("source") = "<python>", py::arg("base_dir") = ".",
            py::arg("memory_budget") = py::none(),
            "Parses scene JSON text; relative file names resolve against base_dir. memory_budget as in "
            "Scene.load.")
        .def_static("default", &defaultScene, "The built-in default scene (a cube pressed by a plate).")
        .def_readonly("source", &Scene::source)
        .def_readwrite("seed", &Scene::seed)
        .def_readwrite("frames", &Scene::frames, "Frames to run.")
        .def_readwrite("start", &Scene::start, "A clay .vdb to continue from (empty: none).")
        .def_property(
            "memory_budget", [](const Scene& s) { return s.memoryBudget; },
            [](Scene& s, const py::object& budget) { s.memoryBudget = budgetArg(budget); },
            "Bytes a run may use (\"memory_budget\" in the scene): 0 the default (3/4 of memory), "
            "NO_MEMORY_BUDGET none. Set from bytes, a size such as \"8G\" or \"none\", or None (0).")
        .def_readonly("dimensions", &Scene::dimensions)
        .def_property_readonly(
            "tool_actions",
            [](const Scene& s) {
                std::vector<std::string> a;
                for (const ToolSpec& t : s.tools)
                    a.push_back(toolActionName(t.action));
                return a;
            },
            "Each tool's \"action\": push, add, remove or smooth.")
        .def_readonly("voxel_size", &Scene::voxelSize)
        .def_property_readonly("up", [](const Scene& s) { return std::string(upAxisName(s.up)); })
        .def_property(
            "threshold", [](const Scene& s) { return s.rule.threshold; },
            [](Scene& s, int32_t t) { s.rule.threshold = t; }, "Tc")
        .def_property(
            "rule", [](const Scene& s) { return std::string(ruleName(s.rule.rule)); },
            [](Scene& s, const std::string& r) { s.rule.rule = parseRule(r); })
        .def_property_readonly("outputs", [](const Scene& s) {
            py::dict d;
            d["vdb"] = s.outputs.vdb;
            d["png"] = s.outputs.png;
            d["mesh"] = s.outputs.mesh;
            d["stats"] = s.outputs.stats;
            return d;
        });

    py::class_<PySculptor>(m, "Sculptor", "Runs a scene frame by frame: move the tools, push, settle.")
        .def(py::init([](const Scene& s, int threads, const py::object& budget) {
                 auto p = std::make_unique<PySculptor>();
                 p->threads = threads;
                 Scene scene = s;
                 if (const uint64_t b = callBudget(budget)) scene.memoryBudget = b;
                 const auto t0 = std::chrono::steady_clock::now();
                 {
                     py::gil_scoped_release nogil;
                     p->sculptor = std::make_unique<Sculptor>(scene, threads);
                 }
                 p->setupSeconds =
                     std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
                 return p;
             }),
             py::arg("scene"), py::arg("threads") = 0, py::arg("memory_budget") = py::none(),
             "Builds the scene's clay, obstacles and tools. memory_budget (bytes, or a size such as \"8G\" "
             "or \"none\"; None: the module's, set_memory_budget(), else the scene's) replaces the scene's, "
             "as `vdbclay run --memory-budget`: a scene estimated to need more is refused before anything "
             "is built, and a run whose clay outgrows it stops (Error).")
        .def(
            "run_frame",
            [](PySculptor& p) {
                auto guard = changing(p);
                InterruptPoll poll;
                StopRequest request(*p.sculptor, poll);
                FrameReport r;
                {
                    py::gil_scoped_release nogil;
                    r = p.sculptor->runFrame();
                }
                poll.rethrow();
                throwIfOutgrewBudget(*p.sculptor);
                return frameDict(r);
            },
            "Runs the next frame; returns a report dict (frame, push, settle, finished). Ctrl-C stops it "
            "after an automaton step (KeyboardInterrupt; the frame stays open and the next run() or "
            "run_frame() finishes it exactly). Raises vdbclay.Error when the clay outgrows the memory "
            "budget (the frame stays open: write() saves it).")
        .def("run", &runSculptor, py::arg("frames") = 0, py::arg("progress") = nullptr,
             "Runs up to `frames` frames (0: all left) and returns the run's report: a dict with the keys "
             "and values of `vdbclay run --stats` (frames run, steps, seconds, setup_seconds, masses, "
             "stage_seconds, the final clay's metrics, content_hash, ...; output_seconds 0). "
             "progress(report) is called after each frame with the frame's report dict and "
             "total_frames; returning False asks the run to stop, which it does at the next point a "
             "checkpoint resumes exactly: almost always that frame's end (else the report counts the "
             "open frame, and `stopped` and `frame_open` say so). Ctrl-C stops the run after an automaton "
             "step and raises KeyboardInterrupt; the next run() or run_frame() goes on exactly (the same "
             "clay as an unbroken run). Raises vdbclay.Error when the clay outgrows the memory budget "
             "(write() saves the "
             "run where it stopped).")
        .def_property_readonly(
            "clay",
            [](const PySculptor& p) {
                GridGuard g(p.lock, false);
                return sculptorClay(p);
            },
            "The clay now (shares the grid and its lock), with metadata to continue from a file.")
        .def(
            "write",
            [](const PySculptor& p, const std::string& path,
               const std::optional<std::vector<std::string>>& grids) {
                const ClayGrids named = gridsOf(grids, p.sculptor->scene().outputs.grids);
                GridGuard g(p.lock, false);
                const Clay c = sculptorClay(p);
                writeClayFile(path, *c.mass, c.meta, named);
            },
            py::arg("path"), py::arg("grids") = py::none(),
            "Writes the clay as a .vdb that a scene's \"start\" continues exactly (it needs \"mass\"), "
            "holding the grids named (a list of \"mass\", \"density\", \"surface\"; default: the scene's "
            "outputs.grids).")
        .def_property_readonly(
            "mass_added",
            [](const PySculptor& p) {
                GridGuard g(p.lock, false);
                return p.sculptor->massAdded();
            },
            "Clay the add tools deposited since the scene's frame 0 (a start file's too).")
        .def_property_readonly(
            "mass_removed",
            [](const PySculptor& p) {
                GridGuard g(p.lock, false);
                return p.sculptor->massRemoved();
            },
            "Clay the remove tools took away since the scene's frame 0.")
        .def_property_readonly("done",
                               [](const PySculptor& p) {
                                   GridGuard g(p.lock, false);
                                   return p.sculptor->done();
                               })
        .def_property_readonly(
            "stopped",
            [](const PySculptor& p) {
                GridGuard g(p.lock, false);
                return p.sculptor->stopped();
            },
            "The last run() or run_frame() stopped early (progress returned False, or the memory budget).")
        .def_property_readonly(
            "frame_open",
            [](const PySculptor& p) {
                GridGuard g(p.lock, false);
                return p.sculptor->frameOpen();
            },
            "A frame was cut short and is not finished; the next run() or run_frame() finishes it.")
        .def_property_readonly(
            "memory_budget",
            [](const PySculptor& p) {
                GridGuard g(p.lock, false);
                return p.sculptor->memoryBudget();
            },
            "The bytes the run keeps to (the default resolved; NO_MEMORY_BUDGET: none).")
        .def_property_readonly("frame",
                               [](const PySculptor& p) {
                                   GridGuard g(p.lock, false);
                                   return p.sculptor->frame();
                               })
        .def_property_readonly("total_frames",
                               [](const PySculptor& p) {
                                   GridGuard g(p.lock, false);
                                   return p.sculptor->totalFrames();
                               })
        .def_property_readonly("total_mass", [](const PySculptor& p) {
            auto g = reading(p);
            return p.sculptor->automaton().totalMass();
        });
}
