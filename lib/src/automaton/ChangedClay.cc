// Where the clay changed (ChangedClay.h): recording splits a box by slots; compacting sorts by slot and
// merges.
#include "automaton/ChangedClay.h"

#include <algorithm>

namespace vdbclay {
namespace automaton_internal {

void ChangedClay::add(const Box& box)
{
    if (box.empty()) return;
    for (int32_t sx = box.min[0] >> 3; sx <= box.max[0] >> 3; ++sx)
        for (int32_t sy = box.min[1] >> 3; sy <= box.max[1] >> 3; ++sy)
            for (int32_t sz = box.min[2] >> 3; sz <= box.max[2] >> 3; ++sz) {
                Entry e;
                e.slot = {{sx, sy, sz}};
                const Box slotBox{{{sx * 8, sy * 8, sz * 8}}, {{sx * 8 + 7, sy * 8 + 7, sz * 8 + 7}}};
                e.voxels = intersect(box, slotBox);
                push(e);
            }
}

void ChangedClay::compact()
{
    if (mEntries.size() == mCompacted) return;
    std::sort(mEntries.begin(), mEntries.end(),
              [](const Entry& a, const Entry& b) { return a.slot < b.slot; });
    size_t out = 0;
    for (size_t i = 0; i < mEntries.size(); ++i) {
        if (out > 0 && mEntries[out - 1].slot == mEntries[i].slot) {
            mEntries[out - 1].voxels = unite(mEntries[out - 1].voxels, mEntries[i].voxels);
        } else {
            mEntries[out++] = mEntries[i];
        }
    }
    mEntries.resize(out);
    mCompacted = out;
}

} // namespace automaton_internal
} // namespace vdbclay
