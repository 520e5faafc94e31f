// Shapes: analytic SDFs, poses, level sets and meshes.
#include <vdbclay/Automaton.h>
#include <vdbclay/Metrics.h>
#include <vdbclay/Push.h>
#include <vdbclay/Shapes.h>

#include <openvdb/openvdb.h>
#include <openvdb/io/File.h>
#include <openvdb/tools/LevelSetSphere.h>

#include <gtest/gtest.h>

#include "shapes/InsideBox.h" // shapes_internal::insideVoxelBox

#include <climits>
#include <cmath>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <string>
#include <vector>

using namespace vdbclay;
using openvdb::Coord;
using openvdb::CoordBBox;

namespace {

class ShapesTest : public ::testing::Test {
protected:
    static void SetUpTestSuite() { openvdb::initialize(); }

    void SetUp() override
    {
        const auto* info = ::testing::UnitTest::GetInstance()->current_test_info();
        mDir = std::filesystem::temp_directory_path() /
               ("vdbclay_shapes_" + std::to_string(::getpid()) + "_" + info->name());
        std::filesystem::remove_all(mDir);
        std::filesystem::create_directories(mDir);
    }
    void TearDown() override { std::filesystem::remove_all(mDir); }

    std::string file(const std::string& name, const std::string& content) const
    {
        const std::string p = (mDir / name).string();
        std::ofstream(p, std::ios::binary) << content;
        return p;
    }
    std::string path(const std::string& name) const { return (mDir / name).string(); }

