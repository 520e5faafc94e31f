// What the candidates' tests (TestAutomaton, TestKernel) share: a random leaf-table index (the anchors a
// LeafTable would hold for leaves scattered in a box of leaves, in column order, with their neighbours),
// and sinkChanges chosen at run time.
#pragma once

#include "automaton/Candidates.h"
#include "TestRng.h"

#include <algorithm>
#include <cstdint>
#include <vector>

namespace vdbclay_test {

struct RandomAnchorIndex {
    std::vector<vdbclay::automaton_internal::Origin> keys; ///< every leaf's origin and its upper neighbours'
    std::vector<uint32_t> up, down;
    vdbclay::automaton_internal::AnchorIndex index; ///< points into keys, up and down

    /// Leaves in a box of @a side^3 leaves (2D: side^2), each left out where g.range(0, @a missingRange)
    /// draws 0.
    RandomAnchorIndex(Rng& g, int side, bool is3D, int missingRange)
    {
        using vdbclay::automaton_internal::Origin;
        const int nz = is3D ? side : 1;
        for (int x = 0; x < side; ++x)
            for (int y = 0; y < side; ++y)
                for (int z = 0; z < nz; ++z) {
                    if (g.range(0, missingRange) == 0) continue;
                    for (int d = 0; d < (is3D ? 8 : 4); ++d)
                        keys.push_back(Origin(8 * x + ((d & 1) ? 8 : 0), 8 * y + ((d & 2) ? 8 : 0),
                                              8 * z + ((d & 4) ? 8 : 0)));
                }
        std::sort(keys.begin(), keys.end(), less);
        keys.erase(std::unique(keys.begin(), keys.end()), keys.end());
        up.assign(8 * keys.size(), vdbclay::automaton_internal::kNoEntry);
        down.assign(8 * keys.size(), vdbclay::automaton_internal::kNoEntry);
        index.keys = keys.data();
        index.size = keys.size();
        for (size_t k = 0; k < keys.size(); ++k)
            for (int sh = 0; sh < (is3D ? 8 : 4); ++sh) {
                const int dx = (sh & 1) ? 8 : 0, dy = (sh & 2) ? 8 : 0, dz = (sh & 4) ? 8 : 0;
                const Origin& a = keys[k];
                up[8 * k + sh] = index.find(Origin(a.x() + dx, a.y() + dy, a.z() + dz));
                down[8 * k + sh] = index.find(Origin(a.x() - dx, a.y() - dy, a.z() - dz));
            }
        index.up = up.data();
        index.down = down.data();
    }
    RandomAnchorIndex(const RandomAnchorIndex&) = delete; // index points into the vectors
    RandomAnchorIndex& operator=(const RandomAnchorIndex&) = delete;

    /// Column order (the index's order, and the dense lists').
    static bool less(const vdbclay::automaton_internal::Origin& a,
                     const vdbclay::automaton_internal::Origin& b)
    {
        return vdbclay::automaton_internal::indexLess(a, b);
    }
};

/// sinkChanges<phase, is3D> (Candidates.h) for a phase and dimension known at run time.
inline void sinkChangesAt(int phase, bool is3D, const vdbclay::automaton_internal::DenseSink& s, uint32_t e,
                          uint64_t changed)
{
    using namespace vdbclay::automaton_internal;
    if (is3D)
        phase ? sinkChanges<1, true>(s, e, changed) : sinkChanges<0, true>(s, e, changed);
    else
        phase ? sinkChanges<1, false>(s, e, changed) : sinkChanges<0, false>(s, e, changed);
}

} // namespace vdbclay_test
