// Walks a .vdb file's layout as OpenVDB 10 reads it (io::File::open, io::Archive::readGrid,
// Tree/RootNode/InternalNode/LeafNode::readTopology and readBuffers, io::readCompressedValues,
// MetaMap::readMeta, DelayedLoadMetadata::readValue), checking every recorded size against the
// bytes that are really there. Nothing is allocated by a recorded size.
#include "core/VdbCheck.h"

#include "vdbclay/Types.h"

#include <array>
#include <bitset>
#include <cstring>
#include <fstream>
#include <map>
#include <set>
#include <tuple>

namespace vdbclay {
namespace io_internal {

namespace {

constexpr int64_t kMagic = 0x56444220;  // OPENVDB_MAGIC
constexpr uint32_t kOldestFormat = 222; // node-mask compression, per-grid compression flags
constexpr uint32_t kNewestFormat = 224; // OpenVDB 10
constexpr uint32_t kZip = 0x1, kActiveMask = 0x2, kBlosc = 0x4;
constexpr const char* kHalfSuffix = "_HalfFloat";

/// Sequential reads from the file, each checked against its size.
class Bytes {
public:
    explicit Bytes(const std::string& path) : mIn(path, std::ios::in | std::ios::binary)
    {
        if (!mIn) throw Error("cannot open it");
        mIn.seekg(0, std::ios::end);
        const std::streamoff end = mIn.tellg();
        if (!mIn || end < 0) throw Error("cannot read it");
        mSize = uint64_t(end);
        mIn.seekg(0);
    }

    uint64_t size() const { return mSize; }
    uint64_t pos() const { return mPos; }
    uint64_t left() const { return mSize - mPos; }

    [[noreturn]] void fail(const std::string& what) const
    {
        throw Error(what + " (at byte " + std::to_string(mPos) + " of " + std::to_string(mSize) + ")");
    }

    void need(uint64_t n, const std::string& what) const
    {
        if (n > left()) {
            fail(what + " needs " + std::to_string(n) + " bytes but the file ends " + std::to_string(left()) +
                 " bytes later");
        }
    }

    void read(void* dst, uint64_t n, const std::string& what)
    {
        need(n, what);
        mIn.read(static_cast<char*>(dst), std::streamsize(n));
        if (!mIn) fail("cannot read " + what);
        mPos += n;
    }

    template <typename T> T get(const std::string& what)
    {
        T v{};
        read(&v, sizeof v, what);
        return v;
    }

    void skip(uint64_t n, const std::string& what)
    {
        need(n, what);
        seek(mPos + n, what);
    }

    void seek(uint64_t p, const std::string& what)
    {
        if (p > mSize) fail(what + " lies at byte " + std::to_string(p) + ", past the end of the file");
        mIn.seekg(std::streamoff(p));
        if (!mIn) fail("cannot seek to " + what);
        mPos = p;
    }

