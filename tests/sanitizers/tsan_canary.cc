// A deliberate data race under TBB: scripts/test-tsan.sh builds this with -fsanitize=thread against
// the instrumented oneTBB and requires ThreadSanitizer to report it, so a broken harness (TSan not
// seeing TBB's threads, or the uninstrumented libtbb loaded) cannot pass silently. Not a unit test.
#include <tbb/blocked_range.h>
#include <tbb/parallel_for.h>
#include <tbb/task_arena.h>

#include <chrono>
#include <cstdio>
#include <thread>

static long gCounter = 0; // written by several TBB workers without synchronisation: the race

int main()
{
    tbb::task_arena arena(4);
    arena.execute([] {
        tbb::parallel_for(tbb::blocked_range<int>(0, 64, 1), [](const tbb::blocked_range<int>& r) {
            for (int i = r.begin(); i != r.end(); ++i) {
                std::this_thread::sleep_for(std::chrono::milliseconds(1));
                ++gCounter;
            }
        });
    });
    std::printf("canary: counter %ld\n", gCounter);
    return 0;
}
