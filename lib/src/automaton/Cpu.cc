// The run-time CPU dispatch (see Cpu.h).
#include "automaton/Cpu.h"

namespace vdbclay {
namespace automaton_internal {

#if defined(VDBCLAY_HAVE_AVX2_BUILD)
bool cpuHasAvx2()
{
    static const bool has = [] {
        __builtin_cpu_init();
        return __builtin_cpu_supports("avx2") != 0;
    }();
    return has;
}

bool cpuHasKernelAvx2()
{
    static const bool has = [] {
        __builtin_cpu_init();
        return __builtin_cpu_supports("avx2") && __builtin_cpu_supports("bmi") &&
               __builtin_cpu_supports("bmi2") && __builtin_cpu_supports("popcnt");
    }();
    return has;
}

bool cpuHasAvx512dq()
{
    static const bool has = [] {
        __builtin_cpu_init();
        return __builtin_cpu_supports("avx512f") && __builtin_cpu_supports("avx512dq");
    }();
    return has;
}
#else
bool cpuHasAvx2()
{
    return false;
}
bool cpuHasKernelAvx2()
{
    return false;
}
bool cpuHasAvx512dq()
{
    return false;
}
#endif

} // namespace automaton_internal
} // namespace vdbclay
