// Closed triangle meshes (OBJ, STL) as shapes: read, welded, checked, converted to a level set.

#include "vdbclay/Shapes.h"
#include "vdbclay/IO.h"
#include "vdbclay/MemoryBudget.h"

#include "shapes/Coverage.h"
#include "shapes/LevelSetShape.h"
#include "core/InputFile.h"
#include "core/TreeBytes.h"

#include <openvdb/openvdb.h>
#include <openvdb/tools/MeshToVolume.h>

#include <tbb/blocked_range.h>
#include <tbb/parallel_for.h>

#include <algorithm>
#include <cerrno>
#include <cmath>
#include <cstring>
#include <filesystem>
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

// PLY (Turk 1994; what `vdbclay mesh` writes, and Blender, MeshLab, Open3D, ...): ASCII or binary
// little endian; element "vertex" with float or double properties x, y, z (others skipped), element
// "face" with a list property vertex_indices (or vertex_index), polygons fanned into triangles; any
// other element is skipped. Written here rather than taken from a library: the format needs ~150
// lines, and Debian's candidates are heavy (assimp) or do not read the properties by name.
struct PlyProperty {
    std::string name, type; // type: scalar type, or the item type of a list
    std::string countType;  // non-empty for a list
};
struct PlyElement {
    std::string name;
    uint64_t count = 0;
    std::vector<PlyProperty> properties;
};

int plyTypeSize(const std::string& t)
{
    if (t == "char" || t == "uchar" || t == "int8" || t == "uint8") return 1;
    if (t == "short" || t == "ushort" || t == "int16" || t == "uint16") return 2;
    if (t == "int" || t == "uint" || t == "float" || t == "int32" || t == "uint32" || t == "float32")
        return 4;
    if (t == "double" || t == "float64") return 8;
    return 0;
}

/// One binary little-endian value of PLY type @a t at @a p, as a double.
double plyValue(const char* p, const std::string& t)
{
    auto get = [p](auto v) {
        std::memcpy(&v, p, sizeof v);
        return double(v);
    };
    if (t == "char" || t == "int8") return get(int8_t());
    if (t == "uchar" || t == "uint8") return get(uint8_t());
    if (t == "short" || t == "int16") return get(int16_t());
    if (t == "ushort" || t == "uint16") return get(uint16_t());
    if (t == "int" || t == "int32") return get(int32_t());
    if (t == "uint" || t == "uint32") return get(uint32_t());
    if (t == "float" || t == "float32") return get(float());
    return get(double());
}

