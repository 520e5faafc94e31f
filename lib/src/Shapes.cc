// Signed distance fields: analytic shapes, rigid poses, level sets read from .vdb files, meshes.
//
// Every analytic shape computes its bounds once, at construction, as the smallest voxel box that
// contains the whole shape taken as a continuous solid (not only the voxel centres inside it):
// makeTransformed relies on that to bound a rotated shape from the corners of its inner bounds.
// Level sets and meshes sample an openvdb::FloatGrid (trilinear, BoxSampler) in world space.

#include "vdbclay/Shapes.h"

#include "VdbCheck.h"

#include <openvdb/openvdb.h>
#include <openvdb/io/File.h>
#include <openvdb/tools/Interpolation.h>
#include <openvdb/tools/MeshToVolume.h>

#include <algorithm>
#include <cmath>
#include <cerrno>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <limits>
#include <map>
#include <sstream>
#include <unordered_map>

namespace vdbclay {

namespace {

/// Coordinates of shape bounds must stay well inside int32 (callers add search margins).
constexpr double kMaxCoord = 1 << 30;

std::string num(double v)
{
    std::ostringstream os;
    os.precision(17);
    os << v;
    return os.str();
}

std::string vecStr(const Vec3& v)
{
    return "[" + num(v[0]) + "," + num(v[1]) + "," + num(v[2]) + "]";
}

void requireFinite(const Vec3& v, const std::string& what, const char* name)
{
    for (int i = 0; i < 3; ++i) {
        if (!std::isfinite(v[i])) {
            throw Error(what + ": " + name + "[" + std::to_string(i) + "] must be finite, got " + num(v[i]));
        }
    }
}

void requirePositive(double v, const std::string& what, const char* name)
{
    if (!std::isfinite(v) || !(v > 0.0)) {
        throw Error(what + ": " + name + " must be finite and > 0, got " + num(v));
    }
}

/// The voxel box [floor(lo), ceil(hi)]; throws if it leaves the coordinate range.
Box boxOf(const Vec3& lo, const Vec3& hi, const std::string& what)
{
    Box b;
    for (int i = 0; i < 3; ++i) {
        const double a = std::floor(lo[i]), z = std::ceil(hi[i]);
        if (!(a >= -kMaxCoord) || !(z <= kMaxCoord)) {
            throw Error(what + ": bounds [" + num(a) + ", " + num(z) + "] along axis " + std::to_string(i) +
                        " exceed the coordinate range +-2^30");
        }
        b.min[i] = int32_t(a);
        b.max[i] = int32_t(z);
    }
    return b;
}

double dot(const Vec3& a, const Vec3& b)
{
    return a[0] * b[0] + a[1] * b[1] + a[2] * b[2];
}
Vec3 sub(const Vec3& a, const Vec3& b)
{
    return {{a[0] - b[0], a[1] - b[1], a[2] - b[2]}};
}
double length(const Vec3& a)
{
    return std::sqrt(dot(a, a));
}

/// sin and cos of an angle in degrees; exact for multiples of 90.
void sinCosDeg(double deg, double& s, double& c)
{
    const double r = std::fmod(deg, 360.0);
    const double q = r / 90.0;
    if (q == std::floor(q)) {
        const int k = ((int(q) % 4) + 4) % 4;
        const double S[4] = {0, 1, 0, -1}, C[4] = {1, 0, -1, 0};
        s = S[k];
        c = C[k];
        return;
    }
    const double rad = r * (M_PI / 180.0);
    s = std::sin(rad);
    c = std::cos(rad);
}

using Mat3 = std::array<std::array<double, 3>, 3>;

/// R = Rz Ry Rx: rotate about x first, then y, then z (fixed axes).
Mat3 rotation(const Vec3& deg)
{
    double sx, cx, sy, cy, sz, cz;
    sinCosDeg(deg[0], sx, cx);
    sinCosDeg(deg[1], sy, cy);
    sinCosDeg(deg[2], sz, cz);
    Mat3 r;
    r[0] = {{cz * cy, cz * sy * sx - sz * cx, cz * sy * cx + sz * sx}};
    r[1] = {{sz * cy, sz * sy * sx + cz * cx, sz * sy * cx - cz * sx}};
    r[2] = {{-sy, cy * sx, cy * cx}};
    return r;
}

Vec3 mul(const Mat3& m, const Vec3& v)
{
    return {{dot(m[0], v), dot(m[1], v), dot(m[2], v)}};
}

Vec3 mulT(const Mat3& m, const Vec3& v)
{
    return {{m[0][0] * v[0] + m[1][0] * v[1] + m[2][0] * v[2],
             m[0][1] * v[0] + m[1][1] * v[1] + m[2][1] * v[2],
             m[0][2] * v[0] + m[1][2] * v[1] + m[2][2] * v[2]}};
}

// ---- analytic shapes -----------------------------------------------------------------------------

class Sphere final : public Shape {
public:
    Sphere(const Vec3& c, double r) : mC(c), mR(r)
    {
        mBounds = boxOf({{c[0] - r, c[1] - r, c[2] - r}}, {{c[0] + r, c[1] + r, c[2] + r}}, describe());
    }
    double distance(const Vec3& p) const override { return length(sub(p, mC)) - mR; }
    Box bounds() const override { return mBounds; }
    std::string describe() const override
    {
        return "sphere (center " + vecStr(mC) + ", radius " + num(mR) + ")";
    }

private:
    Vec3 mC;
    double mR;
    Box mBounds;
};

class BoxShape final : public Shape {
public:
    BoxShape(const Vec3& lo, const Vec3& hi)
    {
        for (int i = 0; i < 3; ++i) {
            mCenter[i] = 0.5 * (lo[i] + hi[i]);
            mHalf[i] = 0.5 * (hi[i] - lo[i]) + 0.5;
        }
        mLo = lo;
        mHi = hi;
        mBounds = boxOf({{lo[0] - 0.5, lo[1] - 0.5, lo[2] - 0.5}}, {{hi[0] + 0.5, hi[1] + 0.5, hi[2] + 0.5}},
                        describe());
    }
    double distance(const Vec3& p) const override
    {
        double outside2 = 0, inside = -std::numeric_limits<double>::infinity();
        for (int i = 0; i < 3; ++i) {
            const double q = std::abs(p[i] - mCenter[i]) - mHalf[i];
            if (q > 0) outside2 += q * q;
            inside = std::max(inside, q);
        }
        return std::sqrt(outside2) + std::min(inside, 0.0);
    }
    Box bounds() const override { return mBounds; }
    std::string describe() const override { return "box (min " + vecStr(mLo) + ", max " + vecStr(mHi) + ")"; }

private:
    Vec3 mLo, mHi, mCenter, mHalf;
    Box mBounds;
};

class Cylinder final : public Shape {
public:
    Cylinder(const Vec3& c, double r, double h, int axis) : mC(c), mR(r), mH(h), mAxis(axis)
    {
        Vec3 lo, hi;
        for (int i = 0; i < 3; ++i) {
            const double e = i == axis ? 0.5 * h : r;
            lo[i] = c[i] - e;
            hi[i] = c[i] + e;
        }
        mBounds = boxOf(lo, hi, describe());
    }
    double distance(const Vec3& p) const override
    {
        double radial2 = 0;
        for (int i = 0; i < 3; ++i)
            if (i != mAxis) radial2 += (p[i] - mC[i]) * (p[i] - mC[i]);
        const double dr = std::sqrt(radial2) - mR;
        const double da = std::abs(p[mAxis] - mC[mAxis]) - 0.5 * mH;
        const double a = std::max(dr, 0.0), b = std::max(da, 0.0);
        return std::min(std::max(dr, da), 0.0) + std::sqrt(a * a + b * b);
    }
    Box bounds() const override { return mBounds; }
    std::string describe() const override
    {
        return "cylinder (center " + vecStr(mC) + ", radius " + num(mR) + ", height " + num(mH) + ", axis " +
               std::to_string(mAxis) + ")";
    }

private:
    Vec3 mC;
    double mR, mH;
    int mAxis;
    Box mBounds;
};

class Capsule final : public Shape {
public:
    Capsule(const Vec3& a, const Vec3& b, double r) : mA(a), mB(b), mR(r)
    {
        Vec3 lo, hi;
        for (int i = 0; i < 3; ++i) {
            lo[i] = std::min(a[i], b[i]) - r;
            hi[i] = std::max(a[i], b[i]) + r;
        }
        mBounds = boxOf(lo, hi, describe());
    }
    double distance(const Vec3& p) const override
    {
        const Vec3 ab = sub(mB, mA), ap = sub(p, mA);
        const double l2 = dot(ab, ab);
        const double t = l2 > 0 ? std::clamp(dot(ap, ab) / l2, 0.0, 1.0) : 0.0;
        const Vec3 d{{ap[0] - t * ab[0], ap[1] - t * ab[1], ap[2] - t * ab[2]}};
        return length(d) - mR;
    }
    Box bounds() const override { return mBounds; }
    std::string describe() const override
    {
        return "capsule (a " + vecStr(mA) + ", b " + vecStr(mB) + ", radius " + num(mR) + ")";
    }

private:
    Vec3 mA, mB;
    double mR;
    Box mBounds;
};

class Transformed final : public Shape {
public:
    Transformed(ShapePtr inner, const Pose& pose) : mInner(std::move(inner)), mPose(pose)
    {
        mRot = rotation(pose.rotationDeg);
        const Box ib = mInner->bounds();
        if (ib.empty()) {
            mBounds = Box();
            return;
        }
        Vec3 lo{{kMaxCoord * 4, kMaxCoord * 4, kMaxCoord * 4}},
            hi{{-kMaxCoord * 4, -kMaxCoord * 4, -kMaxCoord * 4}};
        for (int corner = 0; corner < 8; ++corner) {
            Vec3 c;
            for (int i = 0; i < 3; ++i)
                c[i] = ((corner >> i) & 1) ? ib.max[i] + 0.5 : ib.min[i] - 0.5;
            const Vec3 w = mPose.apply(c);
            for (int i = 0; i < 3; ++i) {
                lo[i] = std::min(lo[i], w[i]);
                hi[i] = std::max(hi[i], w[i]);
            }
        }
        // Rounding of the rotation: widen by a hair before rounding outward.
        for (int i = 0; i < 3; ++i) {
            lo[i] -= 1e-9 * (1 + std::abs(lo[i]));
            hi[i] += 1e-9 * (1 + std::abs(hi[i]));
        }
        mBounds = boxOf(lo, hi, describe());
    }
    double distance(const Vec3& p) const override { return mInner->distance(mPose.applyInverse(p)); }
    Vec3 normal(const Vec3& p) const override { return mul(mRot, mInner->normal(mPose.applyInverse(p))); }
    Box bounds() const override { return mBounds; }
    std::string describe() const override
    {
        return mInner->describe() + " moved by (translation " + vecStr(mPose.translation) + ", rotation " +
               vecStr(mPose.rotationDeg) + " deg, pivot " + vecStr(mPose.pivot) + ")";
    }

private:
    ShapePtr mInner;
    Pose mPose;
    Mat3 mRot;
    Box mBounds;
};

// ---- level sets ----------------------------------------------------------------------------------

class LevelSet final : public Shape {
public:
    LevelSet(openvdb::FloatGrid::ConstPtr grid, double voxelSize, std::string what)
        : mGrid(std::move(grid)), mVoxelSize(voxelSize), mWhat(std::move(what)), mSampler(*mGrid)
    {
        // Everything inside the level set lies within its narrow band's active voxels (which enclose
        // the interior) or in inactive negative tiles. One voxel of margin covers interpolation.
        openvdb::CoordBBox bb = mGrid->evalActiveVoxelBoundingBox();
        if (!bb.empty()) bb.expand(1);
        const auto& tree = mGrid->tree();
        auto it = tree.cbeginValueOff();
        it.setMaxDepth(openvdb::FloatTree::ValueOffCIter::LEAF_DEPTH - 1);
        for (; it; ++it) {
            if (*it < 0) {
                openvdb::CoordBBox tb;
                it.getBoundingBox(tb);
                tb.expand(1);
                bb.expand(tb);
            }
        }
        if (bb.empty()) {
            mBounds = Box();
            return;
        }
        Vec3 lo{{1e300, 1e300, 1e300}}, hi{{-1e300, -1e300, -1e300}};
        for (int corner = 0; corner < 8; ++corner) {
            openvdb::Vec3d c;
            for (int i = 0; i < 3; ++i)
                c[i] = ((corner >> i) & 1) ? bb.max()[i] + 0.5 : bb.min()[i] - 0.5;
            const openvdb::Vec3d w = mGrid->indexToWorld(c) / mVoxelSize;
            for (int i = 0; i < 3; ++i) {
                lo[i] = std::min(lo[i], w[i]);
                hi[i] = std::max(hi[i], w[i]);
            }
        }
        mBounds = boxOf(lo, hi, describe());
    }
    double distance(const Vec3& p) const override
    {
        const openvdb::Vec3d w(p[0] * mVoxelSize, p[1] * mVoxelSize, p[2] * mVoxelSize);
        return double(mSampler.wsSample(w)) / mVoxelSize;
    }
    Box bounds() const override { return mBounds; }
    std::string describe() const override { return mWhat; }

private:
    openvdb::FloatGrid::ConstPtr mGrid;
    double mVoxelSize;
    std::string mWhat;
    openvdb::tools::GridSampler<openvdb::FloatGrid, openvdb::tools::BoxSampler> mSampler;
    Box mBounds;
};

void requireVoxelSize(double voxelSize, const std::string& what)
{
    if (!std::isfinite(voxelSize) || !(voxelSize > 0.0)) {
        throw Error(what + ": voxelSize must be finite and > 0, got " + num(voxelSize));
    }
}

void requireFile(const std::string& path)
{
    std::error_code ec;
    if (!std::filesystem::exists(path, ec)) throw Error("cannot open " + path + ": no such file");
    if (std::filesystem::is_directory(path, ec)) throw Error("cannot open " + path + ": it is a directory");
}

bool isFloatLevelSet(const openvdb::GridBase& g)
{
    return g.isType<openvdb::FloatGrid>() && g.getGridClass() == openvdb::GRID_LEVEL_SET;
}

// ---- meshes --------------------------------------------------------------------------------------

struct Mesh {
    std::vector<openvdb::Vec3s> points;
    std::vector<openvdb::Vec3I> triangles;
};

/// Welds vertices with identical coordinates so that shared edges are recognised.
class Welder {
public:
    explicit Welder(Mesh& m) : mMesh(m) {}
    uint32_t add(const openvdb::Vec3s& p)
    {
        const auto key = std::make_tuple(p[0], p[1], p[2]);
        auto it = mIndex.find(key);
        if (it != mIndex.end()) return it->second;
        const uint32_t i = uint32_t(mMesh.points.size());
        mMesh.points.push_back(p);
        mIndex.emplace(key, i);
        return i;
    }

private:
    Mesh& mMesh;
    std::map<std::tuple<float, float, float>, uint32_t> mIndex;
};

std::string trim(const std::string& s)
{
    size_t a = 0, b = s.size();
    while (a < b && std::isspace((unsigned char)s[a]))
        ++a;
    while (b > a && std::isspace((unsigned char)s[b - 1]))
        --b;
    return s.substr(a, b - a);
}

std::vector<std::string> tokens(const std::string& line)
{
    std::istringstream is(line);
    std::vector<std::string> t;
    std::string w;
    while (is >> w)
        t.push_back(w);
    return t;
}

bool parseDouble(const std::string& s, double& out)
{
    if (s.empty()) return false;
    char* end = nullptr;
    out = std::strtod(s.c_str(), &end);
    return end == s.c_str() + s.size() && std::isfinite(out);
}

bool parseLong(const std::string& s, long& out)
{
    if (s.empty()) return false;
    char* end = nullptr;
    errno = 0;
    out = std::strtol(s.c_str(), &end, 10);
    return errno == 0 && end == s.c_str() + s.size();
}

[[noreturn]] void malformed(const std::string& path, size_t line, const std::string& why)
{
    throw Error(path + ":" + std::to_string(line) + ": " + why);
}

openvdb::Vec3s toPoint(const std::string& path, size_t line, const std::vector<std::string>& t, size_t first)
{
    if (t.size() < first + 3) malformed(path, line, "expected three coordinates");
    double v[3];
    for (int i = 0; i < 3; ++i) {
        if (!parseDouble(t[first + i], v[i])) {
            malformed(path, line, "bad coordinate \"" + t[first + i] + "\"");
        }
    }
    return openvdb::Vec3s(float(v[0]), float(v[1]), float(v[2]));
}

void addTriangle(Mesh& m, uint32_t a, uint32_t b, uint32_t c)
{
    if (a == b || b == c || a == c) return; // zero area: no surface, no edges
    m.triangles.emplace_back(a, b, c);
}

void readObj(const std::string& path, std::istream& in, Mesh& mesh)
{
    Welder weld(mesh);
    std::vector<uint32_t> vertexIds; // OBJ index - 1 -> welded index
    std::string raw;
    size_t line = 0;
    while (std::getline(in, raw)) {
        ++line;
        const std::string s = trim(raw);
        if (s.empty() || s[0] == '#') continue;
        const std::vector<std::string> t = tokens(s);
        if (t[0] == "v") {
            if (t.size() != 4 && t.size() != 5 && t.size() != 7) {
                malformed(path, line, "a vertex has 3 coordinates (then an optional w, or r g b)");
            }
            vertexIds.push_back(weld.add(toPoint(path, line, t, 1)));
        } else if (t[0] == "f") {
            if (t.size() < 4) malformed(path, line, "a face needs at least 3 vertices");
            std::vector<uint32_t> f;
            for (size_t i = 1; i < t.size(); ++i) {
                const std::string idx = t[i].substr(0, t[i].find('/'));
                long k = 0;
                if (!parseLong(idx, k) || k == 0) malformed(path, line, "bad vertex index \"" + t[i] + "\"");
                const long n = long(vertexIds.size());
                const long zeroBased = k > 0 ? k - 1 : n + k;
                if (zeroBased < 0 || zeroBased >= n) {
                    malformed(path, line,
                              "vertex index " + std::to_string(k) + " out of range (" + std::to_string(n) +
                                  " vertices so far)");
                }
                f.push_back(vertexIds[size_t(zeroBased)]);
            }
            for (size_t i = 1; i + 1 < f.size(); ++i)
                addTriangle(mesh, f[0], f[i], f[i + 1]);
        }
        // vn, vt, o, g, s, usemtl, mtllib, l, ...: not geometry we need.
    }
}

void readStlAscii(const std::string& path, std::istream& in, Mesh& mesh)
{
    Welder weld(mesh);
    std::string raw;
    size_t line = 0, facetLine = 0;
    bool inFacet = false;
    std::vector<uint32_t> f;
    while (std::getline(in, raw)) {
        ++line;
        const std::vector<std::string> t = tokens(raw);
        if (t.empty()) continue;
        const std::string& k = t[0];
        if (k == "solid" || k == "endsolid" || k == "outer" || k == "endloop") continue;
        if (k == "facet") {
            if (inFacet) malformed(path, line, "facet inside a facet");
            inFacet = true;
            facetLine = line;
            f.clear();
        } else if (k == "vertex") {
            if (!inFacet) malformed(path, line, "vertex outside a facet");
            if (t.size() != 4) malformed(path, line, "a vertex has 3 coordinates");
            f.push_back(weld.add(toPoint(path, line, t, 1)));
        } else if (k == "endfacet") {
            if (!inFacet) malformed(path, line, "endfacet without facet");
            if (f.size() != 3) {
                malformed(path, facetLine, "facet has " + std::to_string(f.size()) + " vertices, expected 3");
            }
            addTriangle(mesh, f[0], f[1], f[2]);
            inFacet = false;
        } else {
            malformed(path, line, "unexpected \"" + k + "\" in an ASCII STL");
        }
    }
    if (inFacet) malformed(path, facetLine, "facet not closed by endfacet");
}

void readStlBinary(const std::string& path, const std::string& data, Mesh& mesh)
{
    Welder weld(mesh);
    uint32_t n = 0;
    std::memcpy(&n, data.data() + 80, 4);
    for (uint32_t i = 0; i < n; ++i) {
        const char* tri = data.data() + 84 + size_t(i) * 50 + 12;
        uint32_t v[3];
        for (int j = 0; j < 3; ++j) {
            float c[3];
            std::memcpy(c, tri + 12 * j, 12);
            for (float x : c)
                if (!std::isfinite(x))
                    throw Error(path + ": triangle " + std::to_string(i) + " has a non-finite coordinate");
            v[j] = weld.add(openvdb::Vec3s(c[0], c[1], c[2]));
        }
        addTriangle(mesh, v[0], v[1], v[2]);
    }
}

std::string lowerExtension(const std::string& path)
{
    std::string e = std::filesystem::path(path).extension().string();
    std::transform(e.begin(), e.end(), e.begin(), [](unsigned char c) { return char(std::tolower(c)); });
    return e;
}

/// Number of undirected edges not shared by exactly two triangles.
size_t openEdges(const Mesh& m)
{
    std::unordered_map<uint64_t, uint32_t> count;
    count.reserve(m.triangles.size() * 3);
    for (const auto& t : m.triangles) {
        for (int i = 0; i < 3; ++i) {
            uint32_t a = t[i], b = t[(i + 1) % 3];
            if (a > b) std::swap(a, b);
            ++count[(uint64_t(a) << 32) | b];
        }
    }
    size_t open = 0;
    for (const auto& e : count)
        if (e.second != 2) ++open;
    return open;
}

} // namespace

// ---- Pose, Shape ---------------------------------------------------------------------------------

Vec3 Pose::apply(const Vec3& p) const
{
    const Vec3 r = mul(rotation(rotationDeg), sub(p, pivot));
    return {{r[0] + pivot[0] + translation[0], r[1] + pivot[1] + translation[1],
             r[2] + pivot[2] + translation[2]}};
}

Vec3 Pose::applyInverse(const Vec3& p) const
{
    const Vec3 q{{p[0] - translation[0] - pivot[0], p[1] - translation[1] - pivot[1],
                  p[2] - translation[2] - pivot[2]}};
    const Vec3 r = mulT(rotation(rotationDeg), q);
    return {{r[0] + pivot[0], r[1] + pivot[1], r[2] + pivot[2]}};
}

bool Pose::isIdentity() const
{
    for (int i = 0; i < 3; ++i) {
        if (translation[i] != 0.0) return false;
        if (std::fmod(rotationDeg[i], 360.0) != 0.0) return false;
    }
    return true;
}

Vec3 Shape::normal(const Vec3& p) const
{
    constexpr double h = 0.5;
    Vec3 g;
    for (int i = 0; i < 3; ++i) {
        Vec3 a = p, b = p;
        a[i] += h;
        b[i] -= h;
        g[i] = distance(a) - distance(b);
    }
    const double l = length(g);
    if (!(l > 0.0) || !std::isfinite(l)) return {{0, 1, 0}};
    return {{g[0] / l, g[1] / l, g[2] / l}};
}

// ---- factories -----------------------------------------------------------------------------------

ShapePtr makeSphere(const Vec3& center, double radius)
{
    requireFinite(center, "makeSphere", "center");
    requirePositive(radius, "makeSphere", "radius");
    return std::make_shared<Sphere>(center, radius);
}

ShapePtr makeBox(const Vec3& min, const Vec3& max)
{
    requireFinite(min, "makeBox", "min");
    requireFinite(max, "makeBox", "max");
    for (int i = 0; i < 3; ++i) {
        if (min[i] > max[i]) {
            throw Error("makeBox: min[" + std::to_string(i) + "] = " + num(min[i]) + " exceeds max[" +
                        std::to_string(i) + "] = " + num(max[i]));
        }
    }
    return std::make_shared<BoxShape>(min, max);
}

ShapePtr makeCylinder(const Vec3& center, double radius, double height, int axis)
{
    requireFinite(center, "makeCylinder", "center");
    requirePositive(radius, "makeCylinder", "radius");
    requirePositive(height, "makeCylinder", "height");
    if (axis < 0 || axis > 2) {
        throw Error("makeCylinder: axis must be 0 (x), 1 (y) or 2 (z), got " + std::to_string(axis));
    }
    return std::make_shared<Cylinder>(center, radius, height, axis);
}

ShapePtr makeCapsule(const Vec3& a, const Vec3& b, double radius)
{
    requireFinite(a, "makeCapsule", "a");
    requireFinite(b, "makeCapsule", "b");
    requirePositive(radius, "makeCapsule", "radius");
    return std::make_shared<Capsule>(a, b, radius);
}

ShapePtr makeTransformed(ShapePtr shape, const Pose& pose)
{
    if (!shape) throw Error("makeTransformed: shape is null");
    requireFinite(pose.translation, "makeTransformed", "pose.translation");
    requireFinite(pose.rotationDeg, "makeTransformed", "pose.rotationDeg");
    requireFinite(pose.pivot, "makeTransformed", "pose.pivot");
    if (pose.isIdentity()) return shape;
    return std::make_shared<Transformed>(std::move(shape), pose);
}

ShapePtr loadLevelSet(const std::string& path, double voxelSize, const std::string& gridName)
{
    requireVoxelSize(voxelSize, "loadLevelSet(" + path + ")");
    requireFile(path);
    openvdb::initialize();
    // OpenVDB trusts the sizes a file records: check them first (VdbCheck.h).
    std::vector<io_internal::VdbGridLayout> layout;
    try {
        layout = io_internal::checkVdbLayout(path);
    } catch (const Error& e) {
        throw Error("cannot read level set from " + path + ": " + e.what());
    }
    // Only trees the check walked are read (a float level set always is).
    for (const auto& g : layout) {
        if (!gridName.empty() && g.baseName() == gridName &&
            g.type != "Tree_float_5_4_3") {
            throw Error(path + ": grid \"" + gridName + "\" is not a FloatGrid level set (type " +
                        g.type + ")");
        }
    }
    openvdb::FloatGrid::Ptr grid;
    try {
        openvdb::io::File file(path);
        file.open(false);
        openvdb::GridBase::Ptr base;
        if (!gridName.empty()) {
            if (!file.hasGrid(gridName)) {
                throw Error(path + ": no grid named \"" + gridName + "\"");
            }
            base = file.readGrid(gridName);
            if (!isFloatLevelSet(*base)) {
                throw Error(path + ": grid \"" + gridName + "\" is not a FloatGrid level set (type " +
                            base->type() + ", class " +
                            openvdb::GridBase::gridClassToString(base->getGridClass()) + ")");
            }
        } else {
            openvdb::GridPtrVecPtr meta = file.readAllGridMetadata();
            for (const auto& g : *meta) {
                if (isFloatLevelSet(*g)) {
                    base = file.readGrid(g->getName());
                    break;
                }
            }
            if (!base) {
                throw Error(path + ": no FloatGrid level set among its " + std::to_string(meta->size()) +
                            " grid(s)");
            }
        }
        file.close();
        grid = openvdb::gridPtrCast<openvdb::FloatGrid>(base);
    } catch (const Error&) {
        throw;
    } catch (const std::exception& e) {
        throw Error("cannot read level set from " + path + ": " + e.what());
    }
    if (!grid) throw Error("cannot read level set from " + path);
    const std::string what = "level set \"" + grid->getName() + "\" from " + path;
    return std::make_shared<LevelSet>(grid, voxelSize, what);
}

ShapePtr loadMesh(const std::string& path, double voxelSize)
{
    requireVoxelSize(voxelSize, "loadMesh(" + path + ")");
    requireFile(path);
    std::ifstream in(path, std::ios::binary);
    if (!in) throw Error("cannot open " + path + ": " + std::strerror(errno));
    std::string data((std::istreambuf_iterator<char>(in)), std::istreambuf_iterator<char>());
    if (in.bad()) throw Error("cannot read " + path);

    Mesh mesh;
    const std::string ext = lowerExtension(path);
    bool binaryStl = false;
    if (data.size() >= 84) {
        uint32_t n = 0;
        std::memcpy(&n, data.data() + 80, 4);
        binaryStl = data.size() == 84 + 50 * uint64_t(n);
    }
    const bool asciiStl = data.compare(0, 5, "solid") == 0 && data.find("facet") != std::string::npos;
    std::istringstream text(data);
    if (ext == ".obj") {
        readObj(path, text, mesh);
    } else if (binaryStl && (!asciiStl || data.find('\0') != std::string::npos)) {
        // A binary header may start with "solid" too; text never holds NUL bytes.
        readStlBinary(path, data, mesh);
    } else if (asciiStl) {
        readStlAscii(path, text, mesh);
    } else if (ext == ".stl") {
        if (data.size() < 84)
            throw Error(path + ": too short for an STL file (" + std::to_string(data.size()) + " bytes)");
        throw Error(path + ": neither ASCII STL (\"solid ... facet\") nor binary STL of consistent size "
                           "(truncated?)");
    } else {
        throw Error(path + ": unknown mesh format (expected .obj or .stl)");
    }
    if (mesh.triangles.empty()) throw Error(path + ": the mesh has no faces");
    const size_t open = openEdges(mesh);
    if (open) {
        throw Error(path + ": the mesh is not closed: " + std::to_string(open) +
                    " open edges (edges not shared by exactly two faces)");
    }
    openvdb::initialize();
    openvdb::FloatGrid::Ptr grid;
    try {
        auto xform = openvdb::math::Transform::createLinearTransform(voxelSize);
        grid = openvdb::tools::meshToLevelSet<openvdb::FloatGrid>(*xform, mesh.points, mesh.triangles, 3.0f);
    } catch (const std::exception& e) {
        throw Error(path + ": cannot convert the mesh to a level set: " + e.what());
    }
    grid->setName(std::filesystem::path(path).filename().string());
    return std::make_shared<LevelSet>(grid, voxelSize, "mesh " + path);
}

} // namespace vdbclay
