// accuracy_study: how close the automaton gets to an analytic answer, how fast, and what the sparse
// representation stores. Writes the CSVs behind docs/ACCURACY.md (scripts/accuracy.sh runs it and
// draws the plots).
//
//   squeeze  A cylinder of clay (axis y, radius R0, height H0 = 2 R0, mass m0 per voxel, Tc) on a
//            floor obstacle, squeezed by a plate (a box tool, wider than the clay) from H0 to
//            H = H0 / 2. The plates only push along their normal (Push.h), so they are slip plates.
//            Nearly incompressible clay keeps its volume, so the analytic answer is a cylinder of
//            height H and radius R0 sqrt(H0 / H). Per rule and resolution R0: volume (mass / Tc and
//            occupied voxels) against pi R0^2 H0, the radius of the occupied cross-section at
//            mid-height, IoU and surface distance against the analytic cylinder (Metrics.h).
//   fig6     The paper's figure 6: data/scenes/paper/cylinder2d-<rule>.json run frame by frame, steps
//            and time to stabilise per frame and rule; then rule 2 (sorted) on the same scene in a dense
//            2D re-implementation, as we implement it (checked bit-identical to the library) and in
//            the variants the paper's text allows, to find which one does not converge.
//   sweep    Speed against error on the squeeze: per rule, one knob at a time around a base case:
//            settle tolerance, step budget per frame, plate travel per frame (same total travel),
//            resolution, Tc against the initial mass.
//   scenes   For every scene in data/scenes/paper and data/scenes/studies: what the sparse grid
//            stores (active voxels, leaves, bytes) and the blocks examined per step, against the dense
//            box a naive implementation allocates and sweeps.
//
// Every run is single-threaded (results are identical on any thread count; one thread makes the
// times less noisy on a shared machine). Output: DIR/{squeeze,fig6,fig6-rule2,sweep,scenes}.csv and
// a readable summary on stderr.
#include "automaton/RulesImpl.h"
#include "vdbclay/Automaton.h"
#include "vdbclay/Metrics.h"
#include "vdbclay/Rules.h"
#include "vdbclay/Scene.h"
#include "vdbclay/Sculpt.h"
#include "vdbclay/Shapes.h"

#include <openvdb/openvdb.h>

#include <algorithm>
#include <cstdarg>
#include <chrono>
#include <climits>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <functional>
#include <map>
#include <sstream>
#include <string>
#include <type_traits>
#include <vector>

