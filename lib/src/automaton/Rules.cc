#include "vdbclay/Rules.h"

#include "automaton/RulesImpl.h"

#include <cmath>

// Why E * room cannot wrap in the prorata branch (E <= A). With o over and u under cells, o + u <= 8,
// masses in [0, 2^31): E <= o (2^31 - Tc) and E <= A <= u Tc, and room <= Tc, so
// E * room <= min(o (2^31 - Tc), u Tc) * Tc. The maximum over Tc, o, u is reached near o = 5, u = 3,
// Tc = 5/8 2^31, where it is about 1.17 * 2^62 < 2^64. TestRules checks the extreme cases exactly.

namespace vdbclay {

uint64_t blockHash(const BlockKey& key)
{
    return rules_internal::hashKey(key);
}

CompiledRule compileRule(const RuleParams& params)
{
    validate(params);
    CompiledRule c;
    c.rule = params.rule;
    c.threshold = params.threshold;
    long double q = std::floor(static_cast<long double>(params.alpha) * 4294967296.0L + 0.5L);
    if (q < 1) q = 1;
    if (q > 4294967295.0L) q = 4294967295.0L;
    c.alphaQ32 = static_cast<uint64_t>(q);
    return c;
}

uint32_t repartitionBlock(const CompiledRule& rule, int n, const int32_t* mass, uint32_t valid,
                          const BlockKey& key, int64_t* out)
{
    if (n != 4 && n != 8)
        throw Error("repartitionBlock: a block has 4 (2D) or 8 (3D) cells, got " + std::to_string(n));
    return rules_internal::repartition(rule, n, mass, valid, key, out);
}

} // namespace vdbclay
