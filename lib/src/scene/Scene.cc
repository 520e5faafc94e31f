// Scene files: JSON (nlohmann/json, header-only, so no hand-written parser) to Scene.
#include "vdbclay/Scene.h"

#include "vdbclay/MemoryBudget.h"

#include "core/InputFile.h"

#include <nlohmann/json.hpp>

#include <algorithm>
#include <array>
#include <cctype>
#include <cstring>
#include <cmath>
#include <cstdio>
#include <climits>
#include <optional>
#include <sstream>

namespace vdbclay {

namespace {

using nlohmann::json;

/// Positions and movements stay within +-2^30 voxels, the range of shape bounds (Shapes.h).
constexpr double kMaxCoordinate = double(1 << 30);
/// A tool turns at most this many degrees about an axis over its whole path.
constexpr double kMaxRotationDeg = 1e9;
/// Scene files are small; a larger one is a mistake (or /dev/zero), refused before it fills memory.
constexpr uint64_t kMaxSceneBytes = uint64_t(16) << 20;

struct Ctx {
    std::string source;
    std::string baseDir;
    int dims = 3;
    double voxelSize = 1.0;
    UpAxis up = UpAxis::Y;
    uint64_t meshBudget = kNoMemoryBudget; ///< for meshes: the scene's memory_budget, else the default

    [[noreturn]] void fail(const std::string& field, const std::string& what) const
    {
        throw Error(source + ": " + (field.empty() ? std::string() : field + ": ") + what);
    }

    std::string typeName(const json& v) const { return v.type_name(); }

    void keys(const json& obj, const std::string& field, std::initializer_list<const char*> allowed) const
    {
        if (!obj.is_object()) fail(field, std::string("expected an object, got ") + obj.type_name());
        for (auto it = obj.begin(); it != obj.end(); ++it) {
            bool ok = false;
            for (const char* a : allowed)
                ok |= (it.key() == a);
            if (!ok) {
                std::string list;
                for (const char* a : allowed)
                    list += (list.empty() ? "" : ", ") + std::string(a);
                fail(join(field, it.key()), "unknown field (expected one of: " + list + ")");
            }
        }
    }

    static std::string join(const std::string& field, const std::string& key)
    {
        return field.empty() ? key : field + "." + key;
    }

    const json* find(const json& obj, const char* key) const
    {
        auto it = obj.find(key);
        return it == obj.end() ? nullptr : &*it;
    }
    const json& need(const json& obj, const std::string& field, const char* key) const
    {
        const json* v = find(obj, key);
        if (!v) fail(field, std::string("missing field \"") + key + "\"");
        return *v;
    }

    double number(const json& v, const std::string& field) const
    {
        if (!v.is_number()) fail(field, std::string("expected a number, got ") + v.type_name());
        const double d = v.get<double>();
        if (!std::isfinite(d)) fail(field, "expected a finite number");
        return d;
    }
    int64_t integer(const json& v, const std::string& field, int64_t lo, int64_t hi) const
    {
        if (!v.is_number()) fail(field, std::string("expected an integer, got ") + v.type_name());
        if (v.is_number_float()) {
            const double d = v.get<double>();
            if (!std::isfinite(d) || d != std::floor(d)) fail(field, "expected an integer, got " + v.dump());
            if (d < double(lo) || d > double(hi)) fail(field, range(lo, hi, v.dump()));
            return int64_t(d);
        }
        if (v.is_number_unsigned()) {
            const uint64_t u = v.get<uint64_t>();
            if (u > uint64_t(hi) || (lo > 0 && u < uint64_t(lo))) fail(field, range(lo, hi, v.dump()));
            return int64_t(u);
        }
        const int64_t i = v.get<int64_t>();
        if (i < lo || i > hi) fail(field, range(lo, hi, v.dump()));
        return i;
    }
    static std::string range(int64_t lo, int64_t hi, const std::string& got)
    {
        return "expected an integer in [" + std::to_string(lo) + ", " + std::to_string(hi) + "], got " + got;
    }
    /// A string field; "" is refused (it would silently mean "none").
    std::string string(const json& v, const std::string& field) const
    {
        if (!v.is_string()) fail(field, std::string("expected a string, got ") + v.type_name());
        if (v.get_ref<const std::string&>().empty()) fail(field, "expected a non-empty string, got \"\"");
        return v.get<std::string>();
    }
    /// A free-text field (description, comment, name): any string, nothing else.
    void text(const json& obj, const char* key, const std::string& field) const
    {
        const json* v = find(obj, key);
        if (v && !v->is_string())
            fail(join(field, key), std::string("expected a string, got ") + v->type_name());
    }
    /// A coordinate (a position, or a movement summed over a path) within the range shapes allow.
    void coordinate(double v, const std::string& field, const std::string& what) const
    {
        if (!(std::fabs(v) <= kMaxCoordinate)) {
            fail(field, what + " must lie within +-2^30 voxels, got " + num(v));
        }
    }
    static std::string num(double v)
    {
        char buf[32];
        std::snprintf(buf, sizeof buf, "%.6g", v);
        return buf;
    }
    Vec3 vec3(const json& v, const std::string& field) const
    {
        if (!v.is_array() || (v.size() != 3 && !(dims == 2 && v.size() == 2))) {
            fail(field, std::string("expected an array of ") + (dims == 2 ? "2 or 3" : "3") +
                            " numbers, got " + v.dump());
        }
        Vec3 r{{0, 0, 0}};
        for (size_t i = 0; i < v.size(); ++i)
            r[i] = number(v[i], field + "[" + std::to_string(i) + "]");
        return r;
    }
    std::string path(const std::string& file) const
    {
        if (file.empty() || file[0] == '/' || baseDir.empty()) return file;
        return baseDir + "/" + file;
    }

