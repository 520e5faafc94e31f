// The routing (Routing.h: the design).

#include "transport/Routing.h"
#include "transport/Chunks.h"

#include <algorithm>
#include <climits>
#include <cmath>

namespace vdbclay {
namespace transport_internal {

namespace {

/// The lower neighbours are gathered for this many cells of the order at a time (bounded memory).
constexpr size_t kBlock = size_t(1) << 16;

/// The order visits the cells at random: the gather and the split prefetch what a cell this many
/// places ahead reads (the gather: its faces and p, then, half as far ahead, its neighbours' p and
/// kinds; the split: its mass and its lower neighbours'), so the misses overlap. Reads only.
constexpr size_t kAhead = 16;

inline void prefetch(const void* at)
{
    __builtin_prefetch(at);
}

} // namespace

void route(Automaton& automaton, const Cells& cells, const std::vector<double>& p, int32_t threshold,
           int dirs, bool serial, RoutingArrays& arrays, RadixScratch& sort, GlobalTransportReport& rep)
{
    const int32_t tc = threshold;
    std::vector<int32_t>& order = arrays.order;
    selectIndices(cells.size(), serial, arrays.counts, order,
                  [&](size_t i) { return cells.kind[i] == kUnknown; });
    const HigherPotential higher{p, cells.at};
    sortByPotential(order, higher, sort, serial);
    std::vector<int64_t>& cur = arrays.cur;
    cur.assign(cells.m0.begin(), cells.m0.end());
    // Each cell's lower neighbours and drops depend on p and the kinds only, not on what the
    // cells above sent: gathered in parallel, a block of the order at a time (read in order by the
    // serial pass, which then only splits the integer excess).
    std::vector<int32_t>& outJ = arrays.outJ;
    std::vector<double>& outW = arrays.outW;
    std::vector<double>& outSum = arrays.outSum;
    std::vector<uint8_t>& outN = arrays.outN;
    const size_t block = std::min(kBlock, order.size());
    outJ.resize(block * 6);
    outW.resize(block * 6);
    outSum.resize(block);
    outN.resize(block);
    for (size_t t0 = 0; t0 < order.size(); t0 += kBlock) {
        const size_t t1 = std::min(order.size(), t0 + kBlock);
        forChunks(t1 - t0, serial, [&](size_t lo, size_t hi) {
            for (size_t u = lo; u < hi; ++u) {
                if (u + kAhead < hi) {
                    const size_t a = size_t(order[t0 + u + kAhead]);
                    prefetch(&cells.nb[a * 6]);
                    prefetch(&cells.nb[a * 6 + 5]);
                    prefetch(&p[a]);
                }
                if (u + kAhead / 2 < hi) {
                    const size_t a = size_t(order[t0 + u + kAhead / 2]);
                    for (int d = 0; d < dirs; ++d) {
                        const int32_t j = cells.nb[a * 6 + size_t(d)];
                        if (j < 0) continue;
                        prefetch(&cells.kind[size_t(j)]);
                        prefetch(&p[size_t(j)]);
                    }
                }
                const size_t i = size_t(order[t0 + u]);
                const double pi = p[i];
                double W = 0;
                uint8_t n = 0;
                for (int d = 0; d < dirs; ++d) {
                    const int32_t j = cells.nb[i * 6 + size_t(d)];
                    if (j < 0) continue;
                    const uint8_t k = cells.kind[size_t(j)];
                    if (k == kFrozen) continue;
                    const double pj = k == kUnknown ? p[size_t(j)] : 0.0;
                    if (!(pj < pi)) continue;
                    outJ[u * 6 + n] = j;
                    outW[u * 6 + n] = pi - pj;
                    ++n;
                    W += pi - pj;
                }
                outN[u] = n;
                outSum[u] = W;
            }
        });
        for (size_t u = 0; u < t1 - t0; ++u) {
            if (u + kAhead < t1 - t0) {
                const size_t a = u + kAhead;
                prefetch(&cur[size_t(order[t0 + a])]);
                for (uint8_t k = 0; k < outN[a]; ++k)
                    prefetch(&cur[size_t(outJ[a * 6 + k])]);
            }
            const size_t i = size_t(order[t0 + u]);
            const int64_t x = cur[i] - tc;
            if (x <= 0) continue;
            const int n = outN[u];
            const double W = outSum[u];
            if (n == 0 || !(W > 0)) continue;
            int64_t share[6];
            double frac[6];
            int rank[6]; // the outs by decreasing remainder, ties in direction order
            int64_t given = 0;
            for (int k = 0; k < n; ++k) {
                const double exact = double(x) * (outW[u * 6 + size_t(k)] / W);
                share[k] = int64_t(std::floor(exact));
                frac[k] = exact - double(share[k]);
                given += share[k];
                int m = k;
                for (; m > 0 && frac[rank[m - 1]] < frac[k]; --m)
                    rank[m] = rank[m - 1];
                rank[m] = k;
            }
            int64_t left = x - given;
            for (int k = 0; left != 0; k = (k + 1) % n) {
                if (left > 0) {
                    ++share[rank[k]];
                    --left;
                } else if (share[rank[k]] > 0) {
                    --share[rank[k]];
                    ++left;
                }
            }
            for (int k = 0; k < n; ++k) {
                cur[size_t(outJ[u * 6 + size_t(k)])] += share[k];
                rep.massMoved += share[k];
            }
            cur[i] -= x;
        }
    }
    // Write the changed cells.
    std::vector<int32_t>& changed = arrays.changed;
    selectIndices(cells.size(), serial, arrays.counts, changed,
                  [&](size_t i) { return cur[i] != cells.m0[i]; });
    if (changed.empty()) return;
    // Their bounds, per fixed chunk, united in chunk order.
    const size_t chunks = (changed.size() + kChunk - 1) / kChunk;
    std::vector<Box> boxes(chunks);
    std::vector<uint8_t> tooBig(chunks, 0);
    forChunks(changed.size(), serial, [&](size_t lo, size_t hi) {
        CellCoord mn = cells.at[size_t(changed[lo])], mx = mn;
        for (size_t k = lo; k < hi; ++k) {
            const size_t i = size_t(changed[k]);
            if (cur[i] > INT32_MAX) tooBig[lo / kChunk] = 1;
            mn.minComponent(cells.at[i]);
            mx.maxComponent(cells.at[i]);
        }
        boxes[lo / kChunk] = Box{{{mn.x, mn.y, mn.z}}, {{mx.x, mx.y, mx.z}}};
    });
    Box region;
    for (size_t c = 0; c < chunks; ++c) {
        if (tooBig[c]) return; // cannot happen for Tc-sized inflows; refuse to write
        region = unite(region, boxes[c]);
    }
    rep.region = region;
    // Only the changed cells are written and read: the same grid, sums and woken blocks as an edit()
    // of the region, without its scans of the region.
    std::vector<Automaton::CellMass>& write = arrays.write;
    write.resize(changed.size());
    forChunks(changed.size(), serial, [&](size_t lo, size_t hi) {
        for (size_t k = lo; k < hi; ++k) {
            const size_t i = size_t(changed[k]);
            write[k].at = {{cells.at[i].x, cells.at[i].y, cells.at[i].z}};
            write[k].mass = cur[i] > 0 ? int32_t(cur[i]) : 0;
        }
    });
    automaton.setMasses(region, write);
    rep.overloadAfter = automaton.residualOverload();
}

} // namespace transport_internal
} // namespace vdbclay