void readPly(const std::string& path, const std::string& data, Mesh& mesh)
{
    // The header: lines up to "end_header".
    size_t pos = 0, line = 0;
    auto nextLine = [&](std::string& out) {
        if (pos >= data.size()) return false;
        size_t e = data.find('\n', pos);
        if (e == std::string::npos) e = data.size();
        out = data.substr(pos, e - pos);
        if (!out.empty() && out.back() == '\r') out.pop_back();
        pos = std::min(e + 1, data.size()); // the last line may have no newline
        ++line;
        return true;
    };
    std::string l;
    if (!nextLine(l) || l != "ply") malformed(path, 1, "a PLY file starts with the line \"ply\"");
    std::string format;
    std::vector<PlyElement> elements;
    bool ended = false;
    while (nextLine(l)) {
        const std::vector<std::string> t = tokens(l);
        if (t.empty() || t[0] == "comment" || t[0] == "obj_info") continue;
        if (t[0] == "end_header") {
            ended = true;
            break;
        }
        if (t[0] == "format") {
            if (t.size() != 3) malformed(path, line, "expected \"format ascii|binary_little_endian 1.0\"");
            format = t[1];
            if (format != "ascii" && format != "binary_little_endian") {
                malformed(path, line,
                          "PLY format \"" + format +
                              "\" is not read (ascii or binary_little_endian; convert it, e.g. "
                              "in MeshLab or Blender)");
            }
        } else if (t[0] == "element") {
            long n = 0;
            if (t.size() != 3 || !parseLong(t[2], n) || n < 0)
                malformed(path, line, "expected \"element NAME COUNT\"");
            elements.push_back({t[1], uint64_t(n), {}});
        } else if (t[0] == "property") {
            if (elements.empty()) malformed(path, line, "a property before any element");
            PlyProperty p;
            if (t.size() == 5 && t[1] == "list") {
                p.countType = t[2];
                p.type = t[3];
                p.name = t[4];
                if (plyTypeSize(p.countType) == 0 || plyTypeSize(p.type) == 0 || p.countType == "float" ||
                    p.countType == "double" || p.countType == "float32" || p.countType == "float64")
                    malformed(path, line, "bad list types \"" + t[2] + " " + t[3] + "\"");
            } else if (t.size() == 3) {
                p.type = t[1];
                p.name = t[2];
                if (plyTypeSize(p.type) == 0) malformed(path, line, "unknown property type \"" + t[1] + "\"");
            } else {
                malformed(path, line, "expected \"property TYPE NAME\" or \"property list COUNT ITEM NAME\"");
            }
            elements.back().properties.push_back(p);
        } else {
            malformed(path, line, "unexpected \"" + t[0] + "\" in a PLY header");
        }
    }
    if (!ended) malformed(path, line, "the PLY header has no end_header");
    if (format.empty()) malformed(path, line, "the PLY header has no format line");

    Welder weld(mesh);
    std::vector<uint32_t> vertexIds;
    bool sawVertex = false, sawFace = false;
    const bool ascii = format == "ascii";
    size_t bin = pos; // binary: the byte after the header
    std::istringstream text(ascii ? data.substr(pos) : std::string());
    for (const PlyElement& e : elements) {
        int ix = -1, iy = -1, iz = -1, iv = -1;
        for (size_t i = 0; i < e.properties.size(); ++i) {
            const PlyProperty& p = e.properties[i];
            if (p.countType.empty() && p.name == "x") ix = int(i);
            if (p.countType.empty() && p.name == "y") iy = int(i);
            if (p.countType.empty() && p.name == "z") iz = int(i);
            if (!p.countType.empty() && (p.name == "vertex_indices" || p.name == "vertex_index")) iv = int(i);
        }
        const bool isVertex = e.name == "vertex", isFace = e.name == "face";
        if (isVertex && (ix < 0 || iy < 0 || iz < 0))
            throw Error(path + ": element \"vertex\" has no scalar properties x, y and z");
        if (isFace && iv < 0) throw Error(path + ": element \"face\" has no list property vertex_indices");
        sawVertex |= isVertex;
        if (isFace && !sawVertex) throw Error(path + ": element \"face\" comes before element \"vertex\"");
        sawFace |= isFace;
        std::vector<double> scalars(e.properties.size());
        std::vector<uint32_t> face;
        for (uint64_t item = 0; item < e.count; ++item) {
            face.clear();
            std::vector<std::string> t;
            size_t next = 0;
            if (ascii) {
                std::string raw;
                do {
                    if (!std::getline(text, raw))
                        throw Error(path + ": element \"" + e.name + "\" ends after " + std::to_string(item) +
                                    " of " + std::to_string(e.count) + " items (truncated?)");
                    ++line;
                    t = tokens(raw);
                } while (t.empty());
            }
            const std::string where = "element \"" + e.name + "\" item " + std::to_string(item);
            auto value = [&](const std::string& type) {
                if (ascii) {
                    double v;
                    if (next >= t.size())
                        throw Error(path + ":" + std::to_string(line) + ": " + where + ": too few values");
                    if (!parseDouble(t[next++], v))
                        throw Error(path + ":" + std::to_string(line) + ": " + where + ": bad number \"" +
                                    t[next - 1] + "\"");
                    return v;
                }
                const int size = plyTypeSize(type);
                if (bin + size > data.size())
                    throw Error(path + ": " + where + ": the file ends inside it (truncated?)");
                const double v = plyValue(data.data() + bin, type);
                bin += size;
                return v;
            };
            for (size_t i = 0; i < e.properties.size(); ++i) {
                const PlyProperty& p = e.properties[i];
                if (p.countType.empty()) {
                    scalars[i] = value(p.type);
                    continue;
                }
                const double n = value(p.countType);
                if (!(n >= 0) || n > 1e6) throw Error(path + ": " + where + ": bad list length");
                for (int64_t k = 0; k < int64_t(n); ++k) {
                    const double v = value(p.type);
                    if (isFace && int(i) == iv) {
                        if (!(v >= 0) || v >= double(vertexIds.size()) || v != std::floor(v))
                            throw Error(path + ": " + where + ": vertex index " + num(v) + " out of range (" +
                                        std::to_string(vertexIds.size()) + " vertices)");
                        face.push_back(vertexIds[size_t(v)]);
                    }
                }
            }
            if (isVertex) {
                for (double c : {scalars[ix], scalars[iy], scalars[iz]})
                    if (!std::isfinite(c)) throw Error(path + ": " + where + " has a non-finite coordinate");
                vertexIds.push_back(
                    weld.add(openvdb::Vec3s(float(scalars[ix]), float(scalars[iy]), float(scalars[iz]))));
            } else if (isFace) {
                if (face.size() < 3) throw Error(path + ": " + where + ": a face needs at least 3 vertices");
                for (size_t i = 1; i + 1 < face.size(); ++i)
                    addTriangle(mesh, face[0], face[i], face[i + 1]);
            }
        }
    }
    if (!sawVertex) throw Error(path + ": no element \"vertex\" in the PLY header");
    if (!sawFace) throw Error(path + ": no element \"face\" in the PLY header (a point cloud is not a mesh)");
}

