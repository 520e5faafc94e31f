// The random generator of the tests: xorshift64, seeded through a golden-ratio multiply. The golden
// scenes (TestGolden.cc) are generated with it, so it must never change.
#pragma once

#include <cstdint>

namespace vdbclay_test {

struct Rng {
    uint64_t s;
    explicit Rng(uint64_t seed) : s(seed * 0x9E3779B97F4A7C15ull + 1) {}
    uint64_t next()
    {
        s ^= s << 13;
        s ^= s >> 7;
        s ^= s << 17;
        return s;
    }
    /// Uniform enough in [lo, hi] for tests (modulo bias is part of the golden values).
    int range(int lo, int hi) { return lo + int(next() % uint64_t(hi - lo + 1)); }
};

} // namespace vdbclay_test
