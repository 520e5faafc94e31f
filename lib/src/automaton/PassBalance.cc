// PassBalance (PassBalance.h): the chunks' shares from their measured seconds per block.
#include "automaton/PassBalance.h"

#include <algorithm>

namespace vdbclay {
namespace automaton_internal {

void PassBalance::fixedCuts(size_t chunks, uint64_t total, int firstShare, std::vector<uint64_t>& out)
{
    out.assign(chunks + 1, 0);
    if (chunks == 0) return;
    out[chunks] = total;
    if (chunks == 1) return;
    const uint64_t first = std::min(total, total * uint64_t(firstShare) / (100 * chunks));
    for (size_t c = 1; c < chunks; ++c)
        out[c] = first + (total - first) * (c - 1) / (chunks - 1);
}

void PassBalance::cuts(int phase, size_t chunks, uint64_t total, int firstShare,
                       std::vector<uint64_t>& out) const
{
    const std::vector<double>& est = mPhase[phase & 1].perBlock;
    const bool known =
        est.size() == chunks && std::all_of(est.begin(), est.end(), [](double s) { return s > 0; });
    if (!known || chunks < 2) return fixedCuts(chunks, total, firstShare, out);
    // Shares proportional to speed (1 / seconds per block), each within [1/4, 4] x an even share,
    // then scaled back to the total (the clamped shares summed first, then accumulated).
    double speedSum = 0;
    for (double s : est)
        speedSum += 1.0 / s;
    const double even = 1.0 / double(chunks);
    auto share = [&](size_t c) { return std::clamp((1.0 / est[c]) / speedSum, even / 4, even * 4); };
    double sum = 0;
    for (size_t c = 0; c < chunks; ++c)
        sum += share(c);
    out.assign(chunks + 1, 0);
    out[chunks] = total;
    double acc = 0; // positive shares: the cuts are nondecreasing
    for (size_t c = 1; c < chunks; ++c) {
        acc += share(c - 1) / sum;
        out[c] = std::min(total, uint64_t(acc * double(total) + 0.5));
    }
}

void PassBalance::measured(int phase, size_t chunks, const Measure* measures)
{
    std::vector<double>& est = mPhase[phase & 1].perBlock;
    if (est.size() != chunks) est.assign(chunks, 0.0);
    for (size_t c = 0; c < chunks; ++c) {
        const Measure& got = measures[c];
        if (got.blocks < kMinMeasured || !(got.seconds > 0)) continue;
        const double m = got.seconds / double(got.blocks);
        double& s = est[c];
        if (s == 0) {
            s = m;
            continue;
        }
        s += (std::clamp(m, s / 2, s * 2) - s) / 8;
    }
}

void PassBalance::reset()
{
    for (Phase& p : mPhase)
        p.perBlock.clear();
}

double PassBalance::secondsPerBlock(int phase, size_t c) const
{
    const std::vector<double>& est = mPhase[phase & 1].perBlock;
    return c < est.size() ? est[c] : 0.0;
}

} // namespace automaton_internal
} // namespace vdbclay