    /// OpenVDB's io::readString: a uint32 length, then that many bytes.
    std::string string(const std::string& what)
    {
        const uint32_t n = get<uint32_t>(what + "'s length");
        need(n, what + " (" + std::to_string(n) + " bytes long)");
        std::string s(n, '\0');
        if (n) read(&s[0], n, what);
        return s;
    }

private:
    std::ifstream mIn;
    uint64_t mSize = 0;
    uint64_t mPos = 0;
};

/// A name fit for a message: printable characters only, cut short.
std::string printable(const std::string& s)
{
    std::string out;
    for (char c : s.substr(0, 40))
        out += (c >= 32 && c < 127) ? c : '?';
    if (s.size() > 40) out += "...";
    return "\"" + out + "\"";
}

/// Sizes of the metadata types whose value OpenVDB reads as sizeof(T) bytes.
uint32_t fixedMetaSize(const std::string& type)
{
    static const std::map<std::string, uint32_t> sizes{
        {"bool", 1},   {"int32", 4},  {"int64", 8},  {"float", 4},  {"double", 8}, {"vec2i", 8},
        {"vec2s", 8},  {"vec2d", 16}, {"vec3i", 12}, {"vec3s", 12}, {"vec3d", 24}, {"vec4i", 16},
        {"vec4s", 16}, {"vec4d", 32}, {"mat4s", 64}, {"mat4d", 128}};
    const auto it = sizes.find(type);
    return it == sizes.end() ? 0 : it->second;
}

/// A blosc block's 16-byte header: the uncompressed and compressed sizes it records.
struct BloscHeader {
    uint32_t nbytes = 0, cbytes = 0;
};

BloscHeader bloscHeader(Bytes& in, uint64_t available, const std::string& what)
{
    if (available < 16) in.fail(what + ": a blosc block of " + std::to_string(available) + " bytes");
    std::array<unsigned char, 16> h{};
    const uint64_t start = in.pos();
    in.read(h.data(), h.size(), what);
    in.seek(start, what);
    BloscHeader b;
    std::memcpy(&b.nbytes, &h[4], 4);
    std::memcpy(&b.cbytes, &h[12], 4);
    if (b.cbytes < 16 || b.cbytes > available) {
        in.fail(what + ": its blosc header records " + std::to_string(b.cbytes) +
                " compressed bytes in a block of " + std::to_string(available));
    }
    return b;
}

/// The value layout of a tree type checkVdbLayout walks.
struct ValueLayout {
    uint32_t size = 0;     ///< sizeof(ValueType)
    uint32_t halfSize = 0; ///< its half-float analogue's size (0: not a real type)
};

bool valueLayout(const std::string& type, ValueLayout& out)
{
    static const std::map<std::string, ValueLayout> known{
        {"Tree_int32_5_4_3", {4, 0}},  {"Tree_int64_5_4_3", {8, 0}},  {"Tree_float_5_4_3", {4, 2}},
        {"Tree_double_5_4_3", {8, 2}}, {"Tree_vec3i_5_4_3", {12, 0}}, {"Tree_vec3s_5_4_3", {12, 6}},
        {"Tree_vec3d_5_4_3", {24, 6}}};
    const auto it = known.find(type);
    if (it == known.end()) return false;
    out = it->second;
    return true;
}

class Walker {
public:
    explicit Walker(const std::string& path) : mIn(path) {}

    std::vector<VdbGridLayout> walk()
    {
        header();
        metaMap("the file metadata");
        const int32_t count = mIn.get<int32_t>("the grid count");
        // A descriptor takes at least 3 lengths and 3 offsets.
        if (count < 0 || uint64_t(count) > mIn.left() / 36) {
            mIn.fail("a grid count of " + std::to_string(count) + " does not fit the file");
        }
        std::vector<VdbGridLayout> grids;
        for (int32_t i = 0; i < count; ++i)
            grids.push_back(grid(i + 1));
        return grids;
    }

private:
    void header()
    {
        if (mIn.size() < 8 || mIn.get<int64_t>("the magic number") != kMagic) {
            throw Error("it does not start with the .vdb magic number");
        }
        mFormat = mIn.get<uint32_t>("the format version");
        if (mFormat < kOldestFormat || mFormat > kNewestFormat) {
            mIn.fail("format version " + std::to_string(mFormat) + " (vdbclay reads " +
                     std::to_string(kOldestFormat) + " to " + std::to_string(kNewestFormat) +
                     ": OpenVDB 3 to 10)");
        }
        mIn.skip(8, "the library version");
        if (mIn.get<char>("the grid-offsets flag") == 0) {
            mIn.fail("a streamed .vdb (no grid offsets), which vdbclay does not read");
        }
        // boost::uuids reads 36 characters: hex digits, hyphens at 8, 13, 18 and 23.
        char uuid[36];
        mIn.read(uuid, sizeof uuid, "the file's UUID");
        for (int i = 0; i < 36; ++i) {
            const bool hyphen = i == 8 || i == 13 || i == 18 || i == 23;
            const char c = uuid[i];
            const bool hex = (c >= '0' && c <= '9') || (c >= 'a' && c <= 'f') || (c >= 'A' && c <= 'F');
            if (hyphen ? c != '-' : !hex) mIn.fail("the file's UUID is malformed");
        }
    }

    void metaMap(const std::string& what)
    {
        const uint32_t count = mIn.get<uint32_t>(what + "'s item count");
        if (count > mIn.left() / 12) { // name, type and size take 12 bytes at least
            mIn.fail(what + " records " + std::to_string(count) + " items, more than fit the file");
        }
        for (uint32_t i = 0; i < count; ++i) {
            const std::string item = what + " item " + std::to_string(i + 1);
            const std::string name = mIn.string(item + "'s name");
            const std::string type = mIn.string(item + "'s type");
            const std::string field = what + " " + printable(name) + " (" + printable(type) + ")";
            const uint32_t bytes = mIn.get<uint32_t>(field + "'s size");
            metaValue(field, type, bytes);
        }
    }

