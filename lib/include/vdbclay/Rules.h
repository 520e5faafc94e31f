/// @file Rules.h
/// @brief The repartition rules as pure functions on one Margolus block of up to eight cells.
///
/// These are the paper's formulas with what the paper leaves open settled:
/// - A cell is over when m > Tc and under otherwise; obstacle cells take no part.
///   A block with no over cell or no under cell is unchanged.
/// - arata:   dm_k = max(1, floor(alpha * m_k)) leaves each over cell k (at least one unit, so a
///            cell with m_k < 1/alpha is not stuck over forever); D = sum dm_k is shared equally.
/// - bingham: dm_k = m_k - Tc leaves each over cell, which drops to Tc; D is shared equally.
/// - sorted:  E = sum(m_k - Tc) over, A = sum(Tc - m_j) under, over cells drop to Tc.
///            E <= A: under cells are filled up to Tc emptiest first (ties broken by the block's hash).
///            E >  A: every under cell gets Tc + (E - A) / n.
/// - prorata: E, A as for sorted. E <= A: m_j += floor(E (Tc - m_j) / A).
///            E >  A (A may be 0): fill every room to Tc, then share E - A equally, as sorted does.
/// - Equal shares leave a remainder r < n (or, for prorata, the rounding loss R). It goes one unit
///   at a time to under cells in a rotation of the block's cells that starts at a counter-based hash
///   of (block origin, step, seed): a first pass over the cells that still have room (m < Tc), then a
///   second over the others. Room is judged as each unit is given, so a cell that a unit of the first
///   pass filled to Tc belongs to the second pass and may take a second unit (tests/TestOracle.cc).
///   The choice changes every step, so a remainder never cycles between the same cells, and it is
///   reproducible on any thread count.
/// - Sums and products are 64-bit. E * room never exceeds 1.2 * 2^62 for int32 masses (E <= A, see
///   Rules.cc), so no intermediate wraps; a result above INT32_MAX is returned as is (int64) for the
///   caller to refuse.
#pragma once

#include "vdbclay/Types.h"

#include <cstdint>

namespace vdbclay {

/// Identifies a block for the remainder hash: its minimum corner, the step and the run's seed.
struct BlockKey {
    int32_t x = 0, y = 0, z = 0;
    uint64_t step = 0;
    uint64_t seed = 0;
};

/// Counter-based 64-bit hash of a block key (SplitMix64 finaliser over the fields).
uint64_t blockHash(const BlockKey& key);

/// A rule compiled for the per-block kernel (alpha as a 32-bit fixed-point fraction).
struct CompiledRule {
    Rule rule = Rule::Prorata;
    int64_t threshold = 1000;
    uint64_t alphaQ32 = 1ull << 31;
};

/// @throw Error as validate(const RuleParams&).
CompiledRule compileRule(const RuleParams& params);

/// Applies @a rule to one block.
/// @param n      number of cells, 4 (2D, 2x2) or 8 (3D, 2x2x2); cell i is at offset
///               (i & 1, (i >> 1) & 1, i >> 2) from the block's minimum corner.
/// @param mass   the n masses, each >= 0.
/// @param valid  bit i set when cell i takes part (is not an obstacle).
/// @param key    the block's identity, hashed only when a remainder or a tie needs it.
/// @param out    the n new masses (64-bit; may exceed INT32_MAX, which the caller must refuse).
/// @return bit i set for each cell whose mass changed; 0 when the block is unchanged (out == mass).
uint32_t repartitionBlock(const CompiledRule& rule, int n, const int32_t* mass, uint32_t valid,
                          const BlockKey& key, int64_t* out);

} // namespace vdbclay
