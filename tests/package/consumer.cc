// Uses only vdbclay's OpenVDB-free headers, so it builds fast; links the whole library.
#include <vdbclay/Rules.h>

#include <cstdio>

int main()
{
    vdbclay::RuleParams p;
    p.rule = vdbclay::parseRule("bingham");
    const vdbclay::CompiledRule r = vdbclay::compileRule(p);
    const int32_t m[4] = {1600, 0, 0, 0};
    int64_t out[4];
    vdbclay::repartitionBlock(r, 4, m, 0xF, vdbclay::BlockKey{}, out);
    if (out[0] + out[1] + out[2] + out[3] != 1600 || out[0] != 1000) return 1;
    std::printf("consumer: ok\n");
    return 0;
}