    ShapeSpec shape(const json& obj, const std::string& field, bool forClay, bool forTool = false) const;

    /// A mesh's or level set's own "up" (its file's axes), else the scene's.
    UpAxis upOfFile(const json& obj, const std::string& field) const
    {
        const json* v = find(obj, "up");
        if (!v) return up;
        const std::string name = string(*v, join(field, "up"));
        try {
            return parseUpAxis(name);
        } catch (const Error& e) {
            fail(join(field, "up"), e.what());
        }
    }
};

ShapeSpec Ctx::shape(const json& obj, const std::string& field, bool forClay, bool forTool) const
{
    if (!obj.is_object()) fail(field, std::string("expected an object, got ") + obj.type_name());
    ShapeSpec s;
    s.field = field;
    s.kind = string(need(obj, field, "shape"), join(field, "shape"));
    // Fields every shape of a list may carry besides its geometry.
    text(obj, "name", field);
    text(obj, "comment", field);
    std::vector<const char*> extra;
    if (forClay)
        extra = {"mass", "transform"};
    else if (forTool)
        extra = {"path", "pivot", "transform", "action", "mass", "strength"};
    else
        extra = {"path", "pivot", "transform"};
    auto allowed = [&](std::initializer_list<const char*> geo) {
        std::vector<const char*> all{"shape", "name", "comment"};
        all.insert(all.end(), geo.begin(), geo.end());
        all.insert(all.end(), extra.begin(), extra.end());
        for (auto it = obj.begin(); it != obj.end(); ++it) {
            if (std::find_if(all.begin(), all.end(), [&](const char* a) { return it.key() == a; }) ==
                all.end()) {
                std::string list;
                for (const char* a : all)
                    list += (list.empty() ? "" : ", ") + std::string(a);
                fail(join(field, it.key()),
                     "unknown field for a " + s.kind + " (expected one of: " + list + ")");
            }
        }
    };
    auto wrap = [&](auto&& make) {
        try {
            return make();
        } catch (const Error& e) {
            fail(field, e.what());
        }
    };
    // A mesh is placed vertex by vertex before it becomes a level set (no resampling); other
    // shapes are wrapped (makePlaced).
    std::optional<Placement> place;
    if (const json* t = s.kind != "vdb" ? find(obj, "transform") : nullptr) {
        const std::string tf = join(field, "transform");
        keys(*t, tf, {"translate", "rotate", "scale", "pivot", "comment"});
        Placement pl;
        if (const json* v = find(*t, "translate")) pl.translate = vec3(*v, join(tf, "translate"));
        if (const json* v = find(*t, "rotate")) pl.rotateDeg = vec3(*v, join(tf, "rotate"));
        if (const json* v = find(*t, "pivot")) pl.pivot = vec3(*v, join(tf, "pivot"));
        if (const json* v = find(*t, "scale")) {
            if (v->is_number()) {
                const double k = number(*v, join(tf, "scale"));
                pl.scale = {{k, k, k}};
            } else {
                pl.scale = vec3(*v, join(tf, "scale"));
                if (v->size() == 2) pl.scale[2] = 1; // 2D: [sx, sy]
            }
            for (int i = 0; i < 3; ++i) {
                if (!(pl.scale[i] > 0)) fail(join(tf, "scale"), "must be > 0, got " + v->dump());
            }
        }
        place = pl;
    }
    if (s.kind == "sphere") {
        allowed({"center", "radius"});
        const Vec3 c = vec3(need(obj, field, "center"), join(field, "center"));
        const double r = number(need(obj, field, "radius"), join(field, "radius"));
        if (!(r > 0)) fail(join(field, "radius"), "must be > 0, got " + obj["radius"].dump());
        s.shape = wrap([&] { return makeSphere(c, r); });
    } else if (s.kind == "box") {
        allowed({"min", "max"});
        const Vec3 lo = vec3(need(obj, field, "min"), join(field, "min"));
        const Vec3 hi = vec3(need(obj, field, "max"), join(field, "max"));
        for (int i = 0; i < 3; ++i) {
            if (lo[i] > hi[i]) {
                fail(field, "min must not exceed max (axis " + std::to_string(i) + ": " + obj["min"].dump() +
                                " > " + obj["max"].dump() + ")");
            }
        }
        s.shape = wrap([&] { return makeBox(lo, hi); });
    } else if (s.kind == "cylinder") {
        allowed({"center", "radius", "height", "axis"});
        const Vec3 c = vec3(need(obj, field, "center"), join(field, "center"));
        const double r = number(need(obj, field, "radius"), join(field, "radius"));
        const double h = number(need(obj, field, "height"), join(field, "height"));
        if (!(r > 0)) fail(join(field, "radius"), "must be > 0, got " + obj["radius"].dump());
        if (!(h > 0)) fail(join(field, "height"), "must be > 0, got " + obj["height"].dump());
        int axis = 1;
        if (const json* a = find(obj, "axis")) {
            if (a->is_string()) {
                const std::string n = a->get<std::string>();
                if (n == "x")
                    axis = 0;
                else if (n == "y")
                    axis = 1;
                else if (n == "z")
                    axis = 2;
                else
                    fail(join(field, "axis"), "expected \"x\", \"y\", \"z\" or 0, 1, 2, got " + a->dump());
            } else {
                axis = int(integer(*a, join(field, "axis"), 0, 2));
            }
        }
        s.shape = wrap([&] { return makeCylinder(c, r, h, axis); });
    } else if (s.kind == "capsule") {
        allowed({"a", "b", "radius"});
        const Vec3 a = vec3(need(obj, field, "a"), join(field, "a"));
        const Vec3 b = vec3(need(obj, field, "b"), join(field, "b"));
        const double r = number(need(obj, field, "radius"), join(field, "radius"));
        if (!(r > 0)) fail(join(field, "radius"), "must be > 0, got " + obj["radius"].dump());
        s.shape = wrap([&] { return makeCapsule(a, b, r); });
    } else if (s.kind == "levelset") {
        allowed({"file", "grid", "up"});
        s.file = path(string(need(obj, field, "file"), join(field, "file")));
        if (const json* g = find(obj, "grid")) s.grid = string(*g, join(field, "grid"));
        const UpAxis fileUp = upOfFile(obj, field);
        // Loaded here, at the scene's voxel size, so a bad file is reported with its scene field.
        s.shape = wrap([&] { return loadLevelSet(s.file, voxelSize, s.grid, fileUp); });
    } else if (s.kind == "mesh") {
        allowed({"file", "up"});
        s.file = path(string(need(obj, field, "file"), join(field, "file")));
        const UpAxis fileUp = upOfFile(obj, field);
        // Bounds and the level set's size (placed) are checked before the mesh is voxelized.
        s.shape = wrap(
            [&] { return loadMesh(s.file, voxelSize, fileUp, place ? *place : Placement(), meshBudget); });
    } else if (s.kind == "vdb" && forClay) {
        extra.clear(); // exact masses come from the file
        allowed({"file", "grid"});
        s.file = path(string(need(obj, field, "file"), join(field, "file")));
        s.grid = "mass";
        if (const json* g = find(obj, "grid")) s.grid = string(*g, join(field, "grid"));
    } else {
        fail(join(field, "shape"), "unknown shape \"" + s.kind +
                                       "\" (expected one of: sphere, box, "
                                       "cylinder, capsule, levelset, mesh" +
                                       (forClay ? ", vdb" : "") + ")");
    }
    if (place && s.kind != "mesh") s.shape = wrap([&] { return makePlaced(s.shape, *place); });
    return s;
}

// ---- "units": "world" ---------------------------------------------------------------------------
// A scene in world units (the scene's up convention, e.g. Blender's coordinates as they are) is
// rewritten into voxel indices (y up) before it is read, field by field, so that everything after
// (checks, messages naming fields) is the same for both. Values of the wrong type are left as they
// are, for the reader to refuse.

/// R = Rz Ry Rx of Euler angles in degrees (x first), as the shapes' rotation() (ShapeMath.h).
std::array<Vec3, 3> eulerMatrix(const Vec3& deg)
{
    const double k = M_PI / 180.0;
    const double sx = std::sin(deg[0] * k), cx = std::cos(deg[0] * k), sy = std::sin(deg[1] * k),
                 cy = std::cos(deg[1] * k), sz = std::sin(deg[2] * k), cz = std::cos(deg[2] * k);
    return {{{{cz * cy, cz * sy * sx - sz * cx, cz * sy * cx + sz * sx}},
             {{sz * cy, sz * sy * sx + cz * cx, sz * sy * cx - cz * sx}},
             {{-sy, cy * sx, cy * cx}}}};
}

/// The Euler angles (degrees, x first) of rotation matrix @a m = Rz Ry Rx, each snapped to 1e-9
/// degree (a quarter turn stays exactly 90, which the shapes turn without rounding).
Vec3 eulerOf(const std::array<Vec3, 3>& m)
{
    const double k = 180.0 / M_PI;
    auto snap = [](double d) { return std::round(d * 1e9) / 1e9 + 0.0; };
    const double sy = std::max(-1.0, std::min(1.0, -m[2][0]));
    if (std::fabs(sy) > 1 - 1e-12) { // gimbal lock: x and z turn about one axis; put it all in z
        return {{0, snap(std::asin(sy) * k), snap(std::atan2(-m[0][1], m[1][1]) * k)}};
    }
    return {{snap(std::atan2(m[2][1], m[2][2]) * k), snap(std::asin(sy) * k),
             snap(std::atan2(m[1][0], m[0][0]) * k)}};
}

struct WorldUnits {
    const Ctx& cx;
    double vs;
    UpAxis up;

