// The active set (ActiveSet.h: the design).

#include "transport/ActiveSet.h"
#include "transport/Chunks.h"

#include <utility>

namespace vdbclay {
namespace transport_internal {

namespace {

/// The rounds solve to the tolerance once a round changes at most 1/kTightChange of the rows.
constexpr size_t kTightChange = 1000;

} // namespace

void solveActiveSet(Domain& domain, PoissonSolver& solver, const SolverTuning& tuning, bool serial,
                    ActiveSetArrays& arrays, GlobalTransportReport& rep)
{
    Cells& cells = domain.cells();
    const int32_t tc = domain.threshold();
    const int dirs = domain.dirs();
    std::vector<double>& p = arrays.p;
    p.assign(cells.size(), 0.0);
    // Rounds solve loosely until the set stops changing, then once to the tolerance (and on
    // if that still changes it): the early rounds only locate the rim.
    const double loose = tuning.roundTolerance;
    bool tight = !(loose > tuning.tolerance), same = false;
    for (int round = 0; round < tuning.maxRounds; ++round) {
        if (round + 1 == tuning.maxRounds) tight = true;
        solver.solve(p, tight ? tuning.tolerance : loose, same, rep);
        same = false;
        // Inflow of each Dirichlet cell: sum of p over its unknown faces.
        const size_t n = cells.size();
        // Gathered (the links back) in parallel; added in increasing cell order, as a serial
        // scatter over the unknown cells would: the same value on any thread count.
        std::vector<double>& inflow = arrays.inflow;
        inflow.resize(n);
        forChunks(n, serial, [&](size_t lo, size_t hi) {
            for (size_t j = lo; j < hi; ++j) {
                inflow[j] = 0.0;
                if (cells.kind[j] != kDirichlet) continue;
                int32_t from[6];
                int count = 0;
                for (int d = 0; d < dirs; ++d) {
                    const int32_t i = cells.nb[j * 6 + size_t(d)];
                    if (i >= 0 && cells.kind[size_t(i)] == kUnknown) from[count++] = i;
                }
                for (int k = 1; k < count; ++k) // insertion sort: at most 6
                    for (int m = k; m > 0 && from[m - 1] > from[m]; --m)
                        std::swap(from[m - 1], from[m]);
                double sum = 0.0;
                for (int k = 0; k < count; ++k)
                    sum += p[size_t(from[k])];
                inflow[j] = sum;
            }
        });
        std::vector<int32_t>& joined = arrays.joined;
        std::vector<int32_t>& left = arrays.left;
        selectIndices(n, serial, arrays.counts, joined, [&](size_t i) {
            return cells.kind[i] == kDirichlet && inflow[i] > double(tc - cells.m0[i]) + 0.5;
        });
        selectIndices(n, serial, arrays.counts, left,
                      [&](size_t i) { return cells.kind[i] == kUnknown && cells.m0[i] < tc && p[i] < 0; });
        if (joined.empty() && left.empty()) {
            if (tight) break;
            tight = same = true;
            continue;
        }
        // A change of at most 1/kTightChange of the rows (the rim settled to a few cells): the next
        // solve, which needs a new set-up anyway, goes straight to the tolerance (the 128-wide
        // compress stroke's rounds change 41-114 cells of ~21,000, then 2-11, then none).
        if (joined.size() + left.size() <= solver.rows() / kTightChange) tight = true;
        for (int32_t i : joined)
            cells.kind[size_t(i)] = kUnknown;
        for (int32_t i : left) {
            cells.kind[size_t(i)] = kDirichlet;
            p[size_t(i)] = 0;
        }
        // Cascade: a joined cell passes what it cannot hold (inflow - room) on, split evenly
        // over its neighbours with room; those that then overflow join now rather than one
        // solve later (the set grows shell by shell otherwise). A wrong guess leaves again
        // (p < 0) in the next round. Serial, in join order.
        for (size_t q = 0; q < joined.size(); ++q) {
            const size_t i = size_t(joined[q]);
            const double over = inflow[i] - double(tc - cells.m0[i]);
            if (!cells.hasNb[i]) domain.link(int32_t(i));
            inflow.resize(cells.size(), 0.0);
            int room = 0;
            for (int d = 0; d < dirs; ++d) {
                const int32_t j = cells.nb[i * 6 + size_t(d)];
                if (j >= 0 && cells.kind[size_t(j)] == kDirichlet) ++room;
            }
            if (room == 0 || !(over > 0)) continue;
            for (int d = 0; d < dirs; ++d) {
                const int32_t j = cells.nb[i * 6 + size_t(d)];
                if (j < 0 || cells.kind[size_t(j)] != kDirichlet) continue;
                inflow[size_t(j)] += over / room;
                if (inflow[size_t(j)] > double(tc - cells.m0[size_t(j)]) + 0.5) {
                    cells.kind[size_t(j)] = kUnknown;
                    joined.push_back(j);
                }
            }
        }
        // (Every joined cell was linked above, new Dirichlet cells included.)
        p.resize(cells.size(), 0.0);
        // A part can lose its last Dirichlet face only by a neighbour joining: if every joined
        // cell touches a Dirichlet cell, each part holding one has room, and so has every part
        // that met one (leaving cells only add room). Else search the whole domain again.
        bool allRoom = true;
        for (int32_t i : joined) {
            bool room = false;
            for (int d = 0; d < dirs && !room; ++d) {
                const int32_t j = cells.nb[size_t(i) * 6 + size_t(d)];
                room = j >= 0 && cells.kind[size_t(j)] == kDirichlet;
            }
            if (!room) {
                allRoom = false;
                break;
            }
        }
        if (allRoom) continue;
        bool grow = false;
        domain.freezeSingular(false, grow, rep);
    }
}

} // namespace transport_internal
} // namespace vdbclay