    void metaValue(const std::string& field, const std::string& type, uint32_t bytes)
    {
        if (type == "string") {
            mIn.skip(bytes, field);
        } else if (type == "__delayedload") {
            delayedLoad(field, bytes);
        } else if (const uint32_t size = fixedMetaSize(type)) {
            if (bytes != size) {
                mIn.fail(field + " records " + std::to_string(bytes) + " bytes, expected " +
                         std::to_string(size));
            }
            if (type == "bool") {
                const auto b = mIn.get<unsigned char>(field);
                if (b > 1) mIn.fail(field + " is neither 0 nor 1");
            } else {
                mIn.skip(size, field);
            }
        } else {
            mIn.fail(field + ": a metadata type vdbclay does not read");
        }
    }

    /// DelayedLoadMetadata: per-leaf masks and compressed sizes, each raw or blosc-compressed.
    void delayedLoad(const std::string& field, uint32_t bytes)
    {
        if (bytes == 0) return;
        const uint64_t start = mIn.pos();
        const uint32_t count = mIn.get<uint32_t>(field + "'s count");
        if (count > mIn.size()) mIn.fail(field + " records " + std::to_string(count) + " leaves");
        delayedLoadArray(field + "'s masks", count, 1, /*mayBeAbsent=*/false);
        delayedLoadArray(field + "'s sizes", count, 8, /*mayBeAbsent=*/true);
        const uint64_t used = mIn.pos() - start;
        if (used < bytes) mIn.skip(bytes - used, field + "'s trailing bytes");
    }

    void delayedLoadArray(const std::string& what, uint32_t count, uint32_t elemSize, bool mayBeAbsent)
    {
        const uint32_t bytes = mIn.get<uint32_t>(what + "' size");
        if (mayBeAbsent && bytes == 0xffffffffu) return;
        if (bytes == 0) {
            mIn.skip(uint64_t(count) * elemSize, what);
            return;
        }
        mIn.need(bytes, what);
        const BloscHeader b = bloscHeader(mIn, bytes, what);
        // OpenVDB pads arrays shorter than 128 bytes to 128 before compressing them.
        const uint64_t expected = uint64_t(count) * elemSize;
        if (b.nbytes != expected && !(b.nbytes == 128 && expected <= 128)) {
            mIn.fail(what + " decompress to " + std::to_string(b.nbytes) + " bytes, expected " +
                     std::to_string(uint64_t(count) * elemSize));
        }
        mIn.skip(bytes, what);
    }

    VdbGridLayout grid(int32_t index)
    {
        const std::string what = "grid " + std::to_string(index);
        VdbGridLayout g;
        g.name = mIn.string(what + "'s name");
        g.type = mIn.string(what + "'s type");
        const std::string grid = "grid " + printable(g.name);
        bool half = false;
        const std::string suffix = kHalfSuffix;
        if (g.type.size() > suffix.size() &&
            g.type.compare(g.type.size() - suffix.size(), suffix.size(), suffix) == 0) {
            half = true;
            g.type.resize(g.type.size() - suffix.size());
        }
        const bool instance = !mIn.string(grid + "'s instance parent").empty();
        const int64_t gridPos = mIn.get<int64_t>(grid + "'s start");
        const int64_t blockPos = mIn.get<int64_t>(grid + "'s data start");
        const int64_t endPos = mIn.get<int64_t>(grid + "'s end");
        if (gridPos < int64_t(mIn.pos()) || blockPos < gridPos || endPos < blockPos ||
            uint64_t(endPos) > mIn.size()) {
            mIn.fail(grid + " records its bytes at " + std::to_string(gridPos) + ".." +
                     std::to_string(blockPos) + ".." + std::to_string(endPos) +
                     ", outside the file or out of order");
        }
        mIn.seek(uint64_t(gridPos), grid);
        mCompression = mIn.get<uint32_t>(grid + "'s compression flags");
        metaMap(grid + "'s metadata");
        transform(grid + "'s transform", /*nested=*/false);
        ValueLayout layout;
        if (!instance && valueLayout(g.type, layout)) {
            mValue = layout;
            mHalf = half && layout.halfSize != 0;
            mLowerNodes = mUpperNodes = 0;
            tree(grid, uint64_t(blockPos), uint64_t(endPos));
            g.treeChecked = true;
            g.leaves = mLeafActive.size();
            g.lowerNodes = mLowerNodes;
            g.upperNodes = mUpperNodes;
        } else {
            g.treeChecked = instance && valueLayout(g.type, layout);
        }
        mIn.seek(uint64_t(endPos), grid + "'s end");
        return g;
    }

