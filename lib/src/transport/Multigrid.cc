// Aggregation multigrid (Multigrid.h: the design).

#include "transport/Multigrid.h"
#include "transport/Chunks.h"
#include "transport/Laplacian.h"

#include <algorithm>
#include <cmath>
#include <numeric>
#include <utility>

namespace vdbclay {
namespace transport_internal {

void Multigrid::build(size_t n, const std::vector<int32_t>& nb, const std::vector<uint8_t>& faces,
                      const std::vector<CellCoord>& coord, bool serial)
{
    mSerial = serial;
    mUsed = 1;
    if (mLevels.empty()) mLevels.emplace_back();
    setMatrix(mLevels.front(), n, nb, faces, true);
    mLevels.front().block.assign(coord.begin(), coord.end());
    while (mLevels[mUsed - 1].n > kDense && mUsed < 24 && coarsen()) {
    }
    Level& c = mLevels[mUsed - 1];
    c.agg.clear();
    c.dense = false;
    if (c.n <= kDense) factor(c);
    for (size_t li = 0; li < mUsed; ++li)
        colour(mLevels[li], mLevels[li].block);
    if (mUsed == 1)
        finish(c); // the only level: solved as the coarsest, by row
    else
        layOutByColour(faces);
}

void Multigrid::rebind(size_t n, const std::vector<int32_t>& nb, const std::vector<uint8_t>& faces,
                       const std::vector<CellCoord>& coord, const std::vector<int32_t>& oldRow, bool serial)
{
    mSerial = serial;
    Level& f = mLevels.front();
    Level& c = mLevels[1];
    std::vector<int32_t>& agg = mScratch;
    agg.resize(n);
    forChunks(n, mSerial, [&](size_t lo, size_t hi) {
        for (size_t k = lo; k < hi; ++k)
            agg[k] = oldRow[k] >= 0 ? f.agg[size_t(oldRow[k])] : -1;
    });
    setMatrix(f, n, nb, faces, false);
    colour(f, coord);
    f.agg.swap(agg);
    c.memberStart.assign(c.n + 1, 0);
    for (size_t k = 0; k < n; ++k)
        if (f.agg[k] >= 0) ++c.memberStart[size_t(f.agg[k]) + 1];
    for (size_t i = 0; i < c.n; ++i)
        c.memberStart[i + 1] += c.memberStart[i];
    c.members.resize(c.memberStart[c.n]);
    std::vector<uint32_t> fill(c.memberStart.begin(), c.memberStart.end() - 1);
    for (size_t k = 0; k < n; ++k)
        if (f.agg[k] >= 0) c.members[fill[size_t(f.agg[k])]++] = int32_t(k);
    layOutByColour(faces);
}

void Multigrid::apply(const std::vector<double>& in, std::vector<double>& out)
{
    Level& f = mLevels.front();
    if (mUsed == 1) {
        f.rhs = in.data();
        cycle(0);
        out.assign(f.x.begin(), f.x.begin() + std::ptrdiff_t(f.n));
        return;
    }
    out.resize(f.n);
    cycleFinest(in.data(), out.data());
}

void Multigrid::setMatrix(Level& f, size_t n, const std::vector<int32_t>& nb,
                          const std::vector<uint8_t>& faces, bool csr)
{
    f.n = n;
    f.nb6.resize(n * 6);
    f.diag.resize(n);
    forChunks(n, mSerial, [&](size_t lo, size_t hi) {
        for (size_t k = lo; k < hi; ++k) {
            for (int d = 0; d < 6; ++d) {
                const int32_t j = nb[k * 6 + size_t(d)];
                f.nb6[k * 6 + size_t(d)] = j >= 0 ? j : int32_t(n);
            }
            f.diag[k] = double(faces[k]);
        }
    });
    if (!csr) {
        f.start.clear();
        f.col.clear();
    } else {
        setCsr(f, n, nb);
    }
}

void Multigrid::setCsr(Level& f, size_t n, const std::vector<int32_t>& nb)
{
    f.start.resize(n + 1);
    // Row lengths per fixed chunk, their offsets in chunk order, then the columns: in parallel.
    const size_t chunks = (n + kChunk - 1) / kChunk;
    mCounts.assign(chunks + 1, 0);
    forChunks(n, mSerial, [&](size_t lo, size_t hi) {
        size_t c = 0;
        for (size_t k = lo; k < hi; ++k)
            for (int d = 0; d < 6; ++d)
                c += nb[k * 6 + size_t(d)] >= 0 ? 1 : 0;
        mCounts[lo / kChunk + 1] = c;
    });
    for (size_t c = 0; c < chunks; ++c)
        mCounts[c + 1] += mCounts[c];
    f.col.resize(mCounts[chunks]);
    forChunks(n, mSerial, [&](size_t lo, size_t hi) {
        size_t e = mCounts[lo / kChunk];
        for (size_t k = lo; k < hi; ++k) {
            f.start[k] = uint32_t(e);
            for (int d = 0; d < 6; ++d)
                if (nb[k * 6 + size_t(d)] >= 0) f.col[e++] = nb[k * 6 + size_t(d)];
        }
    });
    f.start[n] = uint32_t(mCounts[chunks]);
}

void Multigrid::colour(Level& l, const std::vector<CellCoord>& block)
{
    const size_t n = l.n, chunks = (n + kChunk - 1) / kChunk;
    std::vector<size_t>& red = mCounts; // per chunk: its red rows, then their offsets
    red.assign(chunks + 1, 0);
    mParity.resize(n);
    forChunks(n, mSerial, [&](size_t lo, size_t hi) {
        size_t c = 0;
        for (size_t k = lo; k < hi; ++k) {
            const uint8_t odd = uint8_t((block[k].x + block[k].y + block[k].z) & 1);
            mParity[k] = odd;
            c += odd ? 0 : 1;
        }
        red[lo / kChunk + 1] = c;
    });
    for (size_t c = 0; c < chunks; ++c)
        red[c + 1] += red[c];
    l.red = red[chunks];
    l.byColour.resize(n);
    forChunks(n, mSerial, [&](size_t lo, size_t hi) {
        // Before lo: red[lo / kChunk] red rows, and lo minus those black ones (after all the red).
        size_t o[2] = {red[lo / kChunk], l.red + lo - red[lo / kChunk]};
        for (size_t k = lo; k < hi; ++k)
            l.byColour[o[mParity[k]]++] = int32_t(k);
    });
}

void Multigrid::layOutByColour(const std::vector<uint8_t>& faces)
{
    const Level& f = mLevels.front();
    const Level& c = mLevels[1];
    ColourOrder& o = mFine;
    const size_t n = f.n;
    std::vector<int32_t>& place = mScratch; // row -> place (free here: coarsen() and rebind() are done)
    place.resize(n + 1);
    forChunks(n, mSerial, [&](size_t lo, size_t hi) {
        for (size_t i = lo; i < hi; ++i)
            place[size_t(f.byColour[i])] = int32_t(i);
    });
    place[n] = int32_t(n); // a missing face stays the sentinel
    o.nb6.resize(n * 6);
    o.faces.resize(n);
    o.agg.resize(n);
    forChunks(n, mSerial, [&](size_t lo, size_t hi) {
        for (size_t i = lo; i < hi; ++i) {
            const size_t k = size_t(f.byColour[i]);
            for (size_t d = 0; d < 6; ++d)
                o.nb6[i * 6 + d] = place[size_t(f.nb6[k * 6 + d])];
            o.faces[i] = faces[k];
            o.agg[i] = f.agg[k];
        }
    });
    o.redStart.resize(c.n + 1);
    o.redStart[0] = 0;
    forChunks(c.n, mSerial, [&](size_t lo, size_t hi) {
        for (size_t i = lo; i < hi; ++i) {
            uint32_t count = 0;
            for (uint32_t m = c.memberStart[i]; m < c.memberStart[i + 1]; ++m)
                count += size_t(place[size_t(c.members[m])]) < f.red ? 1 : 0;
            o.redStart[i + 1] = count;
        }
    });
    for (size_t i = 0; i < c.n; ++i)
        o.redStart[i + 1] += o.redStart[i];
    o.redMembers.resize(o.redStart[c.n]);
    forChunks(c.n, mSerial, [&](size_t lo, size_t hi) {
        for (size_t i = lo; i < hi; ++i) {
            uint32_t e = o.redStart[i];
            for (uint32_t m = c.memberStart[i]; m < c.memberStart[i + 1]; ++m) {
                const int32_t at = place[size_t(c.members[m])];
                if (size_t(at) < f.red) o.redMembers[e++] = at;
            }
        }
    });
    o.rhs.resize(n);
    o.t.resize(f.red);
    o.x.resize(n + 1);
    o.x[n] = -0.0;
}

void Multigrid::finish(Level& l)
{
    l.invDiag.resize(l.n);
    l.x.resize(l.n);
    l.r.resize(l.n);
    l.t.resize(l.n);
    forChunks(l.n, mSerial, [&](size_t lo, size_t hi) {
        for (size_t k = lo; k < hi; ++k) {
            l.invDiag[k] = 1.0 / l.diag[k];
            l.x[k] = l.r[k] = l.t[k] = 0.0;
        }
    });
}

inline int32_t Multigrid::find(std::vector<int32_t>& parent, int32_t a)
{
    while (parent[size_t(a)] != a) {
        parent[size_t(a)] = parent[size_t(parent[size_t(a)])];
        a = parent[size_t(a)];
    }
    return a;
}

bool Multigrid::coarsen()
{
    if (mUsed == mLevels.size()) mLevels.emplace_back(); // before taking references into mLevels
    Level& f = mLevels[mUsed - 1];
    const size_t n = f.n;
    std::vector<int32_t>& parent = mScratch;
    parent.resize(n);
    std::iota(parent.begin(), parent.end(), 0);
    auto half = [](const CellCoord& c) { return CellCoord{c.x >> 1, c.y >> 1, c.z >> 1}; };
    for (size_t k = 0; k < n; ++k) {
        const CellCoord bk = half(f.block[k]);
        for (uint32_t e = f.start[k]; e < f.start[k + 1]; ++e) {
            const int32_t j = f.col[e];
            if (j >= int32_t(k) || half(f.block[size_t(j)]) != bk) continue;
            const int32_t a = find(parent, int32_t(k)), b = find(parent, j);
            if (a != b) parent[size_t(std::max(a, b))] = std::min(a, b);
        }
    }
    f.agg.assign(n, -1);
    int32_t nc = 0;
    for (size_t k = 0; k < n; ++k) {
        const int32_t root = find(parent, int32_t(k));
        f.agg[k] = root == int32_t(k) ? nc++ : f.agg[size_t(root)];
    }
    if (size_t(nc) * 4 > n * 3) {
        f.agg.clear();
        return false;
    }
    Level& c = mLevels[mUsed];
    c.n = size_t(nc);
    c.col.clear();
    c.w.clear();
    c.memberStart.assign(c.n + 1, 0);
    for (size_t k = 0; k < n; ++k)
        ++c.memberStart[size_t(f.agg[k]) + 1];
    for (size_t i = 0; i < c.n; ++i)
        c.memberStart[i + 1] += c.memberStart[i];
    c.members.resize(n);
    {
        std::vector<uint32_t> fill(c.memberStart.begin(), c.memberStart.end() - 1);
        for (size_t k = 0; k < n; ++k)
            c.members[fill[size_t(f.agg[k])]++] = int32_t(k);
    }
    c.diag.assign(c.n, 0.0);
    c.block.resize(c.n);
    c.start.resize(c.n + 1);
    std::vector<std::pair<int32_t, float>> row;
    std::vector<int32_t>& where = mWhere; // coarse row -> its place in row, or -1 (reset per row)
    where.assign(c.n, -1);
    for (size_t i = 0; i < c.n; ++i) {
        c.start[i] = uint32_t(c.col.size());
        c.block[i] = half(f.block[size_t(c.members[c.memberStart[i]])]);
        row.clear();
        double dg = 0;
        for (uint32_t m = c.memberStart[i]; m < c.memberStart[i + 1]; ++m) {
            const size_t k = size_t(c.members[m]);
            dg += f.diag[k];
            for (uint32_t e = f.start[k]; e < f.start[k + 1]; ++e) {
                const float wt = f.w.empty() ? 1.0f : f.w[e];
                const int32_t J = f.agg[size_t(f.col[e])];
                if (J == int32_t(i)) {
                    dg -= double(wt);
                    continue;
                }
                int32_t& at = where[size_t(J)];
                if (at < 0) {
                    at = int32_t(row.size());
                    row.emplace_back(J, wt);
                } else {
                    row[size_t(at)].second += wt;
                }
            }
        }
        c.diag[i] = dg;
        for (const auto& q : row) {
            c.col.push_back(q.first);
            c.w.push_back(q.second);
            where[size_t(q.first)] = -1;
        }
    }
    c.start[c.n] = uint32_t(c.col.size());
    finish(c);
    ++mUsed;
    return true;
}

void Multigrid::factor(Level& l)
{
    const size_t n = l.n;
    std::vector<double>& a = l.chol;
    a.assign(n * n, 0.0);
    for (size_t k = 0; k < n; ++k) {
        a[k * n + k] = l.diag[k];
        for (uint32_t e = l.start[k]; e < l.start[k + 1]; ++e)
            a[k * n + size_t(l.col[e])] -= l.w.empty() ? 1.0 : double(l.w[e]);
    }
    for (size_t j = 0; j < n; ++j) { // lower Cholesky factor, in place
        double d = a[j * n + j];
        for (size_t k = 0; k < j; ++k)
            d -= a[j * n + k] * a[j * n + k];
        if (!(d > 0)) return; // not SPD (never expected): Jacobi sweeps instead
        d = std::sqrt(d);
        a[j * n + j] = d;
        for (size_t i = j + 1; i < n; ++i) {
            double s = a[i * n + j];
            for (size_t k = 0; k < j; ++k)
                s -= a[i * n + k] * a[j * n + k];
            a[i * n + j] = s / d;
        }
    }
    l.dense = true;
}

inline double Multigrid::residual(const Level& l, size_t k, double own)
{
    double s = l.rhs[k] - l.diag[k] * own;
    if (l.w.empty())
        for (uint32_t e = l.start[k]; e < l.start[k + 1]; ++e)
            s += l.x[size_t(l.col[e])];
    else
        for (uint32_t e = l.start[k]; e < l.start[k + 1]; ++e)
            s += double(l.w[e]) * l.x[size_t(l.col[e])];
    return s;
}

inline double Multigrid::residualByPlace(size_t i, double own) const
{
    const ColourOrder& o = mFine;
    const int32_t* nb = &o.nb6[i * 6];
    const double* x = o.x.data();
    double s = o.rhs[i] - double(o.faces[i]) * own;
    s += x[nb[0]];
    s += x[nb[1]];
    s += x[nb[2]];
    s += x[nb[3]];
    s += x[nb[4]];
    s += x[nb[5]];
    return s;
}

void Multigrid::sweep(Level& l)
{
    forChunks(l.n, mSerial, [&](size_t lo, size_t hi) {
        for (size_t k = lo; k < hi; ++k) {
            l.t[k] = l.x[k] + kOmega * l.invDiag[k] * residual(l, k, l.x[k]);
        }
    });
    l.x.swap(l.t);
}

void Multigrid::halfSweep(Level& l, int c, bool fromZero)
{
    const int32_t* rows = l.byColour.data() + (c ? l.red : 0);
    forChunks(c ? l.n - l.red : l.red, mSerial, [&](size_t lo, size_t hi) {
        if (fromZero) {
            // x_k was 0 (not yet written): x_k = +0 + D^-1 (r - A x)_k with x_k = 0 in the residual,
            // the very operations of the update from a zero-filled x; and t_k = 0 (this colour's
            // residual after the half-sweep) for the restriction.
            for (size_t q = lo; q < hi; ++q) {
                const size_t k = size_t(rows[q]);
                l.x[k] = 0.0 + l.invDiag[k] * residual(l, k, 0.0);
                l.t[k] = 0.0;
            }
            return;
        }
        for (size_t q = lo; q < hi; ++q) {
            const size_t k = size_t(rows[q]);
            l.x[k] += l.invDiag[k] * residual(l, k, l.x[k]);
        }
    });
}

void Multigrid::restrictTo(Level& c, const uint32_t* start, const int32_t* members, const double* t)
{
    forChunks(c.n, mSerial, [&](size_t lo, size_t hi) {
        for (size_t i = lo; i < hi; ++i) {
            double s = 0;
            for (uint32_t m = start[i]; m < start[i + 1]; ++m)
                s += t[size_t(members[m])];
            c.r[i] = s;
        }
    });
}

void Multigrid::cycleFinest(const double* in, double* out)
{
    const Level& f = mLevels.front();
    Level& c = mLevels[1];
    ColourOrder& o = mFine;
    const size_t n = f.n, red = f.red;
    const int32_t* row = f.byColour.data();
    // Pre-smoothing from x = 0, as cycle() does (the right-hand side copied in by place on the way):
    // red x = D^-1 r, then a black half-sweep from x = 0 (its residual is then 0), then the red
    // residual in t.
    forChunks(red, mSerial, [&](size_t lo, size_t hi) {
        for (size_t i = lo; i < hi; ++i) {
            o.rhs[i] = in[row[i]];
            o.x[i] = kInverseFaces[o.faces[i]] * o.rhs[i];
        }
    });
    forChunks(n - red, mSerial, [&](size_t lo, size_t hi) {
        for (size_t i = red + lo; i < red + hi; ++i) {
            o.rhs[i] = in[row[i]];
            o.x[i] = 0.0 + kInverseFaces[o.faces[i]] * residualByPlace(i, 0.0);
        }
    });
    forChunks(red, mSerial, [&](size_t lo, size_t hi) {
        for (size_t i = lo; i < hi; ++i)
            o.t[i] = residualByPlace(i, o.x[i]);
    });
    restrictTo(c, o.redStart.data(), o.redMembers.data(), o.t.data());
    cycle(1);
    // The coarse correction, red rows first; a black row's just before its post-smoothing (which reads
    // only red neighbours), in the same pass. Post-smoothing black then red, each row's last value
    // written out by row on the way.
    forChunks(red, mSerial, [&](size_t lo, size_t hi) {
        for (size_t i = lo; i < hi; ++i)
            if (o.agg[i] >= 0) o.x[i] += kAlpha * c.x[size_t(o.agg[i])];
    });
    forChunks(n - red, mSerial, [&](size_t lo, size_t hi) {
        for (size_t i = red + lo; i < red + hi; ++i) {
            if (o.agg[i] >= 0) o.x[i] += kAlpha * c.x[size_t(o.agg[i])];
            o.x[i] += kInverseFaces[o.faces[i]] * residualByPlace(i, o.x[i]);
            out[row[i]] = o.x[i];
        }
    });
    forChunks(red, mSerial, [&](size_t lo, size_t hi) {
        for (size_t i = lo; i < hi; ++i) {
            o.x[i] += kInverseFaces[o.faces[i]] * residualByPlace(i, o.x[i]);
            out[row[i]] = o.x[i];
        }
    });
}

void Multigrid::cycle(size_t li)
{
    Level& l = mLevels[li];
    if (li > 0) l.rhs = l.r.data(); // the finest level's: apply()'s input
    if (li + 1 == mUsed) {
        forChunks(l.n, mSerial, [&](size_t lo, size_t hi) {
            for (size_t k = lo; k < hi; ++k)
                l.x[k] = kOmega * l.invDiag[k] * l.rhs[k];
        });
        if (l.dense) {
            const size_t n = l.n;
            const std::vector<double>& a = l.chol;
            for (size_t i = 0; i < n; ++i) {
                double s = l.rhs[i];
                for (size_t k = 0; k < i; ++k)
                    s -= a[i * n + k] * l.x[k];
                l.x[i] = s / a[i * n + i];
            }
            for (size_t i = n; i-- > 0;) {
                double s = l.x[i];
                for (size_t k = i + 1; k < n; ++k)
                    s -= a[k * n + i] * l.x[k];
                l.x[i] = s / a[i * n + i];
            }
        } else {
            for (int s = 1; s < kCoarseSweeps; ++s)
                sweep(l);
        }
        return;
    }
    // Pre-smoothing from x = 0: red rows x = D^-1 r (their neighbours are 0), then a black
    // half-sweep. The black rows' residual is then 0; the red rows' residual goes in t. (Every
    // row's x and t is written here before it is read: no zero fill.)
    {
        const int32_t* red = l.byColour.data();
        forChunks(l.red, mSerial, [&](size_t lo, size_t hi) {
            for (size_t q = lo; q < hi; ++q) {
                const size_t k = size_t(red[q]);
                l.x[k] = l.invDiag[k] * l.rhs[k];
            }
        });
        halfSweep(l, 1, true);
        forChunks(l.red, mSerial, [&](size_t lo, size_t hi) {
            for (size_t q = lo; q < hi; ++q) {
                const size_t k = size_t(red[q]);
                l.t[k] = residual(l, k, l.x[k]);
            }
        });
    }
    Level& c = mLevels[li + 1];
    restrictTo(c, c.memberStart.data(), c.members.data(), l.t.data());
    cycle(li + 1);
    forChunks(l.n, mSerial, [&](size_t lo, size_t hi) {
        for (size_t k = lo; k < hi; ++k)
            if (l.agg[k] >= 0) l.x[k] += kAlpha * c.x[size_t(l.agg[k])];
    });
    // Post-smoothing in the adjoint order (black, then red): a symmetric V-cycle.
    halfSweep(l, 1, false);
    halfSweep(l, 0, false);
}

} // namespace transport_internal
} // namespace vdbclay
