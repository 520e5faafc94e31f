// Closed triangle meshes (OBJ, STL) as shapes: read, welded, checked, converted to a level set.

#include "vdbclay/Shapes.h"

#include "Coverage.h"
#include "LevelSetShape.h"

#include <openvdb/openvdb.h>
#include <openvdb/tools/MeshToVolume.h>

#include <tbb/blocked_range.h>
#include <tbb/parallel_for.h>

#include <algorithm>
#include <cerrno>
#include <cmath>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <map>
#include <sstream>
#include <tuple>
#include <unordered_map>

namespace vdbclay {

using namespace shapes_internal;

namespace {

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

/// Number of undirected edges bounding an odd number of triangles (boundary edges of holes).
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
    // Closed means every edge bounds an even number of faces: 2 (manifold) or 4, 6, ... (closed but
    // non-manifold, e.g. two boxes sharing an edge, which meshToLevelSet fills correctly).
    size_t open = 0;
    for (const auto& e : count)
        if (e.second % 2 != 0) ++open;
    return open;
}

/// Number of edges bounding more than two triangles (non-manifold edges; closed if even).
size_t nonManifoldEdges(const Mesh& m)
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
    size_t n = 0;
    for (const auto& e : count)
        if (e.second > 2) ++n;
    return n;
}

/// The generalized winding number of the triangles at @a p (Jacobson, Kavan, Sorkine-Hornung 2013):
/// the sum of the solid angles the triangles subtend at p over 4 pi (Van Oosterom and Strackee's
/// formula). 1 inside a closed outward-wound mesh, 0 outside, in between near the holes of an open
/// one; -1 inside an inside-out mesh.
double windingNumber(const Mesh& m, const openvdb::Vec3d& p)
{
    double sum = 0;
    for (const auto& t : m.triangles) {
        const openvdb::Vec3d a = openvdb::Vec3d(m.points[t[0]]) - p, b = openvdb::Vec3d(m.points[t[1]]) - p,
                             c = openvdb::Vec3d(m.points[t[2]]) - p;
        const double la = a.length(), lb = b.length(), lc = c.length();
        const double num = a.dot(b.cross(c));
        const double den = la * lb * lc + a.dot(b) * lc + b.dot(c) * la + c.dot(a) * lb;
        sum += 2 * std::atan2(num, den);
    }
    return sum / (4 * M_PI);
}

/// The level set of a mesh whose inside meshToLevelSet cannot decide by flood fill (open, or closed
/// with non-manifold edges): distances from @a band (the unsigned narrow band, clamped to its
/// width), signs from the generalized winding number (|w| > 0.5 is inside), at every grid point of
/// the mesh's bounds. O(points x triangles), computed once, in parallel.
openvdb::FloatGrid::Ptr windingLevelSet(const Mesh& m, const openvdb::FloatGrid& band,
                                        const std::string& path, bool& anyInside)
{
    openvdb::CoordBBox bb;
    for (const auto& p : m.points) {
        bb.expand(
            openvdb::Coord(int32_t(std::floor(p[0])), int32_t(std::floor(p[1])), int32_t(std::floor(p[2]))));
        bb.expand(
            openvdb::Coord(int32_t(std::ceil(p[0])), int32_t(std::ceil(p[1])), int32_t(std::ceil(p[2]))));
    }
    bb.expand(2);
    const openvdb::Coord dim = bb.dim();
    const uint64_t n = uint64_t(dim.x()) * uint64_t(dim.y()) * uint64_t(dim.z());
    if (n * m.triangles.size() > (uint64_t(1) << 36)) {
        throw Error(path +
                    ": the mesh is open or non-manifold, and deciding its inside by winding numbers "
                    "would take " +
                    std::to_string(n) + " points x " + std::to_string(m.triangles.size()) +
                    " triangles; close it first, or use a larger voxel size");
    }
    const float width = band.background();
    std::vector<float> values(n);
    tbb::parallel_for(tbb::blocked_range<int32_t>(0, dim.x()), [&](const tbb::blocked_range<int32_t>& r) {
        auto acc = band.getConstAccessor();
        for (int32_t i = r.begin(); i < r.end(); ++i)
            for (int32_t j = 0; j < dim.y(); ++j)
                for (int32_t k = 0; k < dim.z(); ++k) {
                    const openvdb::Coord c = bb.min() + openvdb::Coord(i, j, k);
                    const float d = std::min(std::abs(acc.getValue(c)), width);
                    // Strictly above one half: points on the surface (w = 1/2) are not inside.
                    const bool inside = std::abs(windingNumber(m, c.asVec3d())) > 0.5;
                    values[(uint64_t(i) * dim.y() + j) * dim.z() + k] = inside ? -d : d;
                }
    });
    auto grid = openvdb::FloatGrid::create(width);
    grid->setGridClass(openvdb::GRID_LEVEL_SET);
    auto acc = grid->getAccessor();
    anyInside = false;
    for (int32_t i = 0; i < dim.x(); ++i)
        for (int32_t j = 0; j < dim.y(); ++j)
            for (int32_t k = 0; k < dim.z(); ++k) {
                const float v = values[(uint64_t(i) * dim.y() + j) * dim.z() + k];
                if (v < 0) anyInside = true;
                if (v != width) acc.setValue(bb.min() + openvdb::Coord(i, j, k), v);
            }
    return grid;
}