    void transform(const std::string& what, bool nested)
    {
        static const std::map<std::string, uint32_t> mapSizes{{"AffineMap", 128},
                                                              {"UnitaryMap", 128},
                                                              {"ScaleMap", 120},
                                                              {"UniformScaleMap", 120},
                                                              {"TranslationMap", 24},
                                                              {"ScaleTranslateMap", 144},
                                                              {"UniformScaleTranslateMap", 144}};
        const std::string type = mIn.string(what + "'s type");
        const auto it = mapSizes.find(type);
        if (it != mapSizes.end()) {
            mIn.skip(it->second, what + " " + type);
        } else if (type == "NonlinearFrustumMap" && !nested) {
            mIn.skip(48 + 16, what + " NonlinearFrustumMap"); // bbox, taper, depth
            transform(what + "'s second map", /*nested=*/true);
        } else {
            mIn.fail(what + ": an unknown map type " + printable(type));
        }
    }

    // ---- trees (5-4-3: root, internal nodes of 32^3 and 16^3 children, leaves of 8^3 voxels) ----

    void tree(const std::string& grid, uint64_t blockPos, uint64_t endPos)
    {
        mLeafActive.clear();
        mIn.skip(4, grid + "'s buffer count");
        mIn.skip(mValue.size, grid + "'s background");
        const uint32_t tiles = mIn.get<uint32_t>(grid + "'s root tile count");
        const uint32_t children = mIn.get<uint32_t>(grid + "'s root child count");
        if (tiles > mIn.left() / (13 + mValue.size) || children > mIn.left() / (12 + 2 * 4096)) {
            mIn.fail(grid + " records " + std::to_string(tiles) + " root tiles and " +
                     std::to_string(children) + " root children, more than fit the file");
        }
        std::set<std::tuple<int32_t, int32_t, int32_t>> keys;
        auto key = [&](const std::string& what) {
            int32_t c[3];
            mIn.read(c, sizeof c, what);
            for (int32_t v : c) {
                if (v & 4095) mIn.fail(what + " is not a multiple of 4096");
            }
            const auto k = std::make_tuple(c[0], c[1], c[2]);
            if (!keys.insert(k).second) mIn.fail(what + " repeats another root entry");
            return k;
        };
        for (uint32_t i = 0; i < tiles; ++i) {
            const std::string what = grid + "'s root tile " + std::to_string(i + 1);
            key(what);
            mIn.skip(mValue.size, what);
            if (mIn.get<unsigned char>(what + "'s active flag") > 1)
                mIn.fail(what + "'s active flag is not 0 or 1");
        }
        std::tuple<int32_t, int32_t, int32_t> previous;
        for (uint32_t i = 0; i < children; ++i) {
            const std::string what = grid + "'s root child " + std::to_string(i + 1);
            const auto k = key(what);
            // Buffers are read in the root's key order: children must come in that order.
            if (i > 0 && !(previous < k)) mIn.fail(what + " is out of order");
            previous = k;
            ++mUpperNodes;
            internalTopology(what, 5);
        }
        if (mIn.pos() != blockPos) {
            mIn.fail(grid + "'s topology ends at byte " + std::to_string(mIn.pos()) +
                     " but its data should start at byte " + std::to_string(blockPos));
        }
        for (size_t i = 0; i < mLeafActive.size(); ++i) {
            const std::string what = grid + "'s leaf " + std::to_string(i + 1);
            mIn.skip(64, what + "'s value mask");
            compressedValues(what + "'s values", 512, mLeafActive[i], 64);
        }
        if (mIn.pos() != endPos) {
            mIn.fail(grid + "'s data ends at byte " + std::to_string(mIn.pos()) +
                     " but the grid should end at byte " + std::to_string(endPos));
        }
    }