namespace {

using namespace vdbclay;
using openvdb::Coord;
using Clock = std::chrono::steady_clock;

double since(Clock::time_point t0)
{
    return std::chrono::duration<double>(Clock::now() - t0).count();
}

const double kPi = 3.14159265358979323846;
const Rule kRules[] = {Rule::Arata, Rule::Bingham, Rule::Sorted, Rule::Prorata};

struct Options {
    bool quick = false;
    std::string out = "docs/accuracy";
    std::string scenes = "data/scenes";
    std::vector<std::string> parts{"squeeze", "fig6", "sweep", "scenes"};
    bool wants(const std::string& p) const { return std::find(parts.begin(), parts.end(), p) != parts.end(); }
};

/// A CSV file: header first, then rows; flushed per row so an interrupted study keeps what it did.
class Csv {
public:
    Csv(const std::string& path, const std::string& header)
        : mFile(std::fopen(path.c_str(), "w")), mPath(path)
    {
        if (!mFile) throw Error("cannot write " + path);
        std::fprintf(mFile, "%s\n", header.c_str());
    }
    ~Csv()
    {
        if (mFile) std::fclose(mFile);
    }
    Csv(const Csv&) = delete;
    Csv& operator=(const Csv&) = delete;
    void row(const std::string& line)
    {
        std::fprintf(mFile, "%s\n", line.c_str());
        std::fflush(mFile);
    }

private:
    std::FILE* mFile;
    std::string mPath;
};

std::string fmt(const char* f, ...) __attribute__((format(printf, 1, 2)));
std::string fmt(const char* f, ...)
{
    char buf[4096];
    va_list ap;
    va_start(ap, f);
    std::vsnprintf(buf, sizeof buf, f, ap);
    va_end(ap);
    return buf;
}

// ==== the squeeze ================================================================================

/// One squeeze run: the scene's parameters.
struct SqueezeCase {
    Rule rule = Rule::Prorata;
    int r0 = 8;                 ///< initial radius, voxels
    int h0 = 16;                ///< initial height, voxels (clay in y = 0 .. h0 - 1)
    int h = 8;                  ///< final height
    int32_t m0 = 950;           ///< initial mass per voxel
    int32_t tc = 1000;          ///< threshold
    int travel = 1;             ///< plate travel per frame, voxels (divides h0 - h)
    uint64_t maxSteps = 100000; ///< step budget per frame
    int64_t tolerance = 0;      ///< settle tolerance per frame (0: settle fully)
};

SqueezeCase baseCase(Rule rule, int r0)
{
    SqueezeCase c;
    c.rule = rule;
    c.r0 = r0;
    c.h0 = 2 * r0;
    c.h = r0;
    return c;
}

/// What one squeeze run gave.
struct SqueezeResult {
    double seconds = 0;
    uint64_t frames = 0, steps = 0, framesUnsettled = 0, blocksVisited = 0, blocksUpdated = 0;
    uint64_t initialVoxels = 0; ///< voxels of the rasterised cylinder (the clay at frame 0)
    ClayMetrics m;
    ShapeError shape;             ///< against the analytic squeezed cylinder
    double volumeRef = 0;         ///< pi R0^2 H0
    double volumeMass = 0;        ///< mass / Tc
    double radiusRef = 0;         ///< R0 sqrt(H0 / H)
    double radiusMid = 0;         ///< sqrt(occupied cells of the mid-height layer / pi)
    double radiusMean = 0;        ///< sqrt(occupied cells between the plates / (pi H))
    uint64_t occupiedOutside = 0; ///< occupied cells not between floor and plate (should be 0)
    std::vector<uint64_t> layers; ///< occupied cells per layer y = 0 .. h - 1
    double relErr(double v, double ref) const { return (v - ref) / ref; }
};

std::string squeezeJson(const SqueezeCase& c)
{
    const int travel = c.h0 - c.h;
    if (c.travel <= 0 || travel % c.travel != 0) {
        throw Error(
            fmt("squeeze: travel per frame %d does not divide the total travel %d", c.travel, travel));
    }
    const int frames = travel / c.travel;
    const int w = 3 * c.r0 + 8;                      // plates wider than the squeezed clay can spread
    const int thick = std::max(8, 2 * c.travel + 2); // thicker than a frame's travel: the normal stays -y
    std::ostringstream js;
    js << "{\"dimensions\": 3, \"threshold\": " << c.tc << ", \"rule\": \"" << ruleName(c.rule)
       << "\", \"alpha\": 0.5, \"seed\": 1,\n"
       << " \"clay\": [{\"shape\": \"cylinder\", \"center\": [0, " << 0.5 * (c.h0 - 1)
       << ", 0], \"radius\": " << c.r0 << ", \"height\": " << c.h0 << ", \"axis\": \"y\", \"mass\": " << c.m0
       << "}],\n"
       << " \"tools\": [{\"name\": \"top plate\", \"shape\": \"box\", \"min\": [" << -w << ", " << c.h0
       << ", " << -w << "], \"max\": [" << w << ", " << c.h0 + thick - 1 << ", " << w
       << "], \"path\": [{\"translate\": [0, " << -c.travel << ", 0], \"frames\": " << frames << "}]}],\n"
       << " \"obstacles\": [{\"name\": \"bottom plate\", \"shape\": \"box\", \"min\": [" << -w << ", -3, "
       << -w << "], \"max\": [" << w << ", -1, " << w << "]}],\n"
       << " \"settle\": {\"max_steps\": " << c.maxSteps << ", \"tolerance\": " << c.tolerance << "}}";
    return js.str();
}

SqueezeResult runSqueeze(const SqueezeCase& c)
{
    const Scene scene = parseScene(squeezeJson(c), "<squeeze>", ".");
    Sculptor sculptor(scene, 1);
    SqueezeResult r;
    r.initialVoxels = clayVoxelCount(*sculptor.mass());
    const RunSummary s = sculptor.run();
    r.seconds = s.seconds;
    r.frames = s.frames;
    r.steps = s.steps;
    r.framesUnsettled = s.framesUnsettled;
    r.blocksVisited = s.blocksVisited;
    r.blocksUpdated = s.blocksUpdated;

    const MassGrid& mass = *sculptor.mass();
    r.m = measureClay(mass, c.tc, sculptor.automaton().obstacles().get(), 3);
    r.radiusRef = c.r0 * std::sqrt(double(c.h0) / double(c.h));
    // The analytic answer: voxel centres within radiusRef of the axis, y = 0 .. h - 1, rasterised as
    // makeClay() rasterises the initial cylinder.
    const ShapePtr ref = makeCylinder(Vec3{{0, 0.5 * (c.h - 1), 0}}, r.radiusRef, double(c.h), 1);
    r.shape = compareShapes(mass, c.tc, *ref, 3);
    r.volumeRef = kPi * c.r0 * c.r0 * c.h0;
    r.volumeMass = double(r.m.mass) / double(c.tc);

    // Occupied cells (2 m >= Tc, Metrics.h) per layer.
    std::map<int, uint64_t> layer;
    for (auto it = mass.tree().cbeginValueOn(); it; ++it) {
        if (2 * int64_t(*it) < c.tc) continue;
        const int y = it.getCoord().y();
        if (y < 0 || y >= c.h) ++r.occupiedOutside;
        ++layer[y];
    }
    uint64_t between = 0;
    for (int y = 0; y < c.h; ++y) {
        between += layer[y];
        r.layers.push_back(layer[y]);
    }
    r.radiusMid = std::sqrt(double(layer[(c.h - 1) / 2]) / kPi);
    r.radiusMean = std::sqrt(double(between) / (kPi * c.h));
    return r;
}

const char* kSqueezeHeader =
    "study,rule,knob,value,r0,h0,h,m0,tc,travel,frames,max_steps,tolerance,seconds,steps,frames_unsettled,"
    "blocks_visited,blocks_updated,mass,initial_voxels,volume_ref,volume_mass,volume_mass_err,occupied_"
    "voxels,"
    "volume_occupied_err,volume_mass_err_n0,volume_occupied_err_n0,clay_voxels,radius_ref,radius_ref_voxels,"
    "radius_mid,radius_mid_err,radius_mean,radius_mean_err,"
    "occupied_outside,residual_overload,residual_rel,heterogeneity_cv,compaction,interior_mean_density,"
    "max_cell,iou,mean_surface_distance,max_surface_distance";

std::string squeezeRow(const std::string& study, const std::string& knob, const std::string& value,
                       const SqueezeCase& c, const SqueezeResult& r)
{
    return fmt(
        "%s,%s,%s,%s,%d,%d,%d,%d,%d,%d,%llu,%llu,%lld,%.6f,%llu,%llu,%llu,%llu,%lld,%llu,%.2f,%.2f,%.6f,"
        "%llu,%.6f,%.6f,%.6f,%llu,%.4f,%.4f,%.4f,%.6f,%.4f,%.6f,%llu,%lld,%.3e,%.6f,%.6f,%.6f,%d,%.6f,%.4f,%."
        "4f",
        study.c_str(), ruleName(c.rule), knob.c_str(), value.c_str(), c.r0, c.h0, c.h, c.m0, c.tc, c.travel,
        (unsigned long long)r.frames, (unsigned long long)c.maxSteps, (long long)c.tolerance, r.seconds,
        (unsigned long long)r.steps, (unsigned long long)r.framesUnsettled,
        (unsigned long long)r.blocksVisited, (unsigned long long)r.blocksUpdated, (long long)r.m.mass,
        (unsigned long long)r.initialVoxels, r.volumeRef, r.volumeMass, r.relErr(r.volumeMass, r.volumeRef),
        (unsigned long long)r.m.occupiedVoxels, r.relErr(double(r.m.occupiedVoxels), r.volumeRef),
        r.relErr(r.volumeMass, double(r.initialVoxels)),
        r.relErr(double(r.m.occupiedVoxels), double(r.initialVoxels)), (unsigned long long)r.m.clayVoxels,
        r.radiusRef, std::sqrt(double(r.shape.referenceVoxels) / (kPi * c.h)), r.radiusMid,
        r.relErr(r.radiusMid, r.radiusRef), r.radiusMean, r.relErr(r.radiusMean, r.radiusRef),
        (unsigned long long)r.occupiedOutside, (long long)r.m.residualOverload,
        double(r.m.residualOverload) / double(std::max<int64_t>(1, r.m.mass)), r.m.heterogeneityCV,
        r.m.compaction, r.m.interiorMeanDensity, r.m.maxCell, r.shape.iou, r.shape.meanSurfaceDistance,
        r.shape.maxSurfaceDistance);
}

void logSqueeze(const std::string& what, const SqueezeCase& c, const SqueezeResult& r)
{
    std::fprintf(
        stderr,
        "  %-8s %-22s %7.2f s %7llu steps  V(occ) %+6.2f%%  V(mass) %+6.2f%%  r_mid %6.2f/%6.2f (%+6.2f%%)  "
        "IoU %.3f  dist %.2f  CV %.4f  compaction %.3f  residual %lld\n",
        ruleName(c.rule), what.c_str(), r.seconds, (unsigned long long)r.steps,
        100 * r.relErr(double(r.m.occupiedVoxels), r.volumeRef), 100 * r.relErr(r.volumeMass, r.volumeRef),
        r.radiusMid, r.radiusRef, 100 * r.relErr(r.radiusMid, r.radiusRef), r.shape.iou,
        r.shape.meanSurfaceDistance, r.m.heterogeneityCV, r.m.compaction, (long long)r.m.residualOverload);
}

void studySqueeze(const Options& opt)
{
    std::fprintf(stderr, "\n== squeeze: every rule at several resolutions, settled fully each frame ==\n");
    Csv csv(opt.out + "/squeeze.csv", kSqueezeHeader);
    Csv profile(opt.out + "/squeeze-profile.csv", "rule,r0,h,y,occupied_cells,radius,radius_ref");
    const std::vector<int> radii = opt.quick ? std::vector<int>{4, 6} : std::vector<int>{4, 6, 8, 12, 16, 24};
    for (Rule rule : kRules) {
        for (int r0 : radii) {
            const SqueezeCase c = baseCase(rule, r0);
            const SqueezeResult r = runSqueeze(c);
            logSqueeze("R0=" + std::to_string(r0), c, r);
            csv.row(squeezeRow("squeeze", "r0", std::to_string(r0), c, r));
            for (int y = 0; y < c.h; ++y) {
                profile.row(fmt("%s,%d,%d,%d,%llu,%.4f,%.4f", ruleName(rule), r0, c.h, y,
                                (unsigned long long)r.layers[size_t(y)],
                                std::sqrt(double(r.layers[size_t(y)]) / kPi), r.radiusRef));
            }
        }
    }
}

// ==== the speed / error sweep ====================================================================

void studySweep(const Options& opt)
{
    std::fprintf(stderr, "\n== sweep: one knob at a time around the base squeeze ==\n");
    Csv csv(opt.out + "/sweep.csv", kSqueezeHeader);
    const int r0 = opt.quick ? 4 : 12;
    const int tc = 1000;
    struct Knob {
        std::string name;
        std::vector<std::string> values;
        std::function<void(SqueezeCase&, const std::string&)> apply;
    };
    std::vector<Knob> knobs = {
        {"tolerance",
         {"0", "1000", "10000", "100000", "1000000"},
         [](SqueezeCase& c, const std::string& v) { c.tolerance = std::stoll(v); }},
        {"max_steps",
         {"5", "20", "50", "200", "1000"},
         [](SqueezeCase& c, const std::string& v) { c.maxSteps = std::stoull(v); }},
        {"travel",
         {"1", "2", "4", "8"},
         [](SqueezeCase& c, const std::string& v) { c.travel = std::stoi(v); }},
        {"r0",
         {"6", "8", "12", "16"},
         [](SqueezeCase& c, const std::string& v) {
             const SqueezeCase b = baseCase(c.rule, std::stoi(v));
             c.r0 = b.r0;
             c.h0 = b.h0;
             c.h = b.h;
         }},
        {"m0_over_tc",
         {"0.5", "0.8", "0.9", "0.95", "1.0"},
         [tc](SqueezeCase& c, const std::string& v) { c.m0 = int32_t(std::lround(std::stod(v) * tc)); }},
    };
    if (opt.quick) {
        for (Knob& k : knobs)
            k.values.resize(2);
    }
    for (Rule rule : kRules) {
        for (const Knob& k : knobs) {
            for (const std::string& v : k.values) {
                SqueezeCase c = baseCase(rule, r0);
                c.tc = tc;
                k.apply(c, v);
                if ((c.h0 - c.h) % c.travel != 0) continue;
                const SqueezeResult r = runSqueeze(c);
                logSqueeze(k.name + "=" + v, c, r);
                csv.row(squeezeRow("sweep", k.name, v, c, r));
            }
        }
    }
}

// ==== figure 6 ===================================================================================

/// The scene file of figure 3 to 6 for @a rule.
std::string cylinder2dScene(const Options& opt, Rule rule)
{
    return opt.scenes + "/paper/cylinder2d-" + ruleName(rule) + ".json";
}

void studyFig6Library(const Options& opt, Csv& csv, std::map<Rule, uint64_t>& hashes)
{
    for (Rule rule : kRules) {
        const Scene scene = loadScene(cylinder2dScene(opt, rule));
        // Time: the best of three identical runs (the same steps each time: deterministic).
        std::vector<FrameReport> best;
        std::vector<double> bestSecs;
        double bestTotal = 1e30;
        for (int rep = 0; rep < (opt.quick ? 1 : 3); ++rep) {
            Sculptor s(scene, 1);
            std::vector<FrameReport> frames;
            std::vector<double> secs;
            double total = 0;
            while (!s.done()) {
                const auto t0 = Clock::now();
                frames.push_back(s.runFrame());
                secs.push_back(since(t0));
                total += secs.back();
            }
            if (total < bestTotal) {
                bestTotal = total;
                best = frames;
                bestSecs = secs;
            }
            hashes[rule] = contentHash(*s.mass());
        }
        uint64_t steps = 0;
        for (size_t f = 0; f < best.size(); ++f) {
            const FrameReport& r = best[f];
            steps += r.settle.steps;
            csv.row(fmt("library,%s,%llu,%llu,%.6f,%llu,%llu,%lld,%s", ruleName(rule),
                        (unsigned long long)r.frame, (unsigned long long)r.settle.steps, bestSecs[f],
                        (unsigned long long)r.settle.blocksVisited,
                        (unsigned long long)r.settle.blocksUpdated, (long long)r.settle.residualOverload,
                        stopReasonName(r.settle.reason)));
        }
        std::fprintf(
            stderr, "  %-8s %2zu frames  %6llu steps  %.4f s (best of %d)  max frame %llu steps\n",
            ruleName(rule), best.size(), (unsigned long long)steps, bestTotal, opt.quick ? 1 : 3,
            (unsigned long long)
                std::max_element(best.begin(), best.end(), [](const FrameReport& a, const FrameReport& b) {
                    return a.settle.steps < b.settle.steps;
                })->settle.steps);
    }
}

// ---- rule 2 in a dense 2D re-implementation --------------------------------------------------------

/// How rule 2 (sorted) is applied to one 2x2 block.
enum class Rule2 {
    Library,     ///< ours: rules_internal::repartition (must reproduce the library bit for bit)
    AsPrinted,   ///< the paper's pseudo-code word for word: over cells are not set back to Tc
    Truncated,   ///< over cells to Tc; E > A: Tc + (E - A) / n truncated (the remainder is lost)
    FixedOrder,  ///< ours, but ties and the remainder go to cells in a fixed order, no hash
    Float,       ///< ours in 32-bit floating point (no remainder at all; rounding instead)
    FloatProrata ///< rule 3 in 32-bit floating point, for comparison with Float
};
bool isFloat(Rule2 v)
{
    return v == Rule2::Float || v == Rule2::FloatProrata;
}
const char* rule2Name(Rule2 v)
{
    switch (v) {
    case Rule2::Library: return "library";
    case Rule2::AsPrinted: return "as-printed";
    case Rule2::Truncated: return "truncated";
    case Rule2::FixedOrder: return "fixed-order";
    case Rule2::Float: return "float";
    case Rule2::FloatProrata: return "float-prorata";
    }
    return "?";
}

/// What the E > A branch did, counted over a frame.
struct Rule2Counts {
    uint64_t eOverA = 0;    ///< block updates through the E > A branch (surplus into full cells)
    uint64_t roundUp = 0;   ///< of those, updates whose result holds more clay than before (float)
    uint64_t roundDown = 0; ///< ... less clay than before (float rounding, or truncation)
};

/// Rule 2 on one block of n cells, in 64-bit integers or in float (T), for the variants other
/// than Library.
template <typename T>
void rule2Block(Rule2 v, T tc, int n, const T* m, uint32_t valid, T* out, Rule2Counts& counts)
{
    uint32_t over = 0, under = 0;
    int nu = 0;
    T e = 0, a = 0;
    for (int i = 0; i < n; ++i) {
        out[i] = m[i];
        if (!((valid >> i) & 1u)) continue;
        if (m[i] > tc) {
            over |= 1u << i;
            e += m[i] - tc;
        } else {
            under |= 1u << i;
            ++nu;
            a += tc - m[i];
        }
    }
    if (!over || !under) return;
    if (v != Rule2::AsPrinted) {
        for (int i = 0; i < n; ++i)
            if ((over >> i) & 1u) out[i] = tc;
    }
    if (e > a) {
        const T share = (e - a) / T(nu);
        T r = (e - a) - share * T(nu);
        for (int i = 0; i < n; ++i) {
            if (!((under >> i) & 1u)) continue;
            out[i] = tc + share;
            if (v == Rule2::FixedOrder && r > 0) { // remainder to the first cells, always the same
                ++out[i];
                --r;
            }
        }
        ++counts.eOverA;
        T before = 0, after = 0;
        for (int i = 0; i < n; ++i) {
            before += m[i];
            after += out[i];
        }
        if (after > before) ++counts.roundUp;
        if (after < before) ++counts.roundDown;
        return;
    }
    if (v == Rule2::FloatProrata) {
        for (int i = 0; i < n; ++i)
            if ((under >> i) & 1u) out[i] += e * (tc - out[i]) / a;
        return;
    }
    // E <= A: fill the emptiest first; equal masses in cell order (a stable sort).
    int order[8], cnt = 0;
    for (int i = 0; i < n; ++i)
        if ((under >> i) & 1u) order[cnt++] = i;
    std::stable_sort(order, order + cnt, [&](int x, int y) { return out[x] < out[y]; });
    for (int s = 0; s < cnt && e > 0; ++s) {
        const T take = std::min(tc - out[order[s]], e);
        out[order[s]] += take;
        e -= take;
    }
}

/// The 2D cylinder scene, dense: a box of cells around everything clay can reach, the floor and the
/// plate as obstacle cells, the plate's push done as Push.h does it for a horizontal plate.
template <typename T> struct Dense2D {
    int x0 = 0, y0 = 0, nx = 0, ny = 0;
    std::vector<T> m;
    std::vector<uint8_t> fixedObs; ///< the floor
    size_t idx(int x, int y) const { return size_t(x - x0) + size_t(nx) * size_t(y - y0); }
};

struct Rule2Frame {
    uint64_t frame = 0, steps = 0;
    double seconds = 0;
    double massBefore = 0;         ///< after the push, before settling
    double mass = 0, overload = 0; ///< after settling
    bool settled = false;
    Rule2Counts counts;
};

/// Runs the cylinder2d scene (parsed from @a scene: clay box, plate box moving down one voxel per
/// frame, floor box) with rule 2 variant @a v. Returns per-frame reports; @a hash gets the final
/// content hash (for Library, to check against the library's run).
template <typename T>
std::vector<Rule2Frame> runRule2Dense(const Scene& scene, Rule2 v, uint64_t maxSteps, uint64_t& hash)
{
    if (scene.tools.size() != 1 || scene.obstacles.size() != 1 || scene.clay.size() != 1) {
        throw Error(scene.source + ": the dense rule-2 study expects one clay box, one plate and one floor");
    }
    // Shapes' bounds() may hold a margin: the cells are the voxels whose centres are inside.
    auto inside = [](const Shape& sh, int x, int y) {
        return sh.distance(Vec3{{double(x), double(y), 0.0}}) < 0;
    };
    const Shape& plate = *scene.tools[0].shape.shape;
    const Shape& floor = *scene.obstacles[0].shape;
    const Shape& clay = *scene.clay[0].shape.shape;
    const Box pb = plate.bounds(), fb = floor.bounds(), cb = clay.bounds();
    Dense2D<T> d;
    d.x0 = std::min({pb.min[0], fb.min[0], cb.min[0]}) & ~1;
    d.y0 = std::min({pb.min[1], fb.min[1], cb.min[1]}) & ~1;
    d.nx = std::max({pb.max[0], fb.max[0], cb.max[0]}) - d.x0 + 1;
    d.ny = std::max({pb.max[1], fb.max[1], cb.max[1]}) - d.y0 + 1;
    d.m.assign(size_t(d.nx) * d.ny, 0);
    d.fixedObs.assign(d.m.size(), 0);
    for (int y = d.y0; y < d.y0 + d.ny; ++y)
        for (int x = d.x0; x < d.x0 + d.nx; ++x) {
            if (inside(floor, x, y)) d.fixedObs[d.idx(x, y)] = 1;
            if (inside(clay, x, y)) d.m[d.idx(x, y)] = scene.clay[0].mass;
        }
    const int plateDy = int(scene.tools[0].path[0].translate[1]);
    const T tc = T(scene.rule.threshold);
    const CompiledRule rule = compileRule(scene.rule);
    auto overOf = [tc](T x) { return x > tc ? x - tc : T(0); };
    uint64_t step = 0;
    std::vector<Rule2Frame> frames;
    std::vector<uint8_t> obs;
    for (uint64_t f = 1; f <= scene.frames; ++f) {
        // Place the plate (y from plateMin up, x over its width) and push: clay under the plate's
        // bottom row goes straight down into the row below it (the box's normal there is -y).
        const int dy = int(f) * plateDy;
        obs = d.fixedObs;
        int pyMin = INT_MAX;
        for (int y = d.y0; y < d.y0 + d.ny; ++y)
            for (int x = d.x0; x < d.x0 + d.nx; ++x)
                if (y - dy < d.y0 + d.ny && inside(plate, x, y - dy)) {
                    obs[d.idx(x, y)] = 1;
                    pyMin = std::min(pyMin, y);
                }
        for (int y = pyMin; y < d.y0 + d.ny; ++y)
            for (int x = d.x0; x < d.x0 + d.nx; ++x) {
                T& c = d.m[d.idx(x, y)];
                if (!c || !obs[d.idx(x, y)] || d.fixedObs[d.idx(x, y)]) continue;
                d.m[d.idx(x, pyMin - 1)] += c;
                c = 0;
            }
        T overload = 0, mass = 0;
        for (size_t i = 0; i < d.m.size(); ++i) {
            mass += d.m[i];
            if (!obs[i]) overload += overOf(d.m[i]);
        }
        Rule2Frame fr;
        fr.frame = f;
        fr.massBefore = double(mass);
        int quiet = 0;
        const auto t0 = Clock::now();
        while (overload > 0 && quiet < 2 && fr.steps < maxSteps) {
            const int p = int(step & 1);
            bool changed = false;
            for (int y = d.y0 + p; y + 1 < d.y0 + d.ny; y += 2)
                for (int x = d.x0 + p; x + 1 < d.x0 + d.nx; x += 2) {
                    size_t at[4];
                    T mm[4], out[4];
                    int32_t m32[4];
                    int64_t out64[4];
                    uint32_t valid = 0;
                    bool any = false;
                    for (int i = 0; i < 4; ++i) {
                        at[i] = d.idx(x + (i & 1), y + ((i >> 1) & 1));
                        mm[i] = d.m[at[i]];
                        any |= mm[i] != 0;
                        valid |= uint32_t(!obs[at[i]]) << i;
                    }
                    if (!any) continue;
                    if (v == Rule2::Library) {
                        for (int i = 0; i < 4; ++i)
                            m32[i] = int32_t(mm[i]);
                        rules_internal::repartition(rule, 4, m32, valid, BlockKey{x, y, 0, step, scene.seed},
                                                    out64);
                        for (int i = 0; i < 4; ++i)
                            out[i] = T(out64[i]);
                    } else {
                        rule2Block<T>(v, tc, 4, mm, valid, out, fr.counts);
                    }
                    for (int i = 0; i < 4; ++i) {
                        if (out[i] == mm[i]) continue;
                        changed = true;
                        if ((valid >> i) & 1u) overload += overOf(out[i]) - overOf(mm[i]);
                        mass += out[i] - mm[i];
                        d.m[at[i]] = out[i];
                    }
                }
            quiet = changed ? 0 : quiet + 1;
            ++step;
            ++fr.steps;
            if (std::getenv("R2DEBUG") && std::is_floating_point<T>::value && fr.steps >= 19990) {
                for (int yy = d.y0; yy < d.y0 + d.ny; ++yy)
                    for (int xx = d.x0; xx < d.x0 + d.nx; ++xx) {
                        const double c = double(d.m[d.idx(xx, yy)]);
                        if (c > double(tc) && !obs[d.idx(xx, yy)])
                            std::fprintf(stderr, "step %llu over (%d,%d) %.6f  nbrs %.6f %.6f %.6f %.6f\n",
                                         (unsigned long long)step, xx, yy, c, double(d.m[d.idx(xx - 1, yy)]),
                                         double(d.m[d.idx(xx + 1, yy)]), double(d.m[d.idx(xx, yy - 1)]),
                                         double(d.m[d.idx(xx, yy + 1)]));
                    }
            }
            if (std::is_floating_point<T>::value) { // rounding: recount rather than accumulate
                overload = 0;
                for (size_t i = 0; i < d.m.size(); ++i)
                    if (!obs[i]) overload += overOf(d.m[i]);
            }
            if (double(mass) > 1e15) break; // clay created without bound (as-printed)
        }
        fr.seconds = since(t0);
        fr.mass = double(mass);
        fr.overload = double(overload);
        fr.settled = overload == 0 || quiet >= 2;
        frames.push_back(fr);
    }
    // Final content hash, as Metrics.h computes it on a grid.
    auto g = openvdb::Int32Grid::create(0);
    auto acc = g->getAccessor();
    for (int y = d.y0; y < d.y0 + d.ny; ++y)
        for (int x = d.x0; x < d.x0 + d.nx; ++x) {
            const double c = double(d.m[d.idx(x, y)]);
            if (c != 0) acc.setValue(Coord(x, y, 0), int32_t(std::min<double>(std::round(c), INT32_MAX)));
        }
    hash = contentHash(*g);
    return frames;
}

void studyFig6(const Options& opt)
{
    std::fprintf(stderr,
                 "\n== figure 6: the 2D cylinder pressed by a plate, time to stabilise per rule ==\n");
    Csv csv(opt.out + "/fig6.csv",
            "impl,rule,frame,steps,seconds,blocks_visited,blocks_updated,residual_overload,stop");
    std::map<Rule, uint64_t> hashes;
    studyFig6Library(opt, csv, hashes);

    std::fprintf(stderr,
                 "  rule 2 (sorted), dense 2D re-implementation, step budget per frame as the scene's:\n");
    Csv csv2(
        opt.out + "/fig6-rule2.csv",
        "variant,frame,steps,seconds,mass,residual_overload,settled,e_over_a_blocks,round_up,round_down");
    const Scene scene = loadScene(cylinder2dScene(opt, Rule::Sorted));
    for (Rule2 v : {Rule2::Library, Rule2::AsPrinted, Rule2::Truncated, Rule2::FixedOrder, Rule2::Float,
                    Rule2::FloatProrata}) {
        uint64_t hash = 0;
        const std::vector<Rule2Frame> frames =
            isFloat(v) ? runRule2Dense<float>(scene, v, scene.settle.maxSteps, hash)
                       : runRule2Dense<int64_t>(scene, v, scene.settle.maxSteps, hash);
        uint64_t steps = 0, unsettled = 0;
        Rule2Counts counts;
        double secs = 0;
        for (const Rule2Frame& f : frames) {
            steps += f.steps;
            secs += f.seconds;
            unsettled += !f.settled;
            counts.eOverA += f.counts.eOverA;
            counts.roundUp += f.counts.roundUp;
            counts.roundDown += f.counts.roundDown;
            csv2.row(fmt("%s,%llu,%llu,%.6f,%.3f,%.6g,%d,%llu,%llu,%llu", rule2Name(v),
                         (unsigned long long)f.frame, (unsigned long long)f.steps, f.seconds, f.mass,
                         f.overload, int(f.settled), (unsigned long long)f.counts.eOverA,
                         (unsigned long long)f.counts.roundUp, (unsigned long long)f.counts.roundDown));
        }
        std::fprintf(
            stderr,
            "    %-13s %6llu steps  %.3f s  frames unsettled %llu/%zu  mass %.1f -> %.1f  residual %.6g"
            "  E>A updates %llu (more clay %llu, less %llu)%s\n",
            rule2Name(v), (unsigned long long)steps, secs, (unsigned long long)unsettled, frames.size(),
            frames.front().massBefore, frames.back().mass, frames.back().overload,
            (unsigned long long)counts.eOverA, (unsigned long long)counts.roundUp,
            (unsigned long long)counts.roundDown,
            v == Rule2::Library ? (hash == hashes[Rule::Sorted] ? "  (bit-identical to the library)"
                                                                : "  (DIFFERS from the library!)")
                                : "");
        if (v == Rule2::Library && hash != hashes[Rule::Sorted]) {
            throw Error("the dense rule-2 re-implementation does not reproduce the library's run");
        }
    }
}

// ==== model only what a scene needs ================================================================

struct SceneStats {
    std::string name;
    int dims = 3;
    uint64_t frames = 0, steps = 0, blocksVisited = 0, blocksUpdated = 0;
    double seconds = 0;
    uint64_t activeVoxels = 0, clayVoxels = 0, leaves = 0, bytes = 0, leafBytes = 0, obstacleBytes = 0;
    uint64_t peakActive = 0, peakLeaves = 0, peakBytes = 0;
    openvdb::CoordBBox clayHull; ///< every voxel that ever held clay (bounds, over all frames)
    openvdb::CoordBBox sceneBox; ///< clay hull + tools along their paths + obstacles
};

openvdb::CoordBBox toBBox(const Box& b)
{
    return openvdb::CoordBBox(Coord(b.min[0], b.min[1], b.min[2]), Coord(b.max[0], b.max[1], b.max[2]));
}

openvdb::CoordBBox clayBounds(const MassGrid& g)
{
    openvdb::CoordBBox bb;
    for (auto leaf = g.tree().cbeginLeaf(); leaf; ++leaf)
        for (auto v = leaf->cbeginValueOn(); v; ++v)
            if (*v != 0) bb.expand(v.getCoord());
    return bb;
}

/// Dense voxels and blocks of one phase in @a bb (2D: the z = 0 layer only).
uint64_t denseVoxels(const openvdb::CoordBBox& bb, int dims)
{
    const openvdb::Coord d = bb.dim();
    return uint64_t(d.x()) * uint64_t(d.y()) * (dims == 2 ? 1 : uint64_t(d.z()));
}
uint64_t denseBlocks(const openvdb::CoordBBox& bb, int dims)
{
    const openvdb::Coord d = bb.dim();
    auto half = [](int n) { return uint64_t(n + 1) / 2; };
    return half(d.x()) * half(d.y()) * (dims == 2 ? 1 : half(d.z()));
}

SceneStats measureScene(const std::string& path)
{
    const Scene scene = loadScene(path);
    SceneStats st;
    st.name = std::filesystem::path(path).stem().string();
    st.dims = scene.dimensions;
    Sculptor s(scene, 1);
    auto observe = [&]() {
        const MassGrid& g = *s.mass();
        st.clayHull.expand(clayBounds(g));
        st.peakActive = std::max<uint64_t>(st.peakActive, g.activeVoxelCount());
        st.peakLeaves = std::max<uint64_t>(st.peakLeaves, g.tree().leafCount());
        st.peakBytes = std::max<uint64_t>(st.peakBytes, g.memUsage());
    };
    observe();
    const RunSummary sum = s.run(0, [&](const FrameReport&) { observe(); });
    st.frames = sum.frames;
    st.steps = sum.steps;
    st.blocksVisited = sum.blocksVisited;
    st.blocksUpdated = sum.blocksUpdated;
    st.seconds = sum.seconds;
    const MassGrid& g = *s.mass();
    st.activeVoxels = g.activeVoxelCount();
    st.clayVoxels = clayVoxelCount(g);
    st.leaves = g.tree().leafCount();
    st.bytes = g.memUsage();
    for (auto leaf = g.tree().cbeginLeaf(); leaf; ++leaf)
        st.leafBytes += leaf->memUsage();
    st.obstacleBytes = s.automaton().obstacles() ? s.automaton().obstacles()->memUsage() : 0;
    st.sceneBox = st.clayHull;
    for (const ToolSpec& t : scene.tools)
        for (uint64_t f = 0; f <= scene.frames; ++f)
            st.sceneBox.expand(toBBox(makeTransformed(t.shape.shape, t.poseAt(f))->bounds()));
    for (const ShapeSpec& o : scene.obstacles)
        st.sceneBox.expand(toBBox(o.shape->bounds()));
    if (st.dims == 2) {
        st.clayHull = openvdb::CoordBBox(Coord(st.clayHull.min().x(), st.clayHull.min().y(), 0),
                                         Coord(st.clayHull.max().x(), st.clayHull.max().y(), 0));
        st.sceneBox = openvdb::CoordBBox(Coord(st.sceneBox.min().x(), st.sceneBox.min().y(), 0),
                                         Coord(st.sceneBox.max().x(), st.sceneBox.max().y(), 0));
    }
    return st;
}

void studyScenes(const Options& opt)
{
    std::fprintf(stderr, "\n== model only what a scene needs: every scene in %s/{paper,studies} ==\n",
                 opt.scenes.c_str());
    Csv csv(opt.out + "/scenes.csv",
            "scene,dims,frames,steps,seconds,active_voxels,clay_voxels,leaves,grid_bytes,leaf_bytes,obstacle_"
            "bytes,peak_active,"
            "peak_leaves,peak_bytes,blocks_visited_per_step,blocks_updated_per_step,hull_voxels,hull_bytes,"
            "hull_blocks_per_step,scene_box_voxels,scene_box_bytes,scene_box_blocks_per_step");
    std::vector<std::string> files;
    for (const char* folder : {"paper", "studies"})
        for (const auto& e : std::filesystem::directory_iterator(opt.scenes + "/" + folder))
            if (e.path().extension() == ".json") files.push_back(e.path().string());
    std::sort(files.begin(), files.end());
    for (const std::string& f : files) {
        const SceneStats s = measureScene(f);
        const double perStepV = s.steps ? double(s.blocksVisited) / double(s.steps) : 0;
        const double perStepU = s.steps ? double(s.blocksUpdated) / double(s.steps) : 0;
        // A dense implementation stores 4 bytes of mass per voxel (plus an obstacle flag, not counted).
        const uint64_t hullV = denseVoxels(s.clayHull, s.dims), boxV = denseVoxels(s.sceneBox, s.dims);
        csv.row(fmt("%s,%d,%llu,%llu,%.4f,%llu,%llu,%llu,%llu,%llu,%llu,%llu,%llu,%llu,%.1f,%.1f,%llu,%llu,%"
                    "llu,%llu,%llu,%llu",
                    s.name.c_str(), s.dims, (unsigned long long)s.frames, (unsigned long long)s.steps,
                    s.seconds, (unsigned long long)s.activeVoxels, (unsigned long long)s.clayVoxels,
                    (unsigned long long)s.leaves, (unsigned long long)s.bytes,
                    (unsigned long long)s.leafBytes, (unsigned long long)s.obstacleBytes,
                    (unsigned long long)s.peakActive, (unsigned long long)s.peakLeaves,
                    (unsigned long long)s.peakBytes, perStepV, perStepU, (unsigned long long)hullV,
                    (unsigned long long)(4 * hullV), (unsigned long long)denseBlocks(s.clayHull, s.dims),
                    (unsigned long long)boxV, (unsigned long long)(4 * boxV),
                    (unsigned long long)denseBlocks(s.sceneBox, s.dims)));
        std::fprintf(
            stderr,
            "  %-18s %5llu active voxels %4llu leaves %8llu B | blocks/step %8.1f visited %8.1f updated | "
            "dense hull %8llu voxels %8llu blocks/step, scene box %9llu voxels\n",
            s.name.c_str(), (unsigned long long)s.activeVoxels, (unsigned long long)s.leaves,
            (unsigned long long)s.bytes, perStepV, perStepU, (unsigned long long)hullV,
            (unsigned long long)denseBlocks(s.clayHull, s.dims), (unsigned long long)boxV);
    }
}

int usage(const char* argv0)
{
    std::fprintf(stderr,
                 "usage: %s [--quick] [--out DIR] [--scenes DIR] [--parts squeeze,fig6,sweep,scenes]\n"
                 "  --quick   small sizes and few knob values (a smoke test, seconds)\n"
                 "  --out     where the CSVs go (default docs/accuracy; created if missing)\n"
                 "  --scenes  the scene directory, holding paper/ and studies/ (default data/scenes)\n",
                 argv0);
    return 2;
}

} // namespace

