// The pass over a step's work list on the automaton's threads (see PassEngine.h).
#include "automaton/PassEngine.h"

#include <algorithm>
#include <chrono>

namespace vdbclay {
namespace automaton_internal {

namespace {

using Clock = std::chrono::steady_clock;
double secondsSince(Clock::time_point t0)
{
    return std::chrono::duration<double>(Clock::now() - t0).count();
}

} // namespace

void PassEngine::reset()
{
    mCrew.reset();
    mBalance.reset();
}

PassTotals PassEngine::run(const PassInput& in, const DenseSink* sinks, std::vector<WorkItem>& work,
                           int lanes, Candidates& candidates, PassSeconds& seconds)
{
    PassTotals tot;
    if (work.empty()) return tot;
    const auto start = Clock::now();
    if (lanes <= 1) {
        PassInput one = in;
        one.sink = sinks;
        processRange(one, work.data(), 0, work.size(), tot);
        seconds.busy += secondsSince(start);
        return tot;
    }
    // The pass's thread-seconds: every lane for its whole time, of which its chunks ran `busy`.
    double busy = 0;
    tot = runChunks(in, sinks, work, lanes, candidates, busy);
    const double span = secondsSince(start);
    seconds.busy += busy;
    seconds.idle += std::max(0.0, double(lanes) * span - busy);
    return tot;
}

PassTotals PassEngine::runChunks(const PassInput& in, const DenseSink* sinks, std::vector<WorkItem>& work,
                                 int lanes, Candidates& candidates, double& busy)
{
    const size_t n = work.size();
    // Candidate blocks per item, counted once (the cut below reads them again).
    mBlockSums.resize(n);
    uint64_t total = 0;
    for (size_t i = 0; i < n; ++i) {
        total += popcount64(work[i].mask);
        mBlockSums[i] = total;
    }
    const size_t chunks = std::min({n, size_t(lanes), PassCrew::kMaxChunks});
    // The chunks' shares of the blocks: by their measured speed in this phase (PassBalance.h), or
    // until it is known chunk 0 kFirstShare % of an even share (it also predrains) and the others
    // the rest evenly.
    mBalance.cuts(in.phase, chunks, total, kFirstShare, mCutTargets);
    mBounds.clear();
    mBounds.push_back(0);
    size_t cut = 1;
    for (size_t i = 0; i + 1 < n && cut < chunks; ++i) {
        if (mBlockSums[i] >= mCutTargets[cut]) {
            mBounds.push_back(i + 1);
            ++cut;
        }
    }
    mBounds.push_back(n);
    const size_t m = mBounds.size() - 1;
    mChunkTotals.assign(m, PassTotals());
    mChunkMeasures.assign(m, PassBalance::Measure());
    // Chunk 0, once done, drains the next step's candidates that the later chunks cannot reach
    // (Candidates::predrain), on its thread while theirs still run: that much less serial gather.
    const uint32_t firstOfRest = sinks && !in.dryRun && m >= 2 ? work[mBounds[1]].entry : kNoEntry;
    // The crew has a lane per sink lane: lane l records into sink lane l. (A lane without a sink
    // lane would record nothing and flag its chunk sinkMissed, so that record() records every
    // item; it must not fall back to another lane's sink: two threads would write the same words.)
    if (mCrew && mCrew->forked()) mCrew.reset(); // a fork's child: the helpers are the parent's
    if (!mCrew || mCrew->lanes() != lanes) mCrew = std::make_unique<PassCrew>(lanes - 1);
    const PassCrew::Body body = [&](size_t c, int lane) {
        const auto start = Clock::now();
        PassInput own = in;
        own.sink = sinks && lane < lanes ? sinks + lane : nullptr;
        processRange(own, work.data(), mBounds[c], mBounds[c + 1], mChunkTotals[c]);
        if (sinks && !own.sink) mChunkTotals[c].sinkMissed = true;
        if (c == 0 && firstOfRest != kNoEntry) candidates.predrain(in.phase, firstOfRest);
        mChunkMeasures[c] = {mChunkTotals[c].examined, secondsSince(start)};
    };
    mCrew->run(m, body);
    PassTotals tot;
    for (const PassTotals& t : mChunkTotals)
        tot.join(t);
    for (const PassBalance::Measure& c : mChunkMeasures)
        busy += c.seconds;
    if (!in.dryRun && m == chunks) mBalance.measured(in.phase, m, mChunkMeasures.data());
    return tot;
}

} // namespace automaton_internal
} // namespace vdbclay
