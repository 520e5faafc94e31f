// The global transport's sorts of cell lists (RadixSort.h: the design).

#include "transport/RadixSort.h"
#include "transport/Chunks.h"

#include <tbb/blocked_range.h>
#include <tbb/parallel_for.h>

#include <algorithm>
#include <cstring>

namespace vdbclay {
namespace transport_internal {

namespace {

/// The radix sorts' digits: six of 11 bits (the last one of 9).
constexpr int kBits = 11, kDigits = 6;
constexpr uint64_t kMask = (uint64_t(1) << kBits) - 1;
constexpr size_t kBuckets = size_t(kMask) + 1;

/// Runs @a fn(block, begin, end) over the fixed blocks of kSortBlock entries of [0, n), in parallel.
template <typename Fn> void forBlocks(size_t n, const Fn& fn)
{
    const size_t blocks = (n + kSortBlock - 1) / kSortBlock;
    tbb::parallel_for(tbb::blocked_range<size_t>(0, blocks, 1), [&](const tbb::blocked_range<size_t>& r) {
        for (size_t b = r.begin(); b != r.end(); ++b)
            fn(b, b * kSortBlock, std::min(n, (b + 1) * kSortBlock));
    });
}

/// The sorts' scratch for @a n entries (the second buffers of the keys and the order) and @a counts
/// digit counts, every count 0.
void scratchFor(RadixScratch& s, size_t n, size_t counts)
{
    s.keyTmp.resize(n);
    s.tmp.resize(n);
    s.count.assign(counts, 0);
}

/// radixSort() by blocks, in parallel: per digit, each block's counts (count[block * kBuckets +
/// digit value]), then each value's place for each block, in (value, block) order, then the
/// blocks scattered.
void radixSortBlocks(std::vector<int32_t>& order, RadixScratch& s)
{
    const size_t n = order.size(), blocks = (n + kSortBlock - 1) / kSortBlock;
    scratchFor(s, n, blocks * kBuckets);
    std::vector<uint64_t>& key = s.key;
    std::vector<uint64_t>& keyTmp = s.keyTmp;
    std::vector<int32_t>& tmp = s.tmp;
    std::vector<size_t>& count = s.count;
    for (int d = 0; d < kDigits; ++d) {
        const int shift = kBits * d;
        forBlocks(n, [&](size_t b, size_t lo, size_t hi) {
            size_t* c = &count[b * kBuckets];
            std::fill(c, c + kBuckets, size_t(0));
            for (size_t u = lo; u < hi; ++u)
                ++c[(key[u] >> shift) & kMask];
        });
        const size_t first = (key[0] >> shift) & kMask;
        size_t same = 0;
        for (size_t b = 0; b < blocks; ++b)
            same += count[b * kBuckets + first];
        if (same == n) continue; // one digit for all: the order stands
        size_t sum = 0;
        for (size_t v = 0; v < kBuckets; ++v)
            for (size_t b = 0; b < blocks; ++b) {
                const size_t k = count[b * kBuckets + v];
                count[b * kBuckets + v] = sum;
                sum += k;
            }
        forBlocks(n, [&](size_t b, size_t lo, size_t hi) {
            size_t* c = &count[b * kBuckets];
            for (size_t u = lo; u < hi; ++u) {
                const size_t at = c[(key[u] >> shift) & kMask]++;
                keyTmp[at] = key[u];
                tmp[at] = order[u];
            }
        });
        key.swap(keyTmp);
        order.swap(tmp);
    }
}

} // namespace

void radixSort(std::vector<int32_t>& order, RadixScratch& s, bool serial)
{
    const size_t n = order.size();
    if (!serial && n >= 2 * kSortBlock) {
        radixSortBlocks(order, s);
        return;
    }
    scratchFor(s, n, size_t(kDigits) << kBits);
    std::vector<uint64_t>& key = s.key;
    std::vector<uint64_t>& keyTmp = s.keyTmp;
    std::vector<int32_t>& tmp = s.tmp;
    std::vector<size_t>& count = s.count;
    for (size_t u = 0; u < n; ++u)
        for (int d = 0; d < kDigits; ++d)
            ++count[(size_t(d) << kBits) + ((key[u] >> (kBits * d)) & kMask)];
    for (int d = 0; d < kDigits; ++d) {
        size_t* c = &count[size_t(d) << kBits];
        if (c[(key[0] >> (kBits * d)) & kMask] == n) continue; // one digit for all: the order stands
        size_t sum = 0;
        for (size_t b = 0; b <= kMask; ++b) {
            const size_t k = c[b];
            c[b] = sum;
            sum += k;
        }
        for (size_t u = 0; u < n; ++u) {
            const size_t at = c[(key[u] >> (kBits * d)) & kMask]++;
            keyTmp[at] = key[u];
            tmp[at] = order[u];
        }
        key.swap(keyTmp);
        order.swap(tmp);
    }
}

void sortByCoord(std::vector<int32_t>& order, size_t from, const std::vector<CellCoord>& at, RadixScratch& s)
{
    const size_t n = order.size() - from;
    if (n < 2) return;
    const auto before = [&](int32_t a, int32_t b) { return at[size_t(a)] < at[size_t(b)]; };
    CellCoord lo = at[size_t(order[from])], hi = lo;
    for (size_t u = from; u < order.size(); ++u) {
        lo.minComponent(at[size_t(order[u])]);
        hi.maxComponent(at[size_t(order[u])]);
    }
    constexpr int64_t kAxis = int64_t(1) << 21;
    if (n < 64 || int64_t(hi.x) - lo.x >= kAxis || int64_t(hi.y) - lo.y >= kAxis ||
        int64_t(hi.z) - lo.z >= kAxis) {
        std::sort(order.begin() + std::ptrdiff_t(from), order.end(), before);
        return;
    }
    std::vector<int32_t>& part = s.part;
    part.assign(order.begin() + std::ptrdiff_t(from), order.end());
    std::vector<uint64_t>& key = s.key;
    key.resize(n);
    for (size_t u = 0; u < n; ++u) {
        const CellCoord& c = at[size_t(part[u])];
        key[u] = uint64_t(int64_t(c.x) - lo.x) << 42 | uint64_t(int64_t(c.y) - lo.y) << 21 |
                 uint64_t(int64_t(c.z) - lo.z);
    }
    radixSort(part, s, true); // MIC(0)'s rows: under SolverTuning::multigridMin
    std::copy(part.begin(), part.end(), order.begin() + std::ptrdiff_t(from));
}

void sortByPotential(std::vector<int32_t>& order, const HigherPotential& higher, RadixScratch& s, bool serial)
{
    const size_t n = order.size();
    if (n < 2) return;
    std::vector<uint64_t>& key = s.key;
    key.resize(n);
    forChunks(n, serial, [&](size_t lo, size_t hi) {
        for (size_t u = lo; u < hi; ++u) {
            // +0.0 makes -0 into +0 (they compare equal); the bits then order as the doubles once a
            // negative's are all flipped and a positive's sign bit is set; complemented: decreasing p.
            const double v = higher.p[size_t(order[u])] + 0.0;
            uint64_t b;
            std::memcpy(&b, &v, sizeof b);
            b = (b >> 63) ? ~b : b | (uint64_t(1) << 63);
            key[u] = ~b;
        }
    });
    radixSort(order, s, serial);
    for (size_t u = 0; u < n;) {
        size_t e = u + 1;
        while (e < n && key[e] == key[u])
            ++e;
        if (e - u > 1)
            std::sort(order.begin() + std::ptrdiff_t(u), order.begin() + std::ptrdiff_t(e), higher);
        u = e;
    }
}

} // namespace transport_internal
} // namespace vdbclay