int main(int argc, char** argv)
{
    Options opt;
    try {
        for (int i = 1; i < argc; ++i) {
            const std::string a = argv[i];
            auto val = [&]() -> std::string {
                if (i + 1 >= argc) throw std::runtime_error(a + " needs a value");
                return argv[++i];
            };
            if (a == "--quick")
                opt.quick = true;
            else if (a == "--out")
                opt.out = val();
            else if (a == "--scenes")
                opt.scenes = val();
            else if (a == "--parts") {
                opt.parts.clear();
                std::stringstream ss(val());
                std::string p;
                while (std::getline(ss, p, ','))
                    opt.parts.push_back(p);
            } else if (a == "-h" || a == "--help")
                return usage(argv[0]);
            else
                throw std::runtime_error("unknown option " + a);
        }
    } catch (const std::exception& e) {
        std::fprintf(stderr, "accuracy_study: %s\n", e.what());
        return usage(argv[0]);
    }
    try {
        openvdb::initialize();
        std::filesystem::create_directories(opt.out);
        const auto t0 = Clock::now();
        if (opt.wants("fig6")) studyFig6(opt);
        if (opt.wants("scenes")) studyScenes(opt);
        if (opt.wants("squeeze")) studySqueeze(opt);
        if (opt.wants("sweep")) studySweep(opt);
        std::fprintf(stderr, "\naccuracy_study: done in %.1f s; CSVs in %s\n", since(t0), opt.out.c_str());
    } catch (const std::exception& e) {
        std::fprintf(stderr, "accuracy_study: error: %s\n", e.what());
        return 1;
    }
    return 0;
}