/// A mesh: inside and distance from its level set (or winding-number level set); the clay it makes
/// keeps its volume exactly (Coverage.h) when it is closed and consistently oriented, else by the
/// level set's distance (forEachVoxelCovered).
class MeshShape final : public Shape {
public:
    MeshShape(std::shared_ptr<const LevelSet> levelSet, std::vector<Vec3> points,
              std::vector<std::array<uint32_t, 3>> triangles)
        : mLevelSet(std::move(levelSet)), mPoints(std::move(points)), mTriangles(std::move(triangles))
    {
        mOriented = isOrientedClosed(mTriangles);
    }
    double distance(const Vec3& p) const override { return mLevelSet->distance(p); }
    Vec3 normal(const Vec3& p) const override { return mLevelSet->normal(p); }
    Box bounds() const override { return mLevelSet->bounds(); }
    std::string describe() const override { return mLevelSet->describe(); }
    bool keepsVolume() const override { return true; }
    bool coverage(int dimensions,
                  const std::function<void(int32_t, int32_t, int32_t, double)>& covered) const override
    {
        if (dimensions != 3 || !mOriented) return false;
        meshCoverage(mPoints, mTriangles, covered);
        return true;
    }

private:
    std::shared_ptr<const LevelSet> mLevelSet;
    std::vector<Vec3> mPoints;
    std::vector<std::array<uint32_t, 3>> mTriangles;
    bool mOriented = false;
};

} // namespace

ShapePtr loadMesh(const std::string& path, double voxelSize, UpAxis up, const Placement& placement)
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
    // Open (edges of an odd number of faces: rims of holes) or non-manifold (edges of 4, 6, ...
    // faces) meshes cannot be filled by meshToLevelSet's flood fill: their inside is decided by the
    // generalized winding number instead, and describe() says so.
    const size_t open = openEdges(mesh), nonManifold = nonManifoldEdges(mesh);
    // Into the clay's index space (voxel size, up axis), then placed: the level set is built from
    // the placed vertices, so scaling costs no resolution.
    std::string placed;
    if (!placement.isIdentity()) {
        requireFinite(placement.translate, "transform", "translate");
        requireFinite(placement.rotateDeg, "transform", "rotate");
        requireFinite(placement.pivot, "transform", "pivot");
        for (int i = 0; i < 3; ++i) {
            if (!std::isfinite(placement.scale[i]) || !(placement.scale[i] > 0)) {
                throw Error("transform: scale[" + std::to_string(i) + "] must be finite and > 0, got " +
                            num(placement.scale[i]));
            }
        }
        placed = " placed (scale " + vecStr(placement.scale) + ", rotate " + vecStr(placement.rotateDeg) +
                 ", translate " + vecStr(placement.translate) + ", pivot " + vecStr(placement.pivot) + ")";
    }
    std::vector<Vec3> indexPoints;
    indexPoints.reserve(mesh.points.size());
    for (auto& p : mesh.points) {
        const Vec3 q = placement.apply(worldToIndex(Vec3{{p[0], p[1], p[2]}}, voxelSize, up));
        indexPoints.push_back(q);
        p = openvdb::Vec3s(float(q[0]), float(q[1]), float(q[2]));
    }
    openvdb::initialize();
    openvdb::FloatGrid::Ptr grid;
    try {
        auto xform = openvdb::math::Transform::createLinearTransform(1.0);
        grid = openvdb::tools::meshToLevelSet<openvdb::FloatGrid>(*xform, mesh.points, mesh.triangles, 3.0f);
    } catch (const std::exception& e) {
        throw Error(path + ": cannot convert the mesh to a level set: " + e.what());
    }
    std::string how;
    if (open || nonManifold) {
        bool anyInside = false;
        try {
            grid = windingLevelSet(mesh, *grid, path, anyInside);
        } catch (const Error&) {
            throw;
        } catch (const std::exception& e) {
            throw Error(path + ": cannot fill the mesh: " + e.what());
        }
        how = open ? " (open: " + std::to_string(open) +
                         " open edges, closed by the generalized winding number)"
                   : " (closed, " + std::to_string(nonManifold) +
                         " non-manifold edges: inside by the generalized winding number)";
        if (!anyInside) {
            throw Error(path + ": the mesh" + how +
                        " encloses no volume (winding number at most 0.5 everywhere)");
        }
    }
    grid->setName(std::filesystem::path(path).filename().string());
    std::vector<std::array<uint32_t, 3>> triangles;
    triangles.reserve(mesh.triangles.size());
    for (const auto& t : mesh.triangles)
        triangles.push_back({{t[0], t[1], t[2]}});
    return std::make_shared<MeshShape>(std::make_shared<LevelSet>(grid, 1.0, "mesh " + path + how + placed),
                                       std::move(indexPoints), std::move(triangles));
}

} // namespace vdbclay