std::string lowerExtension(const std::string& path)
{
    std::string e = std::filesystem::path(path).extension().string();
    std::transform(e.begin(), e.end(), e.begin(), [](unsigned char c) { return char(std::tolower(c)); });
    return e;
}

/// OBJ text by its content, for a name without the extension (a pipe: /dev/fd/63): its first
/// statement (past comments and blank lines) is one OBJ defines, and it has a vertex and a face.
bool looksLikeObj(const std::string& data)
{
    if (data.find('\0') != std::string::npos) return false;
    size_t at = 0;
    while (at < data.size()) {
        const size_t end = std::min(data.find('\n', at), data.size());
        const std::string line = data.substr(at, end - at);
        at = end + 1;
        const size_t first = line.find_first_not_of(" \t\r");
        if (first == std::string::npos || line[first] == '#') continue;
        const std::string word = line.substr(first, line.find_first_of(" \t\r", first) - first);
        static const char* const kStatements[] = {"v", "vt", "vn",     "vp",     "f", "o",
                                                  "g", "s",  "mtllib", "usemtl", "l"};
        if (std::find(std::begin(kStatements), std::end(kStatements), word) == std::end(kStatements))
            return false;
        break;
    }
    return (data.compare(0, 2, "v ") == 0 || data.find("\nv ") != std::string::npos) &&
           (data.compare(0, 2, "f ") == 0 || data.find("\nf ") != std::string::npos);
}

/// The mesh's undirected edges by how many triangles they bound.
struct EdgeCounts {
    size_t open = 0;        ///< edges of an odd number of triangles (rims of holes)
    size_t nonManifold = 0; ///< edges of more than two triangles (closed when even)
};
EdgeCounts countEdges(const Mesh& m)
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
    EdgeCounts n;
    for (const auto& e : count) {
        if (e.second % 2 != 0) ++n.open;
        if (e.second > 2) ++n.nonManifold;
    }
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