    std::filesystem::path mDir;
};

/// Runs @a f and expects an Error whose message contains every one of @a parts.
template <typename F>::testing::AssertionResult throwsWith(F&& f, std::vector<std::string> parts)
{
    try {
        f();
    } catch (const Error& e) {
        const std::string m = e.what();
        for (const std::string& p : parts) {
            if (m.find(p) == std::string::npos) {
                return ::testing::AssertionFailure() << "message \"" << m << "\" lacks \"" << p << "\"";
            }
        }
        return ::testing::AssertionSuccess();
    } catch (const std::exception& e) {
        return ::testing::AssertionFailure() << "threw a non-vdbclay exception: " << e.what();
    }
    return ::testing::AssertionFailure() << "did not throw";
}

bool inBox(const Box& b, const Coord& c)
{
    return c.x() >= b.min[0] && c.x() <= b.max[0] && c.y() >= b.min[1] && c.y() <= b.max[1] &&
           c.z() >= b.min[2] && c.z() <= b.max[2];
}

Vec3 v3(const Coord& c)
{
    return {{double(c.x()), double(c.y()), double(c.z())}};
}

/// Every voxel of @a search whose centre is inside @a s lies in s->bounds(); returns how many.
::testing::AssertionResult boundsHoldInside(const ShapePtr& s, const CoordBBox& search,
                                            int64_t* count = nullptr)
{
    const Box b = s->bounds();
    int64_t n = 0;
    for (auto it = search.begin(); it; ++it) {
        if (s->distance(v3(*it)) < 0) {
            ++n;
            if (!inBox(b, *it)) {
                return ::testing::AssertionFailure()
                       << s->describe() << ": inside voxel " << *it << " outside bounds";
            }
        }
    }
    if (count) *count = n;
    return ::testing::AssertionSuccess();
}

// ---- analytic shapes --------------------------------------------------------------------------------

TEST_F(ShapesTest, SphereExactDistances)
{
    const ShapePtr s = makeSphere({{1, 2, 3}}, 4);
    EXPECT_EQ(s->distance({{1, 2, 3}}), -4.0);
    EXPECT_EQ(s->distance({{5, 2, 3}}), 0.0);
    EXPECT_EQ(s->distance({{1, 2, 10}}), 3.0);
    EXPECT_EQ(s->distance({{4, 6, 3}}), 1.0); // 3-4-5
    EXPECT_EQ(s->distance({{1, 2, 1}}), -2.0);
    const Box b = s->bounds();
    EXPECT_EQ(b.min, (std::array<int32_t, 3>{{-3, -2, -1}}));
    EXPECT_EQ(b.max, (std::array<int32_t, 3>{{5, 6, 7}}));
    EXPECT_NE(s->describe().find("sphere"), std::string::npos);
}

TEST_F(ShapesTest, BoxExactDistances)
{
    // Voxels 0..3 x 0..1 x 0..1: faces at -0.5, 3.5 / -0.5, 1.5.
    const ShapePtr s = makeBox({{0, 0, 0}}, {{3, 1, 1}});
    EXPECT_EQ(s->distance({{1.5, 0.5, 0.5}}), -1.0);
    EXPECT_EQ(s->distance({{0, 0, 0}}), -0.5);
    EXPECT_EQ(s->distance({{5.5, 0.5, 0.5}}), 2.0);
    EXPECT_EQ(s->distance({{-0.5, 0.5, 0.5}}), 0.0);
    EXPECT_DOUBLE_EQ(s->distance({{4.5, 2.5, 0.5}}), std::sqrt(2.0));
    EXPECT_DOUBLE_EQ(s->distance({{4.5, 2.5, 3.5}}), std::sqrt(1.0 + 1.0 + 4.0));
    const Box b = s->bounds();
    for (int i = 0; i < 3; ++i) {
        EXPECT_LE(b.min[i], 0);
        EXPECT_GE(b.max[i], i == 0 ? 3 : 1);
    }
    // One voxel box: its centre is inside, its neighbours are not.
    const ShapePtr one = makeBox({{2, 2, 2}}, {{2, 2, 2}});
    EXPECT_EQ(one->distance({{2, 2, 2}}), -0.5);
    EXPECT_EQ(one->distance({{3, 2, 2}}), 0.5);
    int64_t n = 0;
    EXPECT_TRUE(boundsHoldInside(one, CoordBBox(Coord(-2), Coord(6)), &n));
    EXPECT_EQ(n, 1);
}

TEST_F(ShapesTest, CylinderExactDistances)
{
    for (int axis = 0; axis < 3; ++axis) {
        const ShapePtr s = makeCylinder({{0, 0, 0}}, 2, 6, axis);
        auto at = [&](double radial, double along, double other = 0) {
            Vec3 p{{0, 0, 0}};
            p[axis] = along;
            p[(axis + 1) % 3] = radial;
            p[(axis + 2) % 3] = other;
            return s->distance(p);
        };
        EXPECT_EQ(at(0, 0), -2.0) << axis;
        EXPECT_EQ(at(1, 0), -1.0) << axis;
        EXPECT_EQ(at(0, 2.5), -0.5) << axis; // near a cap
        EXPECT_EQ(at(0, 5), 2.0) << axis;
        EXPECT_EQ(at(5, 0), 3.0) << axis;
        EXPECT_EQ(at(3, 0, 4), 3.0) << axis;                       // radial distance 5
        EXPECT_DOUBLE_EQ(at(4, 7), std::sqrt(4.0 + 16.0)) << axis; // beyond the rim
        const Box b = s->bounds();
        EXPECT_EQ(b.min[axis], -3);
        EXPECT_EQ(b.max[axis], 3);
        EXPECT_EQ(b.max[(axis + 1) % 3], 2);
    }
}

TEST_F(ShapesTest, CapsuleExactDistances)
{
    const ShapePtr s = makeCapsule({{0, 0, 0}}, {{10, 0, 0}}, 2);
    EXPECT_EQ(s->distance({{5, 3, 0}}), 1.0);
    EXPECT_EQ(s->distance({{5, 0, 0}}), -2.0);
    EXPECT_EQ(s->distance({{-3, 0, 0}}), 1.0);
    EXPECT_EQ(s->distance({{13, 4, 0}}), 3.0);
    EXPECT_EQ(s->distance({{0, 0, 1}}), -1.0);
    // a == b: a sphere.
    const ShapePtr p = makeCapsule({{1, 1, 1}}, {{1, 1, 1}}, 3);
    EXPECT_EQ(p->distance({{1, 1, 5}}), 1.0);
}

TEST_F(ShapesTest, BoundsContainEveryInsideVoxel)
{
    std::vector<ShapePtr> shapes = {
        makeSphere({{0.3, -1.7, 2.5}}, 5.2),          makeBox({{-3, 0, 1}}, {{4, 2, 6}}),
        makeCylinder({{1, 1, 1}}, 3.5, 7, 0),         makeCylinder({{0.5, 0.5, 0.5}}, 2, 9.5, 2),
        makeCapsule({{-4, -2, 0}}, {{5, 3, 2}}, 2.5),
    };
    const size_t analytic = shapes.size();
    for (size_t i = 0; i < analytic; ++i) {
        Pose pose;
        pose.translation = {{1.5, -2.25, 0.75}};
        pose.rotationDeg = {{30.0 + 7 * double(i), 45, -60}};
        pose.pivot = {{1, 2, 3}};
        shapes.push_back(makeTransformed(shapes[i], pose));
        Pose quarter;
        quarter.rotationDeg = {{0, 0, 90}};
        shapes.push_back(makeTransformed(shapes[i], quarter));
    }
    for (const ShapePtr& s : shapes) {
        int64_t n = 0;
        EXPECT_TRUE(boundsHoldInside(s, CoordBBox(Coord(-20), Coord(20)), &n));
        EXPECT_GT(n, 0) << s->describe();
        // Not absurdly loose: the box of a shape whose voxels all lie in [-20, 20].
        const Box b = s->bounds();
        for (int a = 0; a < 3; ++a) {
            EXPECT_GE(b.min[a], -21) << s->describe();
            EXPECT_LE(b.max[a], 21) << s->describe();
        }
    }
}

TEST_F(ShapesTest, PoseRoundTripAndQuarterTurns)
{
    Pose pose;
    pose.translation = {{3, -4, 5.5}};
    pose.rotationDeg = {{17, -123, 271}};
    pose.pivot = {{-2, 1, 7}};
    EXPECT_FALSE(pose.isIdentity());
    for (const Vec3& p : {Vec3{{0, 0, 0}}, Vec3{{1.5, -2, 9}}, Vec3{{-100, 30, 0.25}}}) {
        const Vec3 q = pose.applyInverse(pose.apply(p));
        const Vec3 r = pose.apply(pose.applyInverse(p));
        for (int i = 0; i < 3; ++i) {
            EXPECT_NEAR(q[i], p[i], 1e-9);
            EXPECT_NEAR(r[i], p[i], 1e-9);
        }
    }
    // Quarter turns are exact. x first, then y, then z: (1,0,0) -90 about x stays, +90 about z -> y.
    Pose q;
    q.rotationDeg = {{0, 0, 90}};
    EXPECT_EQ(q.apply({{1, 0, 0}}), (Vec3{{0, 1, 0}}));
    q.rotationDeg = {{90, 0, 0}};
    EXPECT_EQ(q.apply({{0, 1, 0}}), (Vec3{{0, 0, 1}}));
    q.rotationDeg = {{90, 90, 0}}; // y -> z (about x) -> x (about y)
    EXPECT_EQ(q.apply({{0, 1, 0}}), (Vec3{{1, 0, 0}}));
    q.rotationDeg = {{0, 0, 90}};
    q.pivot = {{1, 1, 0}};
    q.translation = {{0, 0, 2}};
    EXPECT_EQ(q.apply({{2, 1, 0}}), (Vec3{{1, 2, 2}}));
    EXPECT_EQ(q.applyInverse({{1, 2, 2}}), (Vec3{{2, 1, 0}}));

    Pose id;
    EXPECT_TRUE(id.isIdentity());
    id.rotationDeg = {{360, 0, 0}};
    EXPECT_TRUE(id.isIdentity());
    id.pivot = {{4, 5, 6}}; // a pivot alone moves nothing
    EXPECT_TRUE(id.isIdentity());
    const ShapePtr s = makeSphere({{0, 0, 0}}, 1);
    EXPECT_EQ(makeTransformed(s, id), s);
}

TEST_F(ShapesTest, TransformedDistancesAndNormals)
{
    // A 10 x 2 x 2 box turned a quarter about z, then moved: it lies along y.
    const ShapePtr box = makeBox({{0, 0, 0}}, {{9, 1, 1}});
    Pose pose;
    pose.rotationDeg = {{0, 0, 90}};
    pose.translation = {{20, 0, 0}};
    const ShapePtr t = makeTransformed(box, pose);
    // Box point (4.5, 0.5, 0.5) (its centre) goes to (-0.5, 4.5, 0.5) + (20, 0, 0).
    EXPECT_EQ(t->distance({{19.5, 4.5, 0.5}}), -1.0);
    EXPECT_EQ(t->distance({{19.5, 12.5, 0.5}}), 3.0);
    const Vec3 n = t->normal({{19.5, 12.5, 0.5}});
    EXPECT_NEAR(n[0], 0, 1e-12);
    EXPECT_NEAR(n[1], 1, 1e-12);
    EXPECT_NEAR(n[2], 0, 1e-12);

    const ShapePtr s = makeSphere({{1, 1, 1}}, 10);
    const Vec3 m = s->normal({{4, 5, 1}});
    EXPECT_NEAR(m[0], 0.6, 1e-3); // central differences of step 0.5 on a curved surface
    EXPECT_NEAR(m[1], 0.8, 1e-3);
    EXPECT_NEAR(m[2], 0.0, 1e-12);
    EXPECT_EQ(s->normal({{1, 1, 1}}), (Vec3{{0, 1, 0}})); // zero gradient: +y
}

// A transformed shape computes its rotation once, when it is built; its distance must stay the
// inner distance at Pose::applyInverse(p) to the last bit (the push's and placement's results
// depend on it). Odd angles, pivots and points, every analytic shape, nested poses.
TEST_F(ShapesTest, TransformedDistanceIsBitIdenticalToTheInnerDistanceAtApplyInverse)
{
    const std::vector<ShapePtr> inner = {makeSphere({{1.5, -2, 3}}, 7.25), makeBox({{-3, 0, 2}}, {{9, 4, 5}}),
                                         makeCylinder({{0, 1, 2}}, 3.5, 11, 1),
                                         makeCapsule({{-4, 0, 0}}, {{5, 6, -2}}, 2.5)};
    uint64_t state = 12345;
    auto next = [&state](double lo, double hi) {
        state = state * 6364136223846793005ull + 1442695040888963407ull;
        return lo + (hi - lo) * double(state >> 11) / double(uint64_t(1) << 53);
    };
    int compared = 0;
    for (const ShapePtr& s : inner) {
        for (int k = 0; k < 20; ++k) {
            Pose pose;
            for (int i = 0; i < 3; ++i) {
                pose.translation[i] = next(-30, 30);
                pose.rotationDeg[i] = next(-400, 400);
                pose.pivot[i] = next(-10, 10);
            }
            const ShapePtr t = makeTransformed(s, pose);
            Pose outer;
            outer.rotationDeg = {{next(-90, 90), 33.3, next(-90, 90)}};
            outer.translation = {{1, -2, 0.5}};
            const ShapePtr tt = makeTransformed(t, outer);
            for (int j = 0; j < 50; ++j) {
                const Vec3 p{{std::floor(next(-40, 40)), std::floor(next(-40, 40)), next(-40, 40)}};
                const double want = s->distance(pose.applyInverse(p));
                const double got = t->distance(p);
                EXPECT_EQ(std::memcmp(&want, &got, sizeof(double)), 0) << s->describe() << " at pose " << k;
                const double want2 = s->distance(pose.applyInverse(outer.applyInverse(p)));
                const double got2 = tt->distance(p);
                EXPECT_EQ(std::memcmp(&want2, &got2, sizeof(double)), 0)
                    << s->describe() << " nested, pose " << k;
                ++compared;
            }
        }
    }
    EXPECT_EQ(compared, 4 * 20 * 50);
}

TEST_F(ShapesTest, InsideVoxelBoxIsExactlyTheVoxelsWhoseCentreIsInside)
{
    // An unrotated box, moved by any translation and pivot, is marked and rasterised as a
    // box (InsideBox.h) instead of a distance per voxel; it must be the same voxels, bit for bit.
    // Boxes with corners on quarter voxels and at random, translations on half voxels (centres on
    // the faces: not inside) and at random.
    uint64_t state = 2026;
    auto next = [&state](double lo, double hi) {
        state = state * 6364136223846793005ull + 1442695040888963407ull;
        return lo + (hi - lo) * double(state >> 11) / double(uint64_t(1) << 53);
    };
    int compared = 0, nonEmpty = 0;
    for (int k = 0; k < 400; ++k) {
        Vec3 lo, hi;
        Pose pose;
        for (int i = 0; i < 3; ++i) {
            const bool quarter = k % 2 == 0;
            lo[i] = quarter ? std::floor(next(-40, 40)) / 4 : next(-10, 10);
            hi[i] = lo[i] + (quarter ? std::floor(next(0, 40)) / 4 : next(0, 8));
            pose.translation[i] = k % 4 < 2 ? std::floor(next(-60, 60)) / 2 : next(-30, 30);
            pose.pivot[i] = k % 3 == 0 ? 0.0 : next(-10, 10);
        }
        const ShapePtr b = makeBox(lo, hi);
        for (const ShapePtr& s : {b, makeTransformed(b, pose)}) {
            Box got;
            ASSERT_TRUE(shapes_internal::insideVoxelBox(*s, got)) << s->describe();
            Box want;
            const Box bb = s->bounds();
            for (int x = bb.min[0] - 1; x <= bb.max[0] + 1; ++x)
                for (int y = bb.min[1] - 1; y <= bb.max[1] + 1; ++y)
                    for (int z = bb.min[2] - 1; z <= bb.max[2] + 1; ++z)
                        if (s->distance(Vec3{{double(x), double(y), double(z)}}) < 0)
                            want = unite(want, Box{{{x, y, z}}, {{x, y, z}}});
            ASSERT_EQ(got.empty(), want.empty()) << s->describe();
            if (!want.empty()) {
                EXPECT_EQ(got.min, want.min) << s->describe();
                EXPECT_EQ(got.max, want.max) << s->describe();
                // A box: every voxel of it inside, none beside it (checked above by the bounding box
                // of the inside voxels: the count says the box is full).
                uint64_t inside = 0;
                for (int x = want.min[0]; x <= want.max[0]; ++x)
                    for (int y = want.min[1]; y <= want.max[1]; ++y)
                        for (int z = want.min[2]; z <= want.max[2]; ++z)
                            inside += s->distance(Vec3{{double(x), double(y), double(z)}}) < 0 ? 1 : 0;
                EXPECT_EQ(inside, uint64_t(want.max[0] - want.min[0] + 1) *
                                      uint64_t(want.max[1] - want.min[1] + 1) *
                                      uint64_t(want.max[2] - want.min[2] + 1));
                ++nonEmpty;
            }
            ++compared;
        }
    }
    EXPECT_EQ(compared, 800);
    EXPECT_GT(nonEmpty, 400);
    // Not boxes of voxels: a rotated box, a sphere, a box moved twice (left to the distance).
    Box unused;
    Pose turned;
    turned.rotationDeg = {{0, 30, 0}};
    EXPECT_FALSE(
        shapes_internal::insideVoxelBox(*makeTransformed(makeBox({{0, 0, 0}}, {{4, 4, 4}}), turned), unused));
    EXPECT_FALSE(shapes_internal::insideVoxelBox(*makeSphere({{0, 0, 0}}, 5), unused));
    Pose shifted;
    shifted.translation = {{1, 2, 3}};
    EXPECT_FALSE(shapes_internal::insideVoxelBox(
        *makeTransformed(makeTransformed(makeBox({{0, 0, 0}}, {{4, 4, 4}}), shifted), shifted), unused));
}

TEST_F(ShapesTest, ParameterErrorsNameTheParameter)
{
    const double nan = std::nan(""), inf = INFINITY;
    EXPECT_TRUE(throwsWith([&] { makeSphere({{0, nan, 0}}, 1); }, {"makeSphere", "center[1]"}));
    EXPECT_TRUE(throwsWith([&] { makeSphere({{0, 0, 0}}, 0); }, {"radius"}));
    EXPECT_TRUE(throwsWith([&] { makeSphere({{0, 0, 0}}, -2); }, {"radius", "-2"}));
    EXPECT_TRUE(throwsWith([&] { makeSphere({{0, 0, 0}}, inf); }, {"radius"}));
    EXPECT_TRUE(throwsWith([&] { makeSphere({{0, 0, 0}}, nan); }, {"radius"}));
    EXPECT_TRUE(throwsWith([&] { makeSphere({{3e9, 0, 0}}, 1); }, {"bounds"}));
    EXPECT_TRUE(throwsWith([&] { makeBox({{0, 5, 0}}, {{1, 4, 1}}); }, {"makeBox", "min[1]", "max[1]"}));
    EXPECT_TRUE(throwsWith([&] { makeBox({{0, 0, 0}}, {{1, 1, inf}}); }, {"max[2]"}));
    EXPECT_TRUE(throwsWith([&] { makeCylinder({{0, 0, 0}}, 1, 0, 1); }, {"makeCylinder", "height"}));
    EXPECT_TRUE(throwsWith([&] { makeCylinder({{0, 0, 0}}, -1, 2, 1); }, {"radius"}));
    EXPECT_TRUE(throwsWith([&] { makeCylinder({{0, 0, 0}}, 1, 2, 3); }, {"axis", "3"}));
    EXPECT_TRUE(throwsWith([&] { makeCylinder({{0, 0, 0}}, 1, 2, -1); }, {"axis"}));
    EXPECT_TRUE(throwsWith([&] { makeCapsule({{nan, 0, 0}}, {{1, 0, 0}}, 1); }, {"makeCapsule", "a[0]"}));
    EXPECT_TRUE(throwsWith([&] { makeCapsule({{0, 0, 0}}, {{1, 0, inf}}, 1); }, {"b[2]"}));
    EXPECT_TRUE(throwsWith([&] { makeCapsule({{0, 0, 0}}, {{1, 0, 0}}, 0); }, {"radius"}));
    EXPECT_TRUE(throwsWith([&] { makeTransformed(nullptr, Pose()); }, {"shape"}));
    Pose bad;
    bad.rotationDeg = {{0, nan, 0}};
    EXPECT_TRUE(throwsWith(
        [&] {
            makeTransformed(makeSphere({{0, 0, 0}}, 1), bad);
        },
        {"pose.rotationDeg[1]"}));
}

// ---- meshes -------------------------------------------------------------------------------------------

// A cube 0..10 in world units; faces as quads, in several OBJ index forms.
const char* kCubeObj = "# cube\n"
                       "o cube\n"
                       "v 0 0 0 1 0 0\nv 10 0 0\nv 10 10 0 1.0\nv 0 10 0\n" // with colour, with w
                       "v 0 0 10\nv 10 0 10\nv 10 10 10\nv 0 10 10\n"
                       "vn 0 0 1\n"
                       "f 1 4 3 2\n"
                       "f 5/1 6/1 7/1 8/1\n"
                       "f 1//1 2//1 6//1 5//1\n"
                       "f 2/1/1 3/1/1 7/1/1 6/1/1\n"
                       "f -5 -1 -2 -6\n" // 3 7 8 4
                       "f 4 8 5 1\n";

std::string tetraAsciiStl()
{
    return "solid tetra\n"
           "facet normal 0 0 -1\n outer loop\n  vertex 0 0 0\n  vertex 0 10 0\n  vertex 10 0 0\n "
           "endloop\nendfacet\n"
           "facet normal 0 -1 0\n outer loop\n  vertex 0 0 0\n  vertex 10 0 0\n  vertex 0 0 10\n "
           "endloop\nendfacet\n"
           "facet normal -1 0 0\n outer loop\n  vertex 0 0 0\n  vertex 0 0 10\n  vertex 0 10 0\n "
           "endloop\nendfacet\n"
           "facet normal 1 1 1\n outer loop\n  vertex 10 0 0\n  vertex 0 10 0\n  vertex 0 0 10\n "
           "endloop\nendfacet\n"
           "endsolid tetra\n";
}

std::string tetraBinaryStl()
{
    const float v[4][3] = {{0, 0, 0}, {10, 0, 0}, {0, 10, 0}, {0, 0, 10}};
    const int tri[4][3] = {{0, 2, 1}, {0, 1, 3}, {0, 3, 2}, {1, 2, 3}};
    std::string s(80, ' ');
    s.replace(0, 5, "solid"); // a binary STL header may start with "solid" too
    const uint32_t n = 4;
    s.append(reinterpret_cast<const char*>(&n), 4);
    for (const auto& t : tri) {
        const float normal[3] = {0, 0, 0};
        s.append(reinterpret_cast<const char*>(normal), 12);
        for (int k = 0; k < 3; ++k)
            s.append(reinterpret_cast<const char*>(v[t[k]]), 12);
        s.append(2, '\0');
    }
    return s;
}

TEST_F(ShapesTest, MeshObjCubeInsideOutside)
{
    const std::string p = file("cube.obj", kCubeObj);
    const ShapePtr s = loadMesh(p, 1.0);
    EXPECT_LT(s->distance({{5, 5, 5}}), 0);
    EXPECT_LT(s->distance({{1, 1, 1}}), 0);
    EXPECT_NEAR(s->distance({{5, 5, 8}}), -2.0, 0.25);
    EXPECT_GT(s->distance({{15, 5, 5}}), 0);
    EXPECT_GT(s->distance({{-3, 5, 5}}), 0);
    EXPECT_GT(s->distance({{5, 5, 11}}), 0);
    EXPECT_GT(s->distance({{50, 50, 50}}), 0);
    int64_t n = 0;
    EXPECT_TRUE(boundsHoldInside(s, CoordBBox(Coord(-5), Coord(15)), &n));
    EXPECT_GE(n, 9 * 9 * 9);
    EXPECT_LE(n, 11 * 11 * 11);
    // Half-size clay voxels: the cube spans clay voxels 0..20.
    const ShapePtr h = loadMesh(p, 0.5);
    EXPECT_LT(h->distance({{18, 10, 10}}), 0);
    EXPECT_GT(h->distance({{22, 10, 10}}), 0);
    EXPECT_TRUE(boundsHoldInside(h, CoordBBox(Coord(-5), Coord(25))));
}

TEST_F(ShapesTest, MeshStlTetrahedronAsciiAndBinary)
{
    for (const std::string& p :
         {file("tetra.stl", tetraAsciiStl()), file("tetra_bin.stl", tetraBinaryStl())}) {
        const ShapePtr s = loadMesh(p, 0.5);
        // Clay voxel p is world p / 2.
        EXPECT_LT(s->distance({{2, 2, 2}}), 0) << p;
        EXPECT_LT(s->distance({{4, 4, 4}}), 0) << p;
        EXPECT_GT(s->distance({{16, 16, 16}}), 0) << p; // beyond the slanted face
        EXPECT_GT(s->distance({{-4, 2, 2}}), 0) << p;
        EXPECT_TRUE(boundsHoldInside(s, CoordBBox(Coord(-5), Coord(25)))) << p;
    }
}

TEST_F(ShapesTest, MeshErrors)
{
    // Open: the cube without its top face (4 edges of one quad are shared by one face only).
    std::string open = kCubeObj;
    open.erase(open.find("f 5/1 6/1 7/1 8/1\n"), std::strlen("f 5/1 6/1 7/1 8/1\n"));
    const std::string po = file("open.obj", open);
    // Open meshes are filled by the generalized winding number and say so.
    EXPECT_TRUE(loadMesh(po)->describe().find("open: 4 open edges") != std::string::npos);
    // Malformed lines name the line.
    const std::string pm = file("bad.obj", "v 0 0 0\nv 1 0 0\nv 0 1 x\nf 1 2 3\n");
    EXPECT_TRUE(throwsWith([&] { loadMesh(pm); }, {pm + ":3:", "\"x\""}));
    const std::string pi = file("badindex.obj", "v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 4\n");
    EXPECT_TRUE(throwsWith([&] { loadMesh(pi); }, {pi + ":4:", "out of range"}));
    const std::string pf = file("shortface.obj", "v 0 0 0\nv 1 0 0\nf 1 2\n");
    EXPECT_TRUE(throwsWith([&] { loadMesh(pf); }, {pf + ":3:"}));
    std::string stl = tetraAsciiStl();
    stl.replace(stl.find("vertex 0 10 0"), std::strlen("vertex 0 10 0"), "vertex 0 10");
    const std::string ps = file("bad.stl", stl);
    EXPECT_TRUE(throwsWith([&] { loadMesh(ps); }, {ps + ":5:"})); // solid, facet, outer loop, vertex, vertex
    // Empty, missing, truncated, unknown.
    const std::string pe = file("empty.obj", "# nothing\nv 1 2 3\n");
    EXPECT_TRUE(throwsWith([&] { loadMesh(pe); }, {pe, "no faces"}));
    EXPECT_TRUE(
        throwsWith([&] { loadMesh(path("missing.obj")); }, {"cannot open", "missing.obj", "no such file"}));
    const std::string bin = tetraBinaryStl();
    const std::string pt = file("trunc.stl", bin.substr(0, bin.size() - 7));
    EXPECT_TRUE(throwsWith([&] { loadMesh(pt); }, {pt}));
    const std::string pu = file("mesh.3ds", "MM\n");
    EXPECT_TRUE(throwsWith([&] { loadMesh(pu); }, {pu, "unknown mesh format"}));
    const std::string pp = file("mesh.ply", "ply\n"); // PLY is read (TestInterop), a header alone is not
    EXPECT_TRUE(throwsWith([&] { loadMesh(pp); }, {pp, "no end_header"}));
    // A header whose end_header line is the file's last, with no newline (found by fuzz_mesh): the
    // elements it promises are missing, said as such.
    for (const char* format : {"ascii", "binary_little_endian"}) {
        const std::string pn =
            file(std::string("nonl-") + format + ".ply",
                 std::string("ply\nformat ") + format +
                     " 1.0\nelement vertex 99999999999\nproperty float x\nproperty float y\n"
                     "property float z\nend_header");
        EXPECT_TRUE(throwsWith([&] { loadMesh(pn); }, {pn, "element \"vertex\"", "truncated?"})) << format;
    }
    EXPECT_TRUE(throwsWith([&] { loadMesh(file("c.obj", kCubeObj), 0.0); }, {"voxelSize"}));
}

// ---- level sets ---------------------------------------------------------------------------------------

TEST_F(ShapesTest, LevelSetRoundTrip)
{
    // World radius 5 at (1, 2, 3), level-set voxels of 0.5.
    auto ls =
        openvdb::tools::createLevelSetSphere<openvdb::FloatGrid>(5.0f, openvdb::Vec3f(1, 2, 3), 0.5f, 3.0f);
    ls->setName("ball");
    auto fog = openvdb::FloatGrid::create(0.0f);
    fog->setName("density");
    fog->setGridClass(openvdb::GRID_FOG_VOLUME);
    fog->tree().setValue(Coord(0), 1.0f);
    const std::string p = path("ball.vdb");
    openvdb::io::File(p).write({fog, ls});

    for (double vs : {0.5, 1.0, 0.25}) {
        const ShapePtr s = loadLevelSet(p, vs); // the first level set: "ball", not "density"
        const Vec3 c{{1 / vs, 2 / vs, 3 / vs}};
        const double r = 5 / vs;
        EXPECT_LT(s->distance(c), 0) << vs; // deep inside: the background, negative
        EXPECT_NEAR(s->distance({{c[0] + r - 1, c[1], c[2]}}), -1.0, 0.1) << vs;
        EXPECT_NEAR(s->distance({{c[0], c[1] - r - 1, c[2]}}), 1.0, 0.1) << vs;
        EXPECT_GT(s->distance({{c[0] + 3 * r, c[1], c[2]}}), 0) << vs; // far outside
        EXPECT_GT(s->distance({{-1000, 0, 0}}), 0) << vs;
        const int R = int(r) + 4;
        const Coord cc{int(c[0]), int(c[1]), int(c[2])};
        int64_t n = 0;
        EXPECT_TRUE(boundsHoldInside(s, CoordBBox(cc.offsetBy(-R), cc.offsetBy(R)), &n)) << vs;
        const double exact = 4.0 / 3.0 * M_PI * r * r * r;
        EXPECT_NEAR(double(n), exact, 0.25 * exact) << vs;
    }
    const ShapePtr named = loadLevelSet(p, 1.0, "ball");
    EXPECT_NE(named->describe().find("ball"), std::string::npos);
    EXPECT_TRUE(
        throwsWith([&] { loadLevelSet(p, 1.0, "density"); }, {p, "density", "not a FloatGrid level set"}));
    EXPECT_TRUE(throwsWith([&] { loadLevelSet(p, 1.0, "nope"); }, {p, "no grid named \"nope\""}));
    EXPECT_TRUE(throwsWith([&] { loadLevelSet(p, -1.0); }, {"voxelSize"}));
}

TEST_F(ShapesTest, LevelSetErrors)
{
    EXPECT_TRUE(throwsWith([&] { loadLevelSet(path("nothing.vdb")); }, {"nothing.vdb", "no such file"}));
    const std::string txt = file("text.vdb", "this is not a vdb file\n");
    EXPECT_TRUE(throwsWith([&] { loadLevelSet(txt); }, {txt}));
    auto ints = openvdb::Int32Grid::create(0);
    ints->setName("mass");
    ints->tree().setValue(Coord(1, 2, 3), 7);
    const std::string pv = path("mass.vdb");
    openvdb::io::File(pv).write({ints});
    EXPECT_TRUE(throwsWith([&] { loadLevelSet(pv); }, {pv, "no FloatGrid level set"}));
    // Truncated: half of a valid file.
    auto ls = openvdb::tools::createLevelSetSphere<openvdb::FloatGrid>(5.0f, openvdb::Vec3f(0), 0.5f);
    const std::string pg = path("good.vdb");
    openvdb::io::File(pg).write({ls});
    std::ifstream in(pg, std::ios::binary);
    std::string all((std::istreambuf_iterator<char>(in)), std::istreambuf_iterator<char>());
    const std::string pt = file("trunc.vdb", all.substr(0, all.size() / 2));
    EXPECT_TRUE(throwsWith([&] { loadLevelSet(pt); }, {pt}));
}

} // namespace
