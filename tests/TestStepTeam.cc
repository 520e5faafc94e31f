// The automaton's step team (lib/src/WorkerTeam.h): every task of a job runs exactly once, a task
// waiting for the earlier rounds sees their results, and a task's exception reaches the caller. No
// OpenVDB here; the automaton's use of the team (same steps as without it) is in TestAutomaton.cc.
#include "WorkerTeam.h"

#include <gtest/gtest.h>

#include <atomic>
#include <stdexcept>
#include <vector>

using vdbclay::automaton_internal::WorkerTeam;

TEST(StepTeam, EveryTaskOfEveryJobRunsExactlyOnce)
{
    for (int n : {1, 2, 3, 8}) {
        WorkerTeam team(n);
        ASSERT_EQ(team.size(), n);
        std::vector<std::atomic<int>> runs(64);
        std::vector<std::atomic<int>> byMember(static_cast<size_t>(n));
        for (int job = 0; job < 3000; ++job) {
            const size_t tasks = 1 + size_t(job * 7 % (3 * n + 2)); // 1 .. 3n + 2, not always whole rounds
            for (auto& r : runs)
                r.store(0);
            team.run(tasks, [&](size_t t, int member) {
                ASSERT_GE(member, 0);
                ASSERT_LT(member, n);
                runs[t].fetch_add(1);
                byMember[size_t(member)].fetch_add(1);
            });
            for (size_t t = 0; t < runs.size(); ++t)
                ASSERT_EQ(runs[t].load(), t < tasks ? 1 : 0)
                    << n << " members, job " << job << ", task " << t;
        }
        int total = 0;
        for (auto& b : byMember)
            total += b.load();
        int expected = 0;
        for (int job = 0; job < 3000; ++job)
            expected += 1 + job * 7 % (3 * n + 2);
        EXPECT_EQ(total, expected);
    }
}

TEST(StepTeam, ALaterRoundSeesTheEarlierRoundsResults)
{
    // The automaton's pattern: round 0 writes pieces (plain stores), round 1 waits for them and reads.
    for (int n : {1, 2, 3, 8}) {
        WorkerTeam team(n);
        const size_t N = size_t(n);
        std::vector<uint64_t> piece(N);
        for (uint64_t job = 1; job <= 2000; ++job) {
            std::atomic<int> bad{0};
            team.run(3 * N, [&](size_t t, int) {
                if (t < N) {
                    piece[t] = job * 1000 + t;
                    return;
                }
                team.waitDone(t < 2 * N ? N : 2 * N);
                for (size_t p = 0; p < N; ++p)
                    if (piece[p] != job * 1000 + p) bad.fetch_add(1);
            });
            ASSERT_EQ(bad.load(), 0) << n << " members, job " << job;
        }
    }
}

TEST(StepTeam, ATasksExceptionReachesTheCallerAfterEveryTaskRan)
{
    for (int n : {1, 2, 3}) {
        WorkerTeam team(n);
        std::atomic<int> ran{0};
        EXPECT_THROW(team.run(2 * size_t(n) + 1,
                              [&](size_t t, int) {
                                  ran.fetch_add(1);
                                  if (t == 1) throw std::runtime_error("task 1");
                              }),
                     std::runtime_error);
        EXPECT_EQ(ran.load(), 2 * n + 1);
        ran = 0; // the team still works
        team.run(4, [&](size_t, int) { ran.fetch_add(1); });
        EXPECT_EQ(ran.load(), 4);
    }
}

TEST(StepTeam, TooManyTasksAreRefusedBeforeAnyRuns)
{
    WorkerTeam team(2);
    std::atomic<int> ran{0};
    EXPECT_THROW(team.run(team.maxTasks() + 1, [&](size_t, int) { ran.fetch_add(1); }),
                 std::invalid_argument);
    EXPECT_EQ(ran.load(), 0);
    team.run(team.maxTasks(), [&](size_t, int) { ran.fetch_add(1); });
    EXPECT_EQ(ran.load(), int(team.maxTasks()));
}