/// Checks the placed mesh before meshToLevelSet: its vertices (index space) within +-2^30 voxels,
/// and the level set's band within @a budget bytes (UINT64_MAX: no limit). meshToLevelSet builds a
/// float distance and an Int32 index grid over the band, each in partial copies by the worker
/// threads that are then merged (counted three times), over the surface of the vertices' bounding
/// box, 6 voxels thick.
void checkMeshFits(const std::string& path, const std::vector<Vec3>& indexPoints, double voxelSize,
                   uint64_t budget)
{
    double lo[3] = {HUGE_VAL, HUGE_VAL, HUGE_VAL}, hi[3] = {-HUGE_VAL, -HUGE_VAL, -HUGE_VAL};
    for (const Vec3& p : indexPoints)
        for (int a = 0; a < 3; ++a) {
            lo[a] = std::min(lo[a], p[a]);
            hi[a] = std::max(hi[a], p[a]);
        }
    double side[3];
    for (int a = 0; a < 3; ++a) {
        if (!(std::fabs(lo[a]) <= double(1 << 30)) || !(std::fabs(hi[a]) <= double(1 << 30))) {
            char buf[160];
            std::snprintf(buf, sizeof buf, "%.6g .. %.6g voxels along axis %d (at voxel size %g)", lo[a],
                          hi[a], a, voxelSize);
            throw Error(path + ": the mesh spans " + buf + ", outside the coordinate range +-2^30");
        }
        side[a] = hi[a] - lo[a] + 1;
    }
    if (budget == UINT64_MAX) return;
    using tree_bytes::leafBytes;
    const double bandVoxels = 2 * (side[0] * side[1] + side[1] * side[2] + side[0] * side[2]) * 6;
    const double bytes =
        3 * bandVoxels / 512 * double(leafBytes<openvdb::FloatTree>() + leafBytes<openvdb::Int32Tree>());
    if (bytes > double(budget)) {
        char surface[96];
        std::snprintf(surface, sizeof surface, " (a surface of about %.3g voxels at voxel size %g)",
                      bandVoxels / 6, voxelSize);
        throw Error(path + ": turning the mesh into a level set needs about " +
                    formatBytes(uint64_t(std::min(bytes, 9e18))) + surface +
                    ", more than the memory budget of " + formatBytes(budget) +
                    "; use a larger voxel size or raise the budget");
    }
}

/// The triangles of the mesh file @a path (OBJ, STL, PLY), read whole within @a budget bytes.
Mesh readMeshFile(const std::string& path, uint64_t budget)
{
    // Read whole (a pipe or process substitution is fine); the mesh's bytes count against the budget.
    const std::string data = io_internal::readStreamable(path, "mesh", budget);
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
    if (ext == ".obj" || (ext != ".stl" && ext != ".ply" && looksLikeObj(data))) {
        readObj(path, text, mesh);
    } else if (ext == ".ply" || data.compare(0, 4, "ply\n") == 0 || data.compare(0, 5, "ply\r\n") == 0) {
        readPly(path, data, mesh);
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
        throw Error(path + ": unknown mesh format (expected .obj, .stl or .ply)");
    }
    if (mesh.triangles.empty()) throw Error(path + ": the mesh has no faces");
    return mesh;
}

} // namespace

std::array<Vec3, 2> meshFileBounds(const std::string& path, uint64_t memoryBudget)
{
    const Mesh mesh = readMeshFile(path, memoryBudget ? memoryBudget : defaultMemoryBudget());
    std::array<Vec3, 2> b{{{{HUGE_VAL, HUGE_VAL, HUGE_VAL}}, {{-HUGE_VAL, -HUGE_VAL, -HUGE_VAL}}}};
    for (const openvdb::Vec3s& p : mesh.points) {
        for (int i = 0; i < 3; ++i) {
            b[0][i] = std::min(b[0][i], double(p[i]));
            b[1][i] = std::max(b[1][i], double(p[i]));
        }
    }
    return b;
}

ShapePtr loadMesh(const std::string& path, double voxelSize, UpAxis up, const Placement& placement,
                  uint64_t memoryBudget)
{
    requireVoxelSize(voxelSize, "loadMesh(" + path + ")");
    const uint64_t budget = memoryBudget ? memoryBudget : defaultMemoryBudget();
    Mesh mesh = readMeshFile(path, budget);
    // Open (edges of an odd number of faces: rims of holes) or non-manifold (edges of 4, 6, ...
    // faces) meshes cannot be filled by meshToLevelSet's flood fill: their inside is decided by the
    // generalized winding number instead, and describe() says so.
    const EdgeCounts edges = countEdges(mesh);
    const size_t open = edges.open, nonManifold = edges.nonManifold;
    // Into the clay's index space (voxel size, up axis), then placed: the level set is built from
    // the placed vertices, so scaling costs no resolution.
    std::string placed;
    if (!placement.isIdentity()) {
        requireValidPlacement(placement);
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
    checkMeshFits(path, indexPoints, voxelSize, budget);
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
