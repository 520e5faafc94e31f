#include "vdbclay/Types.h"

#include <algorithm>
#include <cmath>

namespace vdbclay {

std::string printableText(const std::string& text)
{
    static const char* hex = "0123456789abcdef";
    std::string out;
    out.reserve(text.size());
    for (const char ch : text) {
        const unsigned char c = static_cast<unsigned char>(ch);
        if (c == '\n')
            out += "\\n";
        else if (c == '\t')
            out += "\\t";
        else if (c == '\r')
            out += "\\r";
        else if (c < 32 || c == 127)
            out += std::string("\\x") + hex[c >> 4] + hex[c & 15];
        else
            out += ch;
    }
    return out;
}

const char* ruleName(Rule rule)
{
    switch (rule) {
    case Rule::Arata: return "arata";
    case Rule::Bingham: return "bingham";
    case Rule::Sorted: return "sorted";
    case Rule::Prorata: return "prorata";
    }
    return "unknown";
}

Rule parseRule(const std::string& name)
{
    if (name == "arata") return Rule::Arata;
    if (name == "bingham" || name == "rule1") return Rule::Bingham;
    if (name == "sorted" || name == "rule2") return Rule::Sorted;
    if (name == "prorata" || name == "rule3") return Rule::Prorata;
    throw Error("unknown rule \"" + name + "\": expected one of arata, bingham, sorted, prorata");
}

void validate(const RuleParams& p)
{
    if (p.threshold <= 0) {
        throw Error("threshold Tc must be > 0, got " + std::to_string(p.threshold));
    }
    if (!std::isfinite(p.alpha) || !(p.alpha > 0.0) || !(p.alpha < 1.0)) {
        throw Error("alpha must lie in the open interval (0, 1), got " + std::to_string(p.alpha));
    }
}

Box unite(const Box& a, const Box& b)
{
    if (a.empty()) return b;
    if (b.empty()) return a;
    Box r;
    for (int i = 0; i < 3; ++i) {
        r.min[i] = std::min(a.min[i], b.min[i]);
        r.max[i] = std::max(a.max[i], b.max[i]);
    }
    return r;
}

Box intersect(const Box& a, const Box& b)
{
    Box r;
    for (int i = 0; i < 3; ++i) {
        r.min[i] = std::max(a.min[i], b.min[i]);
        r.max[i] = std::min(a.max[i], b.max[i]);
    }
    return r;
}

} // namespace vdbclay