    /// The index axis of world axis @a a, and its sign (up z: x -> x, y -> -z, z -> y).
    int axisOf(int a) const { return up == UpAxis::Z ? (a == 1 ? 2 : (a == 2 ? 1 : 0)) : a; }
    double signOf(int a) const { return up == UpAxis::Z && a == 1 ? -1.0 : 1.0; }

    static bool isVec(const json* v)
    {
        if (!v || !v->is_array() || v->size() < 2 || v->size() > 3) return false;
        for (const json& x : *v)
            if (!x.is_number()) return false;
        return true;
    }
    static Vec3 get(const json& v)
    {
        Vec3 r{{0, 0, 0}};
        for (size_t i = 0; i < v.size(); ++i)
            r[i] = v[i].get<double>();
        return r;
    }
    static void set(json& v, const Vec3& r)
    {
        const size_t n = v.size();
        v = json::array();
        for (size_t i = 0; i < n; ++i)
            v.push_back(r[i]);
    }
    /// A position: divided by the voxel size and turned for up.
    void point(json& obj, const char* key) const
    {
        json* v = obj.is_object() && obj.contains(key) ? &obj[key] : nullptr;
        if (isVec(v)) set(*v, worldToIndex(get(*v), vs, up));
    }
    /// A length.
    void length(json& obj, const char* key) const
    {
        if (obj.is_object() && obj.contains(key) && obj[key].is_number())
            obj[key] = obj[key].get<double>() / vs;
    }
    /// Per-axis factors (a scale): moved to their index axes, unsigned.
    void perAxis(json& v) const
    {
        if (!isVec(&v) || v.size() != 3) return;
        const Vec3 w = get(v);
        Vec3 r{{1, 1, 1}};
        for (int a = 0; a < 3; ++a)
            r[axisOf(a)] = w[a];
        set(v, r);
    }
    /// A rotation (Euler degrees, x first, about world axes) as the same turn about index axes.
    void rotation(json& v) const
    {
        if (!isVec(&v) || up == UpAxis::Y) return;
        const Vec3 w = get(v);
        set(v, w[1] != 0 && w[2] != 0 ? eulerToIndex(w) : mapAngles(w));
    }
    /// The index-space Euler angles of world Euler angles @a w (degrees, x first).
    Vec3 eulerToIndex(const Vec3& w) const
    {
        const std::array<Vec3, 3> m0 = eulerMatrix(w);
        std::array<Vec3, 3> m{}; // index = P world: M_index = P M_world P^T, P[axisOf(a)][a] = signOf(a)
        for (int i = 0; i < 3; ++i)
            for (int j = 0; j < 3; ++j)
                m[axisOf(i)][axisOf(j)] = signOf(i) * signOf(j) * m0[i][j];
        return eulerOf(m);
    }
    /// World Euler angles that turn about x and at most one of y, z: the same turn about index axes
    /// is the angles moved to their index axes (x, y, z becomes x, z, y: still in order).
    Vec3 mapAngles(const Vec3& w) const
    {
        Vec3 r{{0, 0, 0}};
        for (int a = 0; a < 3; ++a)
            r[axisOf(a)] = signOf(a) * w[a];
        return r;
    }
    /// A path segment's turn per frame (degrees about world axes, x first), for up z. The tool's
    /// pose is its turn so far as one set of Euler angles (@a turned in world axes, @a pose in index
    /// axes), so the segment is rewritten for the index pose to follow the world pose: while the
    /// turn stays about x and at most one of y, z, its angles move axis by axis (exact at every
    /// frame); otherwise the pose at the segment's end is converted, which is exact at every frame
    /// only for a segment of one frame.
    void turnRate(json& seg, const std::string& field, Vec3& turned, Vec3& pose) const
    {
        json& v = seg["rotate"];
        if (!isVec(&v) || up == UpAxis::Y) return;
        double n = 1;
        if (seg.contains("frames")) {
            const json& f = seg["frames"];
            if (!f.is_number() || !(f.get<double>() >= 1)) return; // refused by the reader
            n = f.get<double>();
        }
        const Vec3 rate = get(v);
        Vec3 end;
        for (int a = 0; a < 3; ++a)
            end[a] = turned[a] + rate[a] * n;
        const Vec3 mappedSoFar = mapAngles(turned);
        const bool clean =
            ((turned[1] == 0 && end[1] == 0) || (turned[2] == 0 && end[2] == 0)) && pose == mappedSoFar;
        Vec3 r;
        if (clean) {
            r = mapAngles(rate);
            for (int a = 0; a < 3; ++a)
                pose[a] += r[a] * n;
        } else {
            if (n != 1) {
                cx.fail(field + ".frames",
                        "in world units with up z, a tool that has turned about both world y and z moves "
                        "along one-frame segments (its turn, about x, then y, then z, becomes a turn "
                        "about vdbclay's x, z, y, exact only at a segment's end); give one segment per "
                        "frame");
            }
            Vec3 poseEnd = eulerToIndex(end);
            for (int a = 0; a < 3; ++a) {
                poseEnd[a] += 360.0 * std::round((pose[a] - poseEnd[a]) / 360.0); // the nearest turn
                r[a] = poseEnd[a] - pose[a];
            }
            pose = poseEnd;
        }
        turned = end;
        set(v, r);
    }
    void transform(json& t) const
    {
        if (!t.is_object()) return;
        if (t.contains("translate") && isVec(&t["translate"])) {
            json& v = t["translate"];
            set(v, worldToIndex(get(v), vs, up));
        }
        point(t, "pivot");
        if (t.contains("rotate")) rotation(t["rotate"]);
        if (t.contains("scale")) perAxis(t["scale"]);
    }
    void shape(json& obj) const
    {
        if (!obj.is_object() || !obj.contains("shape") || !obj["shape"].is_string()) return;
        const std::string kind = obj["shape"].get<std::string>();
        if (kind == "sphere") {
            point(obj, "center");
            length(obj, "radius");
        } else if (kind == "box") {
            point(obj, "min");
            point(obj, "max");
            if (isVec(&obj["min"]) && isVec(&obj["max"]) && obj["min"].size() == obj["max"].size()) {
                Vec3 lo = get(obj["min"]), hi = get(obj["max"]); // a turn for up may swap them
                for (int a = 0; a < 3; ++a)
                    if (lo[a] > hi[a]) std::swap(lo[a], hi[a]);
                set(obj["min"], lo);
                set(obj["max"], hi);
            }
        } else if (kind == "cylinder") {
            point(obj, "center");
            length(obj, "radius");
            length(obj, "height");
            if (up == UpAxis::Z) {
                json& a = obj.contains("axis") ? obj["axis"] : (obj["axis"] = "z"); // world z: up
                if (a.is_string() && a.get<std::string>().size() == 1) {
                    const int w = std::string("xyz").find(a.get<std::string>()[0]);
                    if (w >= 0 && w < 3) a = std::string(1, "xyz"[axisOf(w)]);
                } else if (a.is_number_integer() && a.get<int64_t>() >= 0 && a.get<int64_t>() <= 2) {
                    a = axisOf(int(a.get<int64_t>()));
                }
            }
        } else if (kind == "capsule") {
            point(obj, "a");
            point(obj, "b");
            length(obj, "radius");
        }
        if (obj.contains("transform") && kind != "vdb") transform(obj["transform"]);
    }
    void tool(json& obj, const std::string& field) const
    {
        shape(obj);
        if (!obj.is_object()) return;
        point(obj, "pivot");
        if (!obj.contains("path") || !obj["path"].is_array()) return;
        json& path = obj["path"];
        Vec3 turned{{0, 0, 0}}, pose{{0, 0, 0}}; // the tool's turn so far: world and index Euler angles
        for (size_t k = 0; k < path.size(); ++k) {
            json& seg = path[k];
            if (!seg.is_object()) continue;
            if (seg.contains("translate") && isVec(&seg["translate"])) {
                json& v = seg["translate"];
                set(v, worldToIndex(get(v), vs, up));
            }
            if (seg.contains("rotate"))
                turnRate(seg, field + ".path[" + std::to_string(k) + "]", turned, pose);
        }
    }
    void scene(json& root) const
    {
        auto each = [&](const char* key, auto&& f) {
            if (!root.contains(key) || !root[key].is_array()) return;
            for (size_t i = 0; i < root[key].size(); ++i)
                f(root[key][i], std::string(key) + "[" + std::to_string(i) + "]");
        };
        each("clay", [&](json& o, const std::string&) { shape(o); });
        each("tools", [&](json& o, const std::string& f) { tool(o, f); });
        each("obstacles", [&](json& o, const std::string&) { shape(o); });
    }
};

/// In 2D only the z = 0 layer exists: a tool or obstacle that does not reach it would do nothing.
void requireInPlane(const Ctx& cx, const ShapeSpec& s, const std::string& field)
{
    if (!s.shape) return;
    const Box b = s.shape->bounds();
    bool reaches = !b.empty() && b.min[2] <= 0 && b.max[2] >= 0;
    // Bounds may be a voxel loose: look for a voxel centre at z = 0 inside the shape (when the
    // layer is too large to look at, the bounds decide).
    const uint64_t area =
        reaches ? uint64_t(int64_t(b.max[0]) - b.min[0] + 1) * uint64_t(int64_t(b.max[1]) - b.min[1] + 1) : 0;
    if (reaches && area <= (uint64_t(1) << 20)) {
        reaches = false;
        for (int32_t x = b.min[0]; x <= b.max[0] && !reaches; ++x)
            for (int32_t y = b.min[1]; y <= b.max[1] && !reaches; ++y)
                reaches = s.shape->distance(Vec3{{double(x), double(y), 0.0}}) < 0;
    }
    if (!reaches) {
        cx.fail(field, "a 2D scene happens in the z = 0 layer, but this " + s.kind + " holds no voxel there");
    }
}

/// A tool's "action" and the fields that belong to it: "mass" (add), "strength" (smooth).
void parseAction(const Ctx& cx, const json& obj, const std::string& f, int32_t threshold, ToolSpec& t)
{
    if (const json* v = cx.find(obj, "action")) {
        try {
            t.action = parseToolAction(cx.string(*v, f + ".action"));
        } catch (const Error& e) {
            cx.fail(f + ".action", e.what());
        }
    }
    const std::string name = toolActionName(t.action);
    if (const json* m = cx.find(obj, "mass")) {
        if (t.action != ToolAction::Add)
            cx.fail(f + ".mass", "only an \"add\" tool has a mass (this tool's action is \"" + name + "\")");
        if (m->is_number() && m->get<double>() <= 0) cx.fail(f + ".mass", "must be > 0, got " + m->dump());
        if (m->is_number() && m->get<double>() > double(INT32_MAX)) {
            cx.fail(f + ".mass", "exceeds the most clay a voxel holds (" + std::to_string(INT32_MAX) +
                                     "), got " + m->dump());
        }
        t.mass = int32_t(cx.integer(*m, f + ".mass", 1, INT32_MAX));
    } else if (t.action == ToolAction::Add) {
        t.mass = threshold;
    }
    if (const json* v = cx.find(obj, "strength")) {
        if (t.action != ToolAction::Smooth) {
            cx.fail(f + ".strength",
                    "only a \"smooth\" tool has a strength (this tool's action is \"" + name + "\")");
        }
        t.strength = cx.number(*v, f + ".strength");
        if (!(t.strength > 0 && t.strength <= 1))
            cx.fail(f + ".strength", "must lie in (0, 1], got " + v->dump());
    }
}

} // namespace

// ---- ToolSpec ----------------------------------------------------------------------------------

uint64_t ToolSpec::pathFrames() const
{
    uint64_t n = 0;
    for (const PathSegment& s : path)
        n += s.frames;
    return n;
}

Pose ToolSpec::poseAt(uint64_t frame) const
{
    Pose p;
    p.pivot = pivot;
    uint64_t left = frame;
    for (const PathSegment& s : path) {
        const uint64_t k = std::min(left, s.frames);
        for (int i = 0; i < 3; ++i) {
            p.translation[i] += s.translate[i] * double(k);
            p.rotationDeg[i] += s.rotateDeg[i] * double(k);
        }
        left -= k;
        if (!left) break;
    }
    return p;
}

// ---- parsing -----------------------------------------------------------------------------------

Scene parseScene(const std::string& text, const std::string& source, const std::string& baseDir,
                 uint64_t memoryBudget)
{
    Ctx cx;
    cx.source = source;
    cx.baseDir = baseDir;
    json root;
    // nlohmann keeps the last of duplicate keys; a scene that says "threshold" twice is refused.
    std::vector<std::vector<std::string>> keysSeen; // per open object, its keys so far
    const json::parser_callback_t noDuplicates = [&](int, json::parse_event_t event, json& parsed) {
        if (event == json::parse_event_t::object_start) {
            keysSeen.emplace_back();
        } else if (event == json::parse_event_t::object_end) {
            if (!keysSeen.empty()) keysSeen.pop_back();
        } else if (event == json::parse_event_t::key && !keysSeen.empty()) {
            const std::string& key = parsed.get_ref<const std::string&>();
            std::vector<std::string>& seen = keysSeen.back();
            if (std::find(seen.begin(), seen.end(), key) != seen.end()) {
                throw Error(source + ": " + key +
                            ": duplicate field (each field may appear once in an object)");
            }
            seen.push_back(key);
        }
        return true;
    };
    try {
        root = json::parse(text, noDuplicates);
    } catch (const json::exception& e) {
        // e.g. "[json.exception.parse_error.101] parse error at line 2, column 12: ..." or
        // "[json.exception.out_of_range.406] number overflow parsing '1e999'": keep what follows "] ".
        std::string what = e.what();
        const auto p = what.find("] ");
        throw Error(source + ": invalid JSON: " + (p == std::string::npos ? what : what.substr(p + 2)));
    }
    cx.keys(root, "",
            {"dimensions",     "voxel_size", "threshold", "rule",      "alpha", "seed",    "clay",
             "tools",          "obstacles",  "settle",    "frames",    "start", "outputs", "memory_budget",
             "description",    "comment",    "push",      "transport", "sweep", "up",      "units",
             "surface_tension"});
    cx.text(root, "description", "");
    cx.text(root, "comment", "");
    Scene sc;
    sc.source = source;
    if (const json* v = cx.find(root, "dimensions")) {
        sc.dimensions = int(cx.integer(*v, "dimensions", 2, 3));
    }
    cx.dims = sc.dimensions;
    if (const json* v = cx.find(root, "voxel_size")) {
        sc.voxelSize = cx.number(*v, "voxel_size");
        if (!(sc.voxelSize >= kMinVoxelSize && sc.voxelSize <= kMaxVoxelSize)) {
            cx.fail("voxel_size", "expected a number in [" + Ctx::num(kMinVoxelSize) + ", " +
                                      Ctx::num(kMaxVoxelSize) + "] (world units per voxel), got " +
                                      v->dump());
        }
    }
    cx.voxelSize = sc.voxelSize;
    if (const json* v = cx.find(root, "up")) {
        try {
            sc.up = parseUpAxis(cx.string(*v, "up"));
        } catch (const Error& e) {
            cx.fail("up", e.what());
        }
    }
    cx.up = sc.up;
    if (const json* v = cx.find(root, "units")) {
        const std::string units = cx.string(*v, "units");
        if (units != "voxels" && units != "world") {
            cx.fail("units", "expected \"voxels\" (voxel indices, y up) or \"world\" (world units in the "
                             "scene's up convention), got \"" +
                                 units + "\"");
        }
        if (units == "world") {
            if (sc.dimensions == 2 && sc.up == UpAxis::Z) {
                cx.fail("units", "a 2D scene in world units needs \"up\": \"y\" (its plane is x, y)");
            }
            WorldUnits{cx, sc.voxelSize, sc.up}.scene(root);
        }
    }
    // Meshes are voxelized as they are read, below: they get the scene's budget (a malformed one is
    // reported further down), or the default.
    cx.meshBudget = defaultMemoryBudget();
    if (const json* v = cx.find(root, "memory_budget")) {
        try {
            cx.meshBudget = v->is_string() ? parseByteSize(v->get<std::string>())
                                           : (v->is_number_unsigned() ? v->get<uint64_t>() : cx.meshBudget);
        } catch (const Error&) {
        }
    }
    if (memoryBudget != 0) cx.meshBudget = memoryBudget; // the caller's budget replaces the scene's
    if (const json* v = cx.find(root, "threshold")) {
        if (v->is_number() && v->get<double>() <= 0) cx.fail("threshold", "Tc must be > 0, got " + v->dump());
        sc.rule.threshold = int32_t(cx.integer(*v, "threshold", 1, INT32_MAX));
    }
    if (const json* v = cx.find(root, "rule")) {
        try {
            sc.rule.rule = parseRule(cx.string(*v, "rule"));
        } catch (const Error& e) {
            cx.fail("rule", e.what());
        }
    }
    if (const json* v = cx.find(root, "alpha")) {
        sc.rule.alpha = cx.number(*v, "alpha");
        if (!(sc.rule.alpha > 0 && sc.rule.alpha < 1)) {
            cx.fail("alpha", "must lie in the open interval (0, 1), got " + v->dump());
        }
    }
    if (const json* v = cx.find(root, "seed")) sc.seed = uint64_t(cx.integer(*v, "seed", 0, INT64_MAX));
    if (const json* v = cx.find(root, "push")) {
        try {
            sc.push = parsePushMode(cx.string(*v, "push"));
        } catch (const Error& e) {
            cx.fail("push", e.what());
        }
    }
    if (const json* v = cx.find(root, "transport")) {
        try {
            sc.transport = parseTransport(cx.string(*v, "transport"));
        } catch (const Error& e) {
            cx.fail("transport", e.what());
        }
    }
    if (const json* v = cx.find(root, "sweep")) {
        if (!v->is_boolean()) cx.fail("sweep", std::string("expected true or false, got ") + v->type_name());
        sc.sweep = v->get<bool>();
    }
    if (const json* v = cx.find(root, "surface_tension")) {
        sc.surfaceTension = cx.number(*v, "surface_tension");
        if (!(sc.surfaceTension >= 0 && sc.surfaceTension <= 1))
            cx.fail("surface_tension", "must lie in [0, 1] (0: off), got " + v->dump());
    }

    auto list = [&](const char* key) -> const json* {
        const json* v = cx.find(root, key);
        if (v && !v->is_array()) cx.fail(key, std::string("expected an array, got ") + v->type_name());
        return v;
    };
    if (const json* arr = list("clay")) {
        for (size_t i = 0; i < arr->size(); ++i) {
            const std::string f = "clay[" + std::to_string(i) + "]";
            ClaySpec c;
            c.shape = cx.shape((*arr)[i], f, true);
            if (c.shape.kind != "vdb") {
                const json& m = cx.need((*arr)[i], f, "mass");
                if (m.is_number() && m.get<double>() <= 0) {
                    cx.fail(f + ".mass", "must be > 0, got " + m.dump());
                }
                if (m.is_number() && m.get<double>() > double(INT32_MAX)) {
                    cx.fail(f + ".mass", "exceeds the most clay a voxel holds (" + std::to_string(INT32_MAX) +
                                             "), got " + m.dump());
                }
                c.mass = int32_t(cx.integer(m, f + ".mass", 1, INT32_MAX));
            }
            sc.clay.push_back(std::move(c));
        }
    }
    if (const json* arr = list("tools")) {
        for (size_t i = 0; i < arr->size(); ++i) {
            const std::string f = "tools[" + std::to_string(i) + "]";
            const json& obj = (*arr)[i];
            ToolSpec t;
            t.shape = cx.shape(obj, f, false, true);
            parseAction(cx, obj, f, sc.rule.threshold, t);
            const json* path = cx.find(obj, "path");
            if (!path)
                cx.fail(f, "missing field \"path\" (a tool moves; shapes that never move are obstacles)");
            if (!path->is_array())
                cx.fail(f + ".path", std::string("expected an array, got ") + path->type_name());
            if (path->empty()) cx.fail(f + ".path", "empty path: give at least one segment");
            double moved[3] = {0, 0, 0}, turned[3] = {0, 0, 0};
            for (size_t k = 0; k < path->size(); ++k) {
                const std::string pf = f + ".path[" + std::to_string(k) + "]";
                const json& seg = (*path)[k];
                cx.keys(seg, pf, {"translate", "rotate", "frames"});
                PathSegment s;
                if (const json* v = cx.find(seg, "translate")) s.translate = cx.vec3(*v, pf + ".translate");
                if (const json* v = cx.find(seg, "rotate")) s.rotateDeg = cx.vec3(*v, pf + ".rotate");
                if (const json* v = cx.find(seg, "frames"))
                    s.frames = uint64_t(cx.integer(*v, pf + ".frames", 1, 1000000));
                if (sc.dimensions == 2 && s.translate[2] != 0) {
                    cx.fail(pf + ".translate[2]",
                            "a 2D scene's tools move in the z = 0 plane, got " + Ctx::num(s.translate[2]));
                }
                if (sc.dimensions == 2 && (s.rotateDeg[0] != 0 || s.rotateDeg[1] != 0)) {
                    cx.fail(pf + ".rotate", "a 2D scene's tools turn about z only (rotate [0, 0, z]), got " +
                                                (*cx.find(seg, "rotate")).dump());
                }
                for (int a = 0; a < 3; ++a) {
                    moved[a] += std::fabs(s.translate[a]) * double(s.frames);
                    turned[a] += std::fabs(s.rotateDeg[a]) * double(s.frames);
                    const std::string idx = "[" + std::to_string(a) + "]";
                    cx.coordinate(moved[a], pf + ".translate" + idx,
                                  "the tool's movement along its path so far");
                    if (!(turned[a] <= kMaxRotationDeg)) {
                        cx.fail(pf + ".rotate" + idx, "the tool turns at most " + Ctx::num(kMaxRotationDeg) +
                                                          " degrees about an axis over its path, got " +
                                                          Ctx::num(turned[a]));
                    }
                }
                t.path.push_back(s);
            }
            if (sc.dimensions == 2) requireInPlane(cx, t.shape, f);
            if (const json* v = cx.find(obj, "pivot")) {
                t.pivot = cx.vec3(*v, f + ".pivot");
                for (int a = 0; a < 3; ++a)
                    cx.coordinate(t.pivot[a], f + ".pivot[" + std::to_string(a) + "]", "a pivot");
            } else {
                const Box b = t.shape.shape->bounds();
                for (int a = 0; a < 3; ++a)
                    t.pivot[a] = 0.5 * (double(b.min[a]) + double(b.max[a]));
            }
            sc.tools.push_back(std::move(t));
        }
    }
    if (const json* arr = list("obstacles")) {
        for (size_t i = 0; i < arr->size(); ++i) {
            const std::string f = "obstacles[" + std::to_string(i) + "]";
            const json& obj = (*arr)[i];
            if (obj.is_object() && obj.contains("path"))
                cx.fail(f + ".path", "obstacles never move; moving shapes are tools");
            ShapeSpec s = cx.shape(obj, f, false);
            if (sc.dimensions == 2) requireInPlane(cx, s, f);
            sc.obstacles.push_back(std::move(s));
        }
    }
    if (const json* v = cx.find(root, "settle")) {
        cx.keys(*v, "settle", {"max_steps", "tolerance"});
        if (const json* m = cx.find(*v, "max_steps"))
            sc.settle.maxSteps = uint64_t(cx.integer(*m, "settle.max_steps", 0, INT64_MAX));
        if (const json* t = cx.find(*v, "tolerance"))
            sc.settle.tolerance = cx.integer(*t, "settle.tolerance", 0, INT64_MAX);
    }
    uint64_t longest = 0;
    for (const ToolSpec& t : sc.tools)
        longest = std::max(longest, t.pathFrames());
    sc.frames = std::max<uint64_t>(longest, 1);
    if (const json* v = cx.find(root, "frames")) sc.frames = uint64_t(cx.integer(*v, "frames", 1, 100000000));
    if (const json* v = cx.find(root, "start")) {
        sc.start = cx.path(cx.string(*v, "start"));
        if (!sc.clay.empty()) {
            cx.fail("start",
                    "a scene starts either from a file (\"start\") or from \"clay\", not both; the start "
                    "file holds the clay (remove \"clay\", or \"start\")");
        }
    }
    if (const json* v = cx.find(root, "memory_budget")) {
        if (v->is_string()) {
            try {
                sc.memoryBudget = parseByteSize(v->get<std::string>());
            } catch (const Error& e) {
                cx.fail("memory_budget", e.what());
            }
        } else {
            sc.memoryBudget = uint64_t(cx.integer(*v, "memory_budget", 1, INT64_MAX));
        }
    }
    if (memoryBudget != 0) sc.memoryBudget = memoryBudget;
    if (const json* v = cx.find(root, "outputs")) {
        cx.keys(*v, "outputs", {"vdb", "png", "mesh", "stats", "grids"});
        auto out = [&](const char* k, std::string& dst) {
            if (const json* o = cx.find(*v, k)) dst = cx.string(*o, std::string("outputs.") + k);
        };
        out("vdb", sc.outputs.vdb);
        out("png", sc.outputs.png);
        out("mesh", sc.outputs.mesh);
        out("stats", sc.outputs.stats);
        if (const json* g = cx.find(*v, "grids")) {
            if (!g->is_array() || g->empty())
                cx.fail("outputs.grids",
                        std::string("expected a non-empty array of grid names (mass, density, "
                                    "surface), got ") +
                            (g->is_array() ? "[]" : g->type_name()));
            std::vector<std::string> names;
            for (size_t i = 0; i < g->size(); ++i) {
                const std::string field = "outputs.grids[" + std::to_string(i) + "]";
                names.push_back(cx.string((*g)[i], field));
                if (names.back().find(',') != std::string::npos) // a list where a name belongs
                    cx.fail(field, "\"" + names.back() +
                                       "\" is not a grid of a clay file (mass, density or surface)");
            }
            try {
                sc.outputs.grids = clayGridsOf(names);
            } catch (const Error& e) {
                cx.fail("outputs.grids", e.what());
            }
        }
    }
    return sc;
}

Scene loadScene(const std::string& path, uint64_t memoryBudget)
{
    // Any stream: "-" (standard input), a FIFO with its writer or process substitution (<(...)) is a
    // fine scene; a directory, a FIFO nobody writes, a device that never ends (/dev/zero) or a huge
    // file is not, and is refused at once or before it fills memory.
    const std::string text =
        io_internal::readStreamable(path, "scene file", kMaxSceneBytes, /*allowStdin=*/true);
    if (path == "-") return parseScene(text, "standard input", "", memoryBudget); // names relative to here
    const auto slash = path.find_last_of('/');
    const std::string base = slash == std::string::npos ? std::string() : path.substr(0, slash);
    return parseScene(text, path, base, memoryBudget);
}

const char* defaultSceneJson()
{
    return R"({
  "description": "A 32^3 cube of clay at 800 per voxel (Tc = 1000) pressed 8 voxels by a plate, on a floor",
  "dimensions": 3, "threshold": 1000, "rule": "prorata",
  "clay":  [{"shape": "box", "min": [0,0,0], "max": [31,31,31], "mass": 800}],
  "tools": [{"shape": "box", "min": [-8,32,-8], "max": [39,40,39], "path": [{"translate": [0,-1,0], "frames": 8}]}],
  "obstacles": [{"shape": "box", "min": [-64,-4,-64], "max": [96,-1,96]}],
  "settle": {"max_steps": 100000}
})";
}

Scene defaultScene()
{
    return parseScene(defaultSceneJson(), "<built-in scene>", "");
}

} // namespace vdbclay
