// MIC(0) (Mic0.h: the design).

#include "transport/Mic0.h"

namespace vdbclay {
namespace transport_internal {

void Mic0::factor(size_t n, const std::vector<int32_t>& nb, const std::vector<uint8_t>& faces)
{
    mN = n;
    mRows.resize(n * 6);
    for (size_t e = 0; e < n * 6; ++e)
        mRows[e] = nb[e] >= 0 ? nb[e] : int32_t(n);
    std::vector<double> piv(n);
    mInv.assign(n, 0.0);
    // A row's even faces (-x, -y, -z) are its lower rows and its odd faces its upper ones: the
    // factor reads only those (the same terms in the same order).
    std::vector<uint8_t> upper(n);
    for (size_t k = 0; k < n; ++k)
        upper[k] = uint8_t((nb[k * 6 + 1] >= 0) + (nb[k * 6 + 3] >= 0) + (nb[k * 6 + 5] >= 0));
    constexpr double tau = 0.97, safety = 0.25;
    for (size_t k = 0; k < n; ++k) {
        const double diag = double(faces[k]);
        double e = diag;
        for (int d = 0; d < 6; d += 2) {
            const int32_t j = nb[k * 6 + size_t(d)];
            if (j < 0) continue;
            e -= (1.0 + tau * double(upper[size_t(j)] - 1)) / piv[size_t(j)];
        }
        if (e < safety * diag) e = diag;
        piv[k] = e;
        mInv[k] = 1.0 / e;
    }
    mW.resize(n + 1);
    mW[n] = -0.0;
}

void Mic0::apply(const std::vector<double>& in, std::vector<double>& out)
{
    const size_t n = mN;
    out.resize(n + 1);
    out[n] = -0.0;
    std::vector<double>& w = mW;
    const std::vector<double>& inv = mInv;
    // The lower faces (even) in order, then the upper ones (odd), each missing face adding
    // w[n] = out[n] = -0: the additions of a loop over the present faces, zeros' signs too.
    const int32_t* rows = mRows.data();
    for (size_t k = 0; k < n; ++k) { // (D + L) w = in
        const int32_t* row = rows + k * 6;
        double s = in[k];
        s += w[size_t(row[0])];
        s += w[size_t(row[2])];
        s += w[size_t(row[4])];
        w[k] = s * inv[k];
    }
    for (size_t k = n; k-- > 0;) { // (D + L)^T out = D w
        const int32_t* row = rows + k * 6;
        double s = 0;
        s += out[size_t(row[1])];
        s += out[size_t(row[3])];
        s += out[size_t(row[5])];
        out[k] = w[k] + s * inv[k];
    }
}

void Mic0::release()
{
    std::vector<double>().swap(mInv);
    std::vector<double>().swap(mW);
}

} // namespace transport_internal
} // namespace vdbclay