    /// An internal node of 2^(3 log2) children: child mask, value mask, values, then children.
    void internalTopology(const std::string& what, int log2)
    {
        const uint32_t numValues = 1u << (3 * log2);
        const uint32_t maskBytes = numValues / 8;
        std::vector<uint64_t> childMask(maskBytes / 8), valueMask(maskBytes / 8);
        mIn.read(childMask.data(), maskBytes, what + "'s child mask");
        mIn.read(valueMask.data(), maskBytes, what + "'s value mask");
        compressedValues(what + "'s values", numValues, popcount(valueMask), maskBytes);
        const uint32_t children = popcount(childMask);
        for (uint32_t i = 0; i < children; ++i) {
            if (log2 == 5) {
                ++mLowerNodes;
                internalTopology(what + " > child " + std::to_string(i + 1), 4);
            } else {
                std::vector<uint64_t> mask(8);
                mIn.read(mask.data(), 64, what + " > leaf " + std::to_string(i + 1) + "'s value mask");
                mLeafActive.push_back(popcount(mask));
            }
        }
    }

    static uint32_t popcount(const std::vector<uint64_t>& words)
    {
        uint32_t n = 0;
        for (uint64_t w : words)
            n += uint32_t(std::bitset<64>(w).count());
        return n;
    }

    /// io::readCompressedValues for @a count values of which @a active are on.
    void compressedValues(const std::string& what, uint32_t count, uint32_t active, uint32_t maskBytes)
    {
        const auto metadata = mIn.get<unsigned char>(what + "' compression code");
        if (metadata > 6) mIn.fail(what + " have an unknown compression code " + std::to_string(metadata));
        if (metadata == 2 || metadata == 4 || metadata == 5) mIn.skip(mValue.size, what + "' inactive value");
        if (metadata == 5) mIn.skip(mValue.size, what + "' second inactive value");
        if (metadata == 3 || metadata == 4 || metadata == 5) mIn.skip(maskBytes, what + "' selection mask");
        const uint32_t stored = (mCompression & kActiveMask) && metadata != 6 ? active : count;
        if (mHalf && stored == 0) return; // HalfWriter/HalfReader: no values, no block at all
        const uint64_t bytes = uint64_t(stored) * (mHalf ? mValue.halfSize : mValue.size);
        if (mCompression & (kBlosc | kZip)) {
            block(what, bytes, (mCompression & kBlosc) != 0);
        } else {
            mIn.skip(bytes, what);
        }
    }

    /// io::bloscFromStream / io::unzipFromStream: an int64 size (<= 0: that many raw bytes), then
    /// the bytes. OpenVDB copies a raw block into the node's buffer before checking its size.
    void block(const std::string& what, uint64_t expected, bool blosc)
    {
        const int64_t n = mIn.get<int64_t>(what + "' block size");
        if (n <= 0) {
            if (uint64_t(0) - uint64_t(n) != expected) {
                mIn.fail(what + ": an uncompressed block of " + std::to_string(uint64_t(0) - uint64_t(n)) +
                         " bytes where " + std::to_string(expected) + " belong");
            }
            mIn.skip(expected, what);
            return;
        }
        mIn.need(uint64_t(n), what);
        if (blosc) {
            const BloscHeader b = bloscHeader(mIn, uint64_t(n), what);
            if (b.nbytes != expected) {
                mIn.fail(what + ": a blosc block of " + std::to_string(b.nbytes) + " bytes where " +
                         std::to_string(expected) + " belong");
            }
        }
        mIn.skip(uint64_t(n), what);
    }

    Bytes mIn;
    uint32_t mFormat = 0;
    uint32_t mCompression = 0;
    ValueLayout mValue;
    bool mHalf = false;
    std::vector<uint32_t> mLeafActive;         ///< active voxels of each leaf, in file order
    uint64_t mLowerNodes = 0, mUpperNodes = 0; ///< internal nodes of the tree being walked
};

} // namespace

bool treeTypeKnown(const std::string& type)
{
    ValueLayout unused;
    return valueLayout(type, unused);
}

std::vector<VdbGridLayout> checkVdbLayout(const std::string& path)
{
    return Walker(path).walk();
}

} // namespace io_internal
} // namespace vdbclay
