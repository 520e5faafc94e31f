#include "output/Png.h"

#include "core/AtomicFile.h"

#include "vdbclay/Types.h"

#include <png.h>

#include <cstring>
#include <ostream>

namespace vdbclay {
namespace io_internal {

void writePngRgb(const std::string& path, int width, int height, const std::vector<uint8_t>& rgb)
{
    if (width <= 0 || height <= 0 || rgb.size() != size_t(width) * size_t(height) * 3) {
        throw Error("cannot write " + path + ": bad image size");
    }
    // libpng's simplified API: no setjmp, errors come back in image.message.
    png_image image;
    std::memset(&image, 0, sizeof(image));
    image.version = PNG_IMAGE_VERSION;
    image.width = png_uint_32(width);
    image.height = png_uint_32(height);
    image.format = PNG_FORMAT_RGB;
    png_alloc_size_t bytes = 0;
    if (!png_image_write_to_memory(&image, nullptr, &bytes, 0, rgb.data(), 0, nullptr)) {
        throw Error("cannot write " + path + ": PNG encoding failed: " + image.message);
    }
    std::vector<uint8_t> encoded(bytes);
    if (!png_image_write_to_memory(&image, encoded.data(), &bytes, 0, rgb.data(), 0, nullptr)) {
        throw Error("cannot write " + path + ": PNG encoding failed: " + image.message);
    }
    encoded.resize(bytes);
    writeAtomically(path, [&](std::ostream& os) {
        os.write(reinterpret_cast<const char*>(encoded.data()), std::streamsize(encoded.size()));
    });
}

} // namespace io_internal
} // namespace vdbclay
