/// @file Types.h
/// @brief Rule names, rule parameters, the box type and the error type shared by all of vdbclay.
#pragma once

#include <array>
#include <cstdint>
#include <stdexcept>
#include <string>

namespace vdbclay {

/// Every error vdbclay reports to a caller: bad input, refused states, I/O failures.
/// The message names what was wrong and where. Library code never prints or exits.
class Error : public std::runtime_error {
public:
    using std::runtime_error::runtime_error;
};

/// @a text fit for one line on a terminal: newline, tab, ESC and the other control characters
/// escaped (\n, \t, \x1b), so that a name read from a file can neither split a message into lines
/// nor send terminal escape sequences. Other bytes (UTF-8 included) are kept.
std::string printableText(const std::string& text);

/// The four repartition rules of the paper.
enum class Rule {
    Arata,   ///< Arata et al. 1999: each over cell gives the fraction alpha of its mass.
    Bingham, ///< Rule 1: each over cell gives its excess m - Tc, shared equally among under cells.
    Sorted,  ///< Rule 2: absorbance; under cells filled emptiest first (E <= A), else equal overfill.
    Prorata  ///< Rule 3: absorbance; excess shared pro rata of each under cell's room Tc - m.
};

/// "arata", "bingham", "sorted", "prorata".
const char* ruleName(Rule rule);
/// Parses a rule name (the names above; "rule1".."rule3" are accepted too).
/// @throw Error naming the unknown rule and the valid names.
Rule parseRule(const std::string& name);

/// What a block update needs to know. Cells with m > threshold are "over", the others "under".
struct RuleParams {
    Rule rule = Rule::Prorata;
    /// Tc, the threshold: a cell holds at most this much clay at rest. Must be > 0.
    int32_t threshold = 1000;
    /// Arata's rate, used by Rule::Arata only; must lie in (0, 1). Quantised to 2^-32.
    double alpha = 0.5;
};

/// @throw Error if threshold <= 0 or alpha is outside (0, 1) or not finite.
void validate(const RuleParams& params);

/// An inclusive box of voxel coordinates, like openvdb::CoordBBox but without the include.
struct Box {
    std::array<int32_t, 3> min{{0, 0, 0}};
    std::array<int32_t, 3> max{{-1, -1, -1}};
    bool empty() const { return min[0] > max[0] || min[1] > max[1] || min[2] > max[2]; }
};

/// The smallest box holding both (an empty box adds nothing).
Box unite(const Box& a, const Box& b);
/// The voxels in both (empty if none).
Box intersect(const Box& a, const Box& b);

} // namespace vdbclay
