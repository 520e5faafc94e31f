// The automaton's candidate blocks (see Candidates.h). No OpenVDB in this translation unit.
#include "automaton/Candidates.h"

#include <algorithm>

namespace vdbclay {
namespace automaton_internal {

uint32_t AnchorIndex::find(const Origin& o) const
{
    const Origin* e = keys + size;
    const Origin* it =
        std::lower_bound(keys, e, o, [](const Origin& a, const Origin& b) { return indexLess(a, b); });
    return (it != e && *it == o) ? uint32_t(it - keys) : kNoEntry;
}

void Candidates::reset(std::vector<Origin> hotLeaves)
{
    if (mDense) {
        clearSlot(0);
        clearSlot(1);
    }
    mHot = std::move(hotLeaves);
    mFullScanSteps = 2;
    mPending.clear();
    mChangedPrev.clear();
    mChangedPrev2.clear();
    mLazy = 0;
}

void Candidates::addRegion(const Box& region)
{
    mPending.push_back(Pending{region, 2});
}

void Candidates::clearChanges()
{
    if (mDense) {
        clearSlot(0);
        clearSlot(1);
    }
    mChangedPrev2.clear();
    mChangedPrev.clear();
    mLazy = 0;
}

void Candidates::endStep()
{
    if (mFullScanSteps > 0) --mFullScanSteps;
    for (Pending& p : mPending)
        --p.steps;
    mPending.erase(
        std::remove_if(mPending.begin(), mPending.end(), [](const Pending& p) { return p.steps <= 0; }),
        mPending.end());
}

void Candidates::record(std::vector<WorkItem>& work)
{
    // A list gathered in dense mode gives every item its index: not read again here (on several
    // threads the items' cache lines then stay with the threads that gather and pass them). Other
    // lists are checked item by item.
    bool indexed = mDense;
    if (!(indexed && work.data() == mGathered.first && work.size() == mGathered.second)) {
        for (size_t i = 0; indexed && i < work.size(); ++i)
            indexed = work[i].entry != kNoEntry;
    }
    mGathered = {nullptr, 0};
    if (!(indexed && mSunk)) undoPredrain(); // the masks go back before anything is added to the slot
    if (indexed) {
        // A pass that did not record its items (a range ran outside the lanes: sinkMissed) leaves
        // the recording to here (serial, plain ORs). Then, as after a pass that recorded every item
        // itself, keep the list (by swap) for a later detach(), which turns the last
        // two into changed lists.
        if (!mSunk) sinkAll(work);
        mPrevWork[1].swap(mPrevWork[0]);
        mPrevWork[0].swap(work);
        mLazy = std::min(mLazy + 1, 2);
        mSunk = false;
        return;
    }
    materialize();
    recordLists(work);
}

void Candidates::sinkAll(const std::vector<WorkItem>& work)
{
    const DenseSink& s = *sink();
    auto each = [&](auto sinkOne) {
        for (const WorkItem& w : work) {
            if (w.changed) sinkOne(s, w.entry, w.changed);
        }
    };
    if (mIs3D)
        mPhase == 0 ? each(sinkChanges<0, true>) : each(sinkChanges<1, true>);
    else
        mPhase == 0 ? each(sinkChanges<0, false>) : each(sinkChanges<1, false>);
}

void Candidates::materialize()
{
    if (mLazy == 2) recordLists(mPrevWork[1], /*listsOnly=*/true);
    if (mLazy >= 1) recordLists(mPrevWork[0], /*listsOnly=*/true);
    mLazy = 0;
}

void Candidates::recordLists(const std::vector<WorkItem>& work, bool listsOnly)
{
    mChangedPrev2.swap(mChangedPrev);
    mChangedPrev.clear();
    for (const WorkItem& w : work) {
        if (!w.changed) continue;
        const Anchor a{w.anchor, w.changed};
        mChangedPrev.push_back(a);
        if (listsOnly || !mDense || (mSunk && w.entry != kNoEntry)) continue;
        // Items gathered in dense mode carry their index; others (a work list built elsewhere) are
        // looked up. A block that changed holds clay, so its anchor is in the table.
        const uint32_t e = w.entry != kNoEntry ? w.entry : mIndex.find(w.anchor);
        if (e == kNoEntry) continue;
        addDense(mPhase, e, w.changed);                   // the step after next, same phase
        addDenseDilated(1 - mPhase, e, a, mPhase, mIs3D); // the next step
    }
    // The merged mode merges the changed lists as runs in layer order; a list gathered densely is in
    // index order (column order), e.g. the step's own list when its grow stage detached mid-step.
    if (!std::is_sorted(mChangedPrev.begin(), mChangedPrev.end(), anchorLayerLess))
        std::sort(mChangedPrev.begin(), mChangedPrev.end(), anchorLayerLess);
    if (!listsOnly) mSunk = false;
}

void Candidates::addDense(int slot, uint32_t e, uint64_t mask)
{
    if (!mask) return;
    mAcc[slot][e] |= mask;
    mTouched[slot][e >> 6] |= uint64_t(1) << (e & 63);
}

void Candidates::addDenseDilated(int slot, uint32_t e, const Anchor& a, int fromPhase, bool is3D)
{
    uint64_t out[8];
    if (is3D) {
        if (fromPhase == 0)
            dilateAll<0, true>(a.mask, out);
        else
            dilateAll<1, true>(a.mask, out);
    } else {
        if (fromPhase == 0)
            dilateAll<0, false>(a.mask, out);
        else
            dilateAll<1, false>(a.mask, out);
    }
    const uint32_t* nb = (fromPhase == 0 ? mIndex.up : mIndex.down) + 8 * size_t(e);
    for (int s = 0; s < (is3D ? 8 : 4); ++s) {
        const uint32_t t = nb[s];
        if (out[s] && t != kNoEntry)
            addDense(slot, t, out[s]); // no entry: no leaf within reach, cannot change
    }
}

template <typename F> void Candidates::drain(int slot, F&& f, size_t fromWord, size_t toWord)
{
    std::vector<uint64_t>& bits = mTouched[slot];
    std::vector<uint64_t>& acc = mAcc[slot];
    toWord = std::min(toWord, bits.size());
    if (!mLanesDirty[slot]) { // one lane (every pass on one thread)
        for (size_t k = fromWord; k < toWord; ++k) {
            for (uint64_t b = bits[k]; b; b &= b - 1) {
                const uint32_t e = uint32_t(64 * k) + uint32_t(__builtin_ctzll(b));
                f(e, acc[e]);
                acc[e] = 0;
            }
            bits[k] = 0;
        }
        return;
    }
    // A lane's entry is nonzero only where its bit is set, so the union of the bits finds them all.
    // Only nonzero words and entries are cleared: a store to a line another thread's lane last
    // wrote moves the line here and back at its next write, and most words and entries are zero.
    if (toWord == bits.size()) mLanesDirty[slot] = false; // (a predrain leaves the rest to the gather)
    for (size_t k = fromWord; k < toWord; ++k) {
        uint64_t word = bits[k];
        if (word) bits[k] = 0;
        for (Lane& l : mLanes) {
            if (const uint64_t w = l.touched[slot][k]) {
                word |= w;
                l.touched[slot][k] = 0;
            }
        }
        for (uint64_t b = word; b; b &= b - 1) {
            const uint32_t e = uint32_t(64 * k) + uint32_t(__builtin_ctzll(b));
            uint64_t m = acc[e];
            if (m) acc[e] = 0;
            for (Lane& l : mLanes) {
                if (const uint64_t a = l.acc[slot][e]) {
                    m |= a;
                    l.acc[slot][e] = 0;
                }
            }
            f(e, m);
        }
    }
}

void Candidates::drainInto(int slot, std::vector<WorkItem>& out, size_t fromWord, size_t toWord)
{
    drain(
        slot,
        [&](uint32_t e, uint64_t m) {
            out.push_back(WorkItem{mIndex.keys[e], m, 0, e});
        },
        fromWord, toWord);
}

void Candidates::clearSlot(int slot)
{
    if (mPreSlot == slot) undoPredrain(/*keep=*/false);
    drain(slot, [](uint32_t, uint64_t) {});
}

// The pass of a step of phase P writes the next step's slot (1 - P) only through sinkChanges's
// dilation, into the neighbours of its items: for P = 0 the upper ones (+8 on some axes: later in
// index order, so at entries >= the item's), for P = 1 the lower ones (-8 on some axes: x at least
// the item's x - 8, x being the index's first key). Items from entry `first` on thus never write below
// the first anchor with x >= x(first) - 8 (P = 1) or below `first` (P = 0); the words wholly below that bound
// hold their final masks once the items before `first` are done, and are drained here while later chunks
// still run (no element is read here and written there: other threads touch only words and entries at or
// above the bound). Same masks, same order as the gather's drain: the work list does not change.
void Candidates::predrain(int passPhase, uint32_t first)
{
    // (Nothing is predrained now: the last one was taken or undone before this pass. Not undone
    // here: that would write lane 0, which another chunk's thread may own.)
    if (mPreSlot >= 0 || !mDense || first == kNoEntry || first >= mIndex.size) return;
    uint32_t bound = first;
    if (passPhase == 1) {
        const int64_t x = int64_t(mIndex.keys[first].x()) - 8;
        bound = uint32_t(std::partition_point(mIndex.keys, mIndex.keys + first,
                                              [&](const Origin& o) { return int64_t(o.x()) < x; }) -
                         mIndex.keys);
    }
    const int slot = 1 - passPhase;
    const size_t words = bound / 64;
    if (words == 0) return;
    mPre.clear();
    drainInto(slot, mPre, 0, words);
    mPreSlot = slot;
    mPreWords = words;
}

void Candidates::undoPredrain(bool keep)
{
    if (mPreSlot < 0) return;
    if (keep) {
        for (const WorkItem& w : mPre)
            addDense(mPreSlot, w.entry, w.mask);
    }
    mPre.clear();
    mPreSlot = -1;
    mPreWords = 0;
}

void Candidates::attach(const AnchorIndex& index, int phase, bool is3D)
{
    detach();
    mIndex = index;
    mDense = true;
    for (int s = 0; s < 2; ++s) {
        mAcc[s].assign(index.size, 0);
        mTouched[s].assign((index.size + 63) / 64, 0);
    }
    // The next gather (phase) takes changedPrev2 and changedPrev's dilation; the one after it
    // changedPrev. Anchors the table lacks read zeros only: dropped.
    for (const Anchor& a : mChangedPrev2) {
        const uint32_t e = mIndex.find(a.origin);
        if (e != kNoEntry) addDense(phase, e, a.mask);
    }
    for (const Anchor& a : mChangedPrev) {
        const uint32_t e = mIndex.find(a.origin);
        if (e == kNoEntry) continue;
        addDense(1 - phase, e, a.mask);
        addDenseDilated(phase, e, a, 1 - phase, is3D);
    }
}

const DenseSink* Candidates::sink()
{
    if (!mDense) return nullptr;
    mSink.acc[0] = mAcc[0].data();
    mSink.acc[1] = mAcc[1].data();
    mSink.touched[0] = mTouched[0].data();
    mSink.touched[1] = mTouched[1].data();
    mSink.nb = mPhase == 0 ? mIndex.up : mIndex.down;
    mSunk = true;
    return &mSink;
}

const DenseSink* Candidates::lanes(int n)
{
    if (!mDense) return nullptr;
    if (n <= 1) return sink();
    const DenseSink lane0 = *sink();
    if (mLanes.size() < size_t(n - 1)) mLanes.resize(size_t(n - 1));
    mLaneSinks.assign(size_t(n), lane0);
    for (int i = 1; i < n; ++i) {
        Lane& l = mLanes[size_t(i - 1)];
        for (int s = 0; s < 2; ++s) {
            if (l.acc[s].size() != mIndex.size) { // a new lane, or a new index (attach() clears them)
                l.acc[s].assign(mIndex.size, 0);
                l.touched[s].assign((mIndex.size + 63) / 64, 0);
            }
            mLaneSinks[size_t(i)].acc[s] = l.acc[s].data();
            mLaneSinks[size_t(i)].touched[s] = l.touched[s].data();
        }
    }
    // Other lanes (a pass on more threads before) hold only zeros: drained with the rest.
    mLanesDirty[0] = mLanesDirty[1] = true;
    return mLaneSinks.data();
}

void Candidates::detach()
{
    undoPredrain(/*keep=*/false); // the accumulators go; the kept work lists hold every change
    mSunk = false;
    if (!mDense) return;
    materialize();
    mDense = false;
    mIndex = AnchorIndex();
    for (int s = 0; s < 2; ++s) {
        mAcc[s].clear();
        mTouched[s].clear();
    }
    mLanes.clear();
    mLanesDirty[0] = mLanesDirty[1] = false;
}

void Candidates::addExtra(const Anchor& a, int anchorPhase, int phase, bool is3D)
{
    if (anchorPhase == phase) {
        mExtras.push_back(a);
        return;
    }
    Anchor buf[8];
    int shift[8];
    const int n = dilateAcrossPhase(a, anchorPhase, is3D, buf, shift);
    mExtras.insert(mExtras.end(), buf, buf + n);
}

void Candidates::addPending(const Pending& p, int phase, bool is3D)
{
    // Every anchor touching the box (grown by one voxel), as phase-0 anchors with every block. Their
    // dilation across the phase is one run per neighbour shift: the box's anchors in layer order,
    // each moved by the same vector with the same spill mask, so every run is in layer order and
    // merges with the others (no sort).
    const uint64_t full = fullMask(is3D);
    const Origin lo((p.box.min[0] - 1) & ~7, (p.box.min[1] - 1) & ~7, is3D ? ((p.box.min[2] - 1) & ~7) : 0);
    const int zmax = is3D ? p.box.max[2] + 1 : 0;
    Anchor buf[8];
    int shift[8];
    int n = 1;
    buf[0] = Anchor{lo, full};
    if (phase != 0) n = dilateAcrossPhase(Anchor{lo, full}, 0, is3D, buf, shift);
    for (int i = 0; i < n; ++i) {
        const int dx = buf[i].origin.x() - lo.x(), dy = buf[i].origin.y() - lo.y(),
                  dz = buf[i].origin.z() - lo.z();
        const size_t start = mPendingAnchors.size();
        for (int y = lo.y(); y <= p.box.max[1] + 1; y += 8) {
            for (int z = lo.z(); z <= zmax; z += 8) {
                for (int x = lo.x(); x <= p.box.max[0] + 1; x += 8)
                    mPendingAnchors.push_back(Anchor{Origin(x + dx, y + dy, z + dz), buf[i].mask});
            }
        }
        mPendingSpans.emplace_back(start, mPendingAnchors.size());
    }
}

void Candidates::gather(int phase, bool is3D, std::vector<WorkItem>& work)
{
    mPhase = phase;
    mIs3D = is3D;
    if (mDense && mFullScanSteps == 0 && mPending.empty()) {
        // The accumulated candidates, in index order; the slot is left empty for
        // the record() of the step after next.
        work.clear();
        size_t from = 0;
        if (mPreSlot == phase) { // the part predrained during the last pass comes first
            work.swap(mPre);
            from = mPreWords;
            mPreSlot = -1;
            mPreWords = 0;
        }
        drainInto(phase, work, from, SIZE_MAX);
        mGathered = {work.data(), work.size()};
        return;
    }
    undoPredrain();
    mRuns.clear();
    for (auto& st : mStreams)
        st.clear();
    mExtras.clear();
    mPendingAnchors.clear();
    mPendingSpans.clear();
    const uint64_t full = fullMask(is3D);
    if (mFullScanSteps > 0) {
        // After reset() only blocks holding an over cell can change, and those cells lie in the hot
        // leaves (an over cell that moved at the first step is followed by mChangedPrev).
        for (const Origin& o : mHot)
            addExtra(Anchor{o, full}, 0, phase, is3D);
    } else if (!mDense) {
        mRuns.push_back(Run{mChangedPrev2.data(), mChangedPrev2.data() + mChangedPrev2.size()});
    }
    if (mDense) {
        // changedPrev2 and changedPrev's dilation are in the dense slot: one run, merged below with
        // the hot leaves and the edited regions. (During the full-scan steps after a reset, the slot
        // holds only the last step's dilation, as the lists would.)
        mDenseRun.clear();
        drain(phase, [&](uint32_t e, uint64_t m) { mDenseRun.push_back(Anchor{mIndex.keys[e], m}); });
        std::sort(mDenseRun.begin(), mDenseRun.end(), // index order to layer order, for the merge
                  anchorLayerLess);
    }
    for (const Pending& p : mPending)
        addPending(p, phase, is3D);
    Anchor buf[8];
    int shift[8];
    if (mDense) {
        mRuns.push_back(Run{mDenseRun.data(), mDenseRun.data() + mDenseRun.size()});
    } else {
        for (const Anchor& a : mChangedPrev) {
            const int n = dilateAcrossPhase(a, 1 - phase, is3D, buf, shift);
            for (int i = 0; i < n; ++i)
                mStreams[shift[i]].push_back(buf[i]);
        }
        for (const auto& st : mStreams)
            mRuns.push_back(Run{st.data(), st.data() + st.size()});
    }
    for (const auto& sp : mPendingSpans) // mPendingAnchors is complete: its data no longer moves
        mRuns.push_back(Run{mPendingAnchors.data() + sp.first, mPendingAnchors.data() + sp.second});
    if (!mExtras.empty()) {
        std::sort(mExtras.begin(), mExtras.end(), anchorLayerLess);
        size_t k = 0; // fold equal origins
        for (size_t i = 1; i < mExtras.size(); ++i) {
            if (mExtras[i].origin == mExtras[k].origin)
                mExtras[k].mask |= mExtras[i].mask;
            else
                mExtras[++k] = mExtras[i];
        }
        mExtras.resize(k + 1);
        mRuns.push_back(Run{mExtras.data(), mExtras.data() + mExtras.size()});
    }
    mRuns.erase(std::remove_if(mRuns.begin(), mRuns.end(), [](const Run& r) { return r.b == r.e; }),
                mRuns.end());

    // Merge pairwise, level by level, ping-ponging between two buffers.
    size_t total = 0;
    for (const Run& r : mRuns)
        total += size_t(r.e - r.b);
    for (int level = 0; mRuns.size() > 1; ++level) {
        std::vector<Anchor>& out = mMergeBuf[level & 1];
        out.clear();
        out.reserve(total); // no reallocation below: the offsets stay valid
        mSpans.clear();
        for (size_t i = 0; i < mRuns.size(); i += 2) {
            const size_t start = out.size();
            if (i + 1 < mRuns.size())
                mergeOr(mRuns[i].b, mRuns[i].e, mRuns[i + 1].b, mRuns[i + 1].e, out);
            else
                out.insert(out.end(), mRuns[i].b, mRuns[i].e);
            mSpans.emplace_back(start, out.size());
        }
        mRuns.clear();
        for (const auto& sp : mSpans)
            mRuns.push_back(Run{out.data() + sp.first, out.data() + sp.second});
    }
    work.clear();
    if (!mRuns.empty()) {
        work.reserve(size_t(mRuns[0].e - mRuns[0].b));
        for (const Anchor* a = mRuns[0].b; a != mRuns[0].e; ++a) {
            if (!mDense) {
                work.push_back(WorkItem{a->origin, a->mask, 0});
                continue;
            }
            // Dense mode (the steps after an edit or a reset): every item gets its index, and
            // anchors outside the index (zeros only) are dropped, as in the dense gather.
            const uint32_t e = mIndex.find(a->origin);
            if (e != kNoEntry) work.push_back(WorkItem{a->origin, a->mask, 0, e});
        }
        // Dense mode's lists are in index order (the pass's cut and the predrain rely on it); the
        // runs were merged in layer order.
        if (mDense)
            std::sort(work.begin(), work.end(),
                      [](const WorkItem& x, const WorkItem& y) { return x.entry < y.entry; });
    }
    mGathered = mDense ? std::make_pair(static_cast<const WorkItem*>(work.data()), work.size())
                       : std::make_pair(static_cast<const WorkItem*>(nullptr), size_t(0));
}

} // namespace automaton_internal
} // namespace vdbclay
