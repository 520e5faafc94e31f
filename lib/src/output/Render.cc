// Pictures of clay. 2D: the density map of the z = 0 layer, each voxel a square of whole pixels,
// coloured like the paper's figures, with a legend strip. 3D: the clay surface (Surface.h) ray
// traced with openvdb::tools::LevelSetRayTracer from a camera orbiting the bounding box centre.
#include "vdbclay/Render.h"

#include "vdbclay/Metrics.h"
#include "vdbclay/Types.h"

#include "output/Png.h"
#include "output/Surface.h"

#include <openvdb/openvdb.h>
#include <openvdb/tools/RayTracer.h>

#include <algorithm>
#include <array>
#include <cstring>
#include <cmath>
#include <vector>

namespace vdbclay {

namespace {

constexpr int kMaxImageSide = 16384;

using Rgb = std::array<uint8_t, 3>;

const Rgb kWhite{{255, 255, 255}};
const Rgb kOver{{215, 25, 28}}; // cells over Tc
const Rgb kInk{{40, 40, 40}};   // legend text and frame

/// Light to dark blue for densities in (0, 1] (ColorBrewer "Blues"); darker = denser.
Rgb rampColour(double t)
{
    static const double stops[][4] = {{0.0, 222, 235, 247}, {0.5, 107, 174, 214}, {1.0, 8, 48, 107}};
    t = std::min(1.0, std::max(0.0, t));
    int i = t <= 0.5 ? 0 : 1;
    const double u = (t - stops[i][0]) / (stops[i + 1][0] - stops[i][0]);
    Rgb c;
    for (int k = 0; k < 3; ++k) {
        c[k] = uint8_t(std::lround(stops[i][k + 1] + u * (stops[i + 1][k + 1] - stops[i][k + 1])));
    }
    return c;
}

Rgb densityColour(int32_t m, int32_t threshold)
{
    if (m <= 0) return kWhite;
    if (m > threshold) return kOver;
    return rampColour(double(m) / double(threshold));
}

struct Image {
    int width, height;
    std::vector<uint8_t> rgb;
    Image(int w, int h) : width(w), height(h), rgb(size_t(w) * size_t(h) * 3, 255) {}
    void set(int x, int y, const Rgb& c)
    {
        if (x < 0 || y < 0 || x >= width || y >= height) return;
        uint8_t* p = &rgb[(size_t(y) * size_t(width) + size_t(x)) * 3];
        p[0] = c[0];
        p[1] = c[1];
        p[2] = c[2];
    }
    void fill(int x0, int y0, int w, int h, const Rgb& c)
    {
        for (int y = y0; y < y0 + h; ++y)
            for (int x = x0; x < x0 + w; ++x)
                set(x, y, c);
    }
};

/// A 3x5 pixel font for the legend's few characters.
void drawText(Image& img, int x, int y, const char* text, int scale)
{
    auto glyph = [](char ch) -> const char* {
        switch (ch) {
        case '0': return "111101101101111";
        case '1': return "010110010010111";
        case '.': return "000000000000010";
        case '5': return "111100111001111";
        case 'T': return "111010010010010";
        case 'c': return "000000111100111";
        case '>': return "100010001010100";
        default: return "000000000000000";
        }
    };
    for (const char* p = text; *p; ++p, x += 4 * scale) {
        const char* g = glyph(*p);
        for (int r = 0; r < 5; ++r)
            for (int c = 0; c < 3; ++c)
                if (g[r * 3 + c] == '1') img.fill(x + c * scale, y + r * scale, scale, scale, kInk);
    }
}

int textWidth(const char* text, int scale)
{
    return int(std::strlen(text)) * 4 * scale - scale;
}

void render2d(const std::string& path, const MassGrid& mass, int32_t threshold, const RenderOptions& options)
{
    // The clay's bounding box in the z = 0 layer (nonzero values, active or not).
    openvdb::CoordBBox box;
    for (auto it = mass.tree().cbeginValueAll(); it; ++it) {
        if (*it == 0) continue;
        openvdb::CoordBBox b;
        it.getBoundingBox(b);
        if (b.min().z() > 0 || b.max().z() < 0) continue;
        b.min().z() = 0;
        b.max().z() = 0;
        box.expand(b);
    }
    if (box.empty()) throw Error("cannot render " + path + ": no clay in the z = 0 layer");

    const openvdb::Coord ext = box.extents();
    const int margin = std::max(2, int(std::max(ext.x(), ext.y()) / 20));
    const int64_t w = int64_t(ext.x()) + 2 * margin, h = int64_t(ext.y()) + 2 * margin;
    if (w > kMaxImageSide || h > kMaxImageSide) {
        throw Error("cannot render " + path + ": the clay spans " + std::to_string(ext.x()) + " x " +
                    std::to_string(ext.y()) + " voxels, more than a picture of " +
                    std::to_string(kMaxImageSide) + " pixels can show");
    }
    int scale = int(std::max<int64_t>(1, options.width / w));
    scale = std::min<int>(scale, 64);
    while (scale > 1 && (w * scale > kMaxImageSide || h * scale > kMaxImageSide))
        --scale;

    const int mapW = int(w * scale), mapH = int(h * scale);
    const int imgW = std::max(mapW, 160);
    const int textScale = 2, legendH = 6 + 12 + 4 + 5 * textScale + 6;
    Image img(imgW, mapH + 1 + legendH);
    const int x0 = (imgW - mapW) / 2;

    // The map: y up, so row 0 holds the highest y.
    auto acc = mass.getConstAccessor();
    const int xmin = box.min().x() - margin, ymax = box.max().y() + margin;
    for (int64_t vy = 0; vy < h; ++vy) {
        for (int64_t vx = 0; vx < w; ++vx) {
            const int32_t m = acc.getValue(openvdb::Coord(int(xmin + vx), int(ymax - vy), 0));
            if (m == 0) continue;
            img.fill(x0 + int(vx) * scale, int(vy) * scale, scale, scale, densityColour(m, threshold));
        }
    }

    // The legend: a separator, the ramp 0..Tc, a swatch for cells over Tc, labels.
    const int ly = mapH + 1;
    img.fill(0, mapH, imgW, 1, Rgb{{180, 180, 180}});
    const int pad = 8;
    const int usable = imgW - 2 * pad;
    const int swatchW = std::max(16, usable / 8);
    const int rampW = std::max(16, usable - swatchW - 3 * textWidth("0", textScale) - 12);
    const int barY = ly + 6, barH = 12;
    for (int x = 0; x < rampW; ++x) {
        const double t = double(x + 1) / double(rampW);
        img.fill(pad + x, barY, 1, barH, rampColour(t));
    }
    const int swatchX = pad + rampW + 12;
    img.fill(swatchX, barY, swatchW, barH, kOver);
    const int textY = barY + barH + 4;
    drawText(img, pad, textY, "0", textScale);
    drawText(img, pad + rampW / 2 - textWidth("0.5", textScale) / 2, textY, "0.5", textScale);
    drawText(img, pad + rampW - textWidth("Tc", textScale), textY, "Tc", textScale);
    drawText(img, swatchX, textY, ">Tc", textScale);

    io_internal::writePngRgb(path, img.width, img.height, img.rgb);
}

/// Clay-coloured Lambert shading: a headlight plus light from above, a little ambient.
class ClayShader : public openvdb::tools::BaseShader {
public:
    openvdb::tools::Film::RGBA operator()(const openvdb::Vec3R&, const openvdb::Vec3R& normal,
                                          const openvdb::Vec3R& dir) const override
    {
        openvdb::Vec3R n = normal;
        if (n.lengthSqr() > 0) n.normalize();
        if (n.dot(dir) > 0) n = -n;
        const double head = std::max(0.0, n.dot(-dir));
        const double sky = std::max(0.0, n.dot(openvdb::Vec3R(0.3, 1.0, 0.2).unit()));
        const double k = std::min(1.0, 0.18 + 0.55 * head + 0.35 * sky);
        using V = openvdb::tools::Film::RGBA::ValueT;
        return openvdb::tools::Film::RGBA(V(0.85 * k), V(0.55 * k), V(0.40 * k), V(1));
    }
    openvdb::tools::BaseShader* copy() const override { return new ClayShader(*this); }
};

void render3d(const std::string& path, const MassGrid& mass, int32_t threshold, const RenderOptions& options)
{
    if (options.width > kMaxImageSide || options.height > kMaxImageSide) {
        throw Error("cannot render " + path + ": the picture may be at most " +
                    std::to_string(kMaxImageSide) + " pixels wide and high");
    }
    auto density = io_internal::densityGrid(mass, threshold, 1.0);
    auto surface = io_internal::surfaceLevelSet(*density, 0.5);
    const openvdb::CoordBBox box = surface->evalActiveVoxelBoundingBox();
    if (surface->activeVoxelCount() == 0 || box.empty()) {
        throw Error("cannot render " + path + ": no surface at density 0.5 (no cell is half full)");
    }

    const openvdb::Vec3d lo = surface->indexToWorld(box.min().asVec3d());
    const openvdb::Vec3d hi = surface->indexToWorld(box.max().asVec3d());
    const openvdb::Vec3d centre = 0.5 * (lo + hi);
    const double radius = std::max(1.0, 0.5 * (hi - lo).length());

    const double focal = 50.0, aperture = 41.2136;
    const double tanHalfW = 0.5 * aperture / focal;
    const double tanHalf = tanHalfW * std::min(1.0, double(options.height) / double(options.width));
    const double distance = 1.08 * radius / std::sin(std::atan(tanHalf));

    const double pi = openvdb::math::pi<double>();
    const double az = options.azimuthDeg * pi / 180.0;
    const double el = std::max(-89.0, std::min(89.0, options.elevationDeg)) * pi / 180.0;
    const openvdb::Vec3d eye = centre + distance * openvdb::Vec3d(std::cos(el) * std::sin(az), std::sin(el),
                                                                  std::cos(el) * std::cos(az));

    openvdb::tools::Film film(size_t(options.width), size_t(options.height));
    film.fill(openvdb::tools::Film::RGBA(1.0, 1.0, 1.0, 1.0)); // white background: rays that miss keep it
    openvdb::tools::PerspectiveCamera camera(film, openvdb::Vec3R(0.0), eye, focal, aperture, 1e-3,
                                             distance + 4 * radius);
    camera.lookAt(centre, openvdb::Vec3R(0, 1, 0));
    openvdb::tools::rayTrace(*surface, ClayShader(), camera, /*pixelSamples=*/2, /*seed=*/0,
                             /*threaded=*/true);

    std::vector<uint8_t> rgb(size_t(options.width) * size_t(options.height) * 3);
    auto byte = [](float v) { return uint8_t(std::lround(std::min(1.f, std::max(0.f, v)) * 255.f)); };
    for (int j = 0; j < options.height; ++j) {
        for (int i = 0; i < options.width; ++i) {
            const auto& p = film.pixel(size_t(i), size_t(j));
            uint8_t* q = &rgb[(size_t(j) * size_t(options.width) + size_t(i)) * 3];
            q[0] = byte(p.r);
            q[1] = byte(p.g);
            q[2] = byte(p.b);
        }
    }
    io_internal::writePngRgb(path, options.width, options.height, rgb);
}

} // namespace

void renderPng(const std::string& path, const MassGrid& mass, int32_t threshold, int dimensions,
               const RenderOptions& options)
{
    openvdb::initialize();
    if (threshold <= 0) throw Error("cannot render " + path + ": the threshold Tc must be > 0");
    if (dimensions != 2 && dimensions != 3) {
        throw Error("cannot render " + path + ": dimensions must be 2 or 3, not " +
                    std::to_string(dimensions));
    }
    if (options.width <= 0 || options.height <= 0) {
        throw Error("cannot render " + path + ": the picture size must be positive, not " +
                    std::to_string(options.width) + " x " + std::to_string(options.height));
    }
    if (clayVoxelCount(mass) == 0) throw Error("cannot render " + path + ": the grid holds no clay");
    try {
        if (dimensions == 2) {
            render2d(path, mass, threshold, options);
        } else {
            render3d(path, mass, threshold, options);
        }
    } catch (const Error&) {
        throw;
    } catch (const std::exception& e) {
        throw Error("cannot render " + path + ": " + e.what());
    }
}

} // namespace vdbclay
