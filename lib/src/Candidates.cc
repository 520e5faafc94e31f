// The automaton's candidate blocks (see Candidates.h). No OpenVDB in this translation unit.
#include "Candidates.h"

#include <algorithm>

namespace vdbclay {
namespace automaton_internal {

void Candidates::reset(std::vector<Origin> hotLeaves)
{
    mHot = std::move(hotLeaves);
    mFullScanSteps = 2;
    mPending.clear();
    mChangedPrev.clear();
    mChangedPrev2.clear();
}

void Candidates::addRegion(const Box& region)
{
    mPending.push_back(Pending{region, 2});
}

void Candidates::clearChanges()
{
    mChangedPrev2.clear();
    mChangedPrev.clear();
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

void Candidates::record(const std::vector<WorkItem>& work)
{
    mChangedPrev2.swap(mChangedPrev);
    mChangedPrev.clear();
    for (const WorkItem& w : work) {
        if (w.changed) mChangedPrev.push_back(Anchor{w.anchor, w.changed});
    }
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
    } else {
        mRuns.push_back(Run{mChangedPrev2.data(), mChangedPrev2.data() + mChangedPrev2.size()});
    }
    for (const Pending& p : mPending)
        addPending(p, phase, is3D);
    Anchor buf[8];
    int shift[8];
    for (const Anchor& a : mChangedPrev) {
        const int n = dilateAcrossPhase(a, 1 - phase, is3D, buf, shift);
        for (int i = 0; i < n; ++i)
            mStreams[shift[i]].push_back(buf[i]);
    }
    for (const auto& st : mStreams)
        mRuns.push_back(Run{st.data(), st.data() + st.size()});
    for (const auto& sp : mPendingSpans) // mPendingAnchors is complete: its data no longer moves
        mRuns.push_back(Run{mPendingAnchors.data() + sp.first, mPendingAnchors.data() + sp.second});
    if (!mExtras.empty()) {
        std::sort(mExtras.begin(), mExtras.end(),
                  [](const Anchor& x, const Anchor& y) { return layerLess(x.origin, y.origin); });
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
        for (const Anchor* a = mRuns[0].b; a != mRuns[0].e; ++a)
            work.push_back(WorkItem{a->origin, a->mask, 0});
    }
}

} // namespace automaton_internal
} // namespace vdbclay
