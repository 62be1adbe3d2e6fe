#include <gtest/gtest.h>

#include <atomic>
#include <chrono>
#include <stdexcept>
#include <string>
#include <thread>
#include <vector>

#include "mocapedit/two_threads.h"

using mocapedit::OnThreads;
using mocapedit::OnTwoThreads;

TEST(Threads, OnThreadsRunsEachPieceOnceAndTheFirstOnTheCaller) {
  for (int threads : {0, 1, 2, 5}) {
    std::vector<std::atomic<int>> runs(static_cast<size_t>(std::max(threads, 1)));
    std::thread::id first;
    OnThreads(threads, [&](int t) {
      ++runs[static_cast<size_t>(t)];
      if (t == 0) first = std::this_thread::get_id();
    });
    for (auto& r : runs) EXPECT_EQ(r.load(), 1) << threads << " threads";
    EXPECT_EQ(first, std::this_thread::get_id());
  }
}

TEST(Threads, ErrorsReachTheCallerAfterEveryPieceFinished) {
  // Pieces 1 and 3 throw; the others still run to the end, and piece 1's error arrives.
  std::atomic<int> finished{0};
  try {
    OnThreads(4, [&](int t) {
      if (t == 1 || t == 3) throw std::runtime_error("piece " + std::to_string(t));
      std::this_thread::sleep_for(std::chrono::milliseconds(20));
      ++finished;
    });
    FAIL() << "no exception";
  } catch (const std::runtime_error& e) {
    EXPECT_STREQ(e.what(), "piece 1");
  }
  EXPECT_EQ(finished.load(), 2);

  bool there_finished = false;
  try {
    OnTwoThreads([] { throw std::invalid_argument("here"); },
                 [&] {
                   std::this_thread::sleep_for(std::chrono::milliseconds(20));
                   there_finished = true;
                 });
    FAIL() << "no exception";
  } catch (const std::invalid_argument& e) {
    EXPECT_STREQ(e.what(), "here");
  }
  EXPECT_TRUE(there_finished);
  EXPECT_THROW(OnTwoThreads([] {}, [] { throw std::out_of_range("there"); }), std::out_of_range);
}

TEST(Threads, ABudgetOfOneRunsBothPiecesOnTheCallerInTurn) {
  const int before = mocapedit::ThreadBudget();
  mocapedit::SetThreadBudget(1);
  EXPECT_EQ(mocapedit::ThreadBudget(), 1);
  EXPECT_EQ(mocapedit::DefaultThreads(), 1);
  std::vector<std::thread::id> where;
  OnTwoThreads([&] { where.push_back(std::this_thread::get_id()); },
               [&] { where.push_back(std::this_thread::get_id()); });
  ASSERT_EQ(where.size(), 2u);
  EXPECT_EQ(where[0], std::this_thread::get_id());
  EXPECT_EQ(where[1], std::this_thread::get_id());
  // Both run before the first piece's error arrives, as on two threads.
  bool there_ran = false;
  try {
    OnTwoThreads([] { throw std::invalid_argument("here"); }, [&] { there_ran = true; });
    FAIL() << "no exception";
  } catch (const std::invalid_argument& e) {
    EXPECT_STREQ(e.what(), "here");
  }
  EXPECT_TRUE(there_ran);
  // Runs of agents: one, on the caller.
  const std::int64_t offsets[] = {0, 10, 20, 30, 40};
  std::vector<std::thread::id> runs(4);
  mocapedit::OnAgentRuns(offsets, 4, 0, [&](std::size_t a) { runs[a] = std::this_thread::get_id(); });
  for (const auto& id : runs) EXPECT_EQ(id, std::this_thread::get_id());
  mocapedit::SetThreadBudget(2);
  EXPECT_EQ(mocapedit::DefaultThreads(), 2);
  std::vector<std::thread::id> split(4);
  mocapedit::OnAgentRuns(offsets, 4, 0, [&](std::size_t a) { split[a] = std::this_thread::get_id(); });
  EXPECT_EQ(split[0], std::this_thread::get_id());
  EXPECT_NE(split[3], std::this_thread::get_id());
  mocapedit::SetThreadBudget(0);
  EXPECT_EQ(mocapedit::ThreadBudget(), before);
  EXPECT_GE(before, 1);
}
