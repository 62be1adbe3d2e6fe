// Independent pieces of work at once, each on a thread of its own but the first, which runs
// on the calling thread. All always finish (threads are joined) before an exception from
// one of them is rethrown: the first piece's, as if they had run in turn.
//
// The thread budget: how many threads the library's jobs may use at once when their callers
// leave the count to them (0). The MOCAPEDIT_THREADS environment variable (a positive whole
// number) when the process first asks, else the machine's hardware threads; SetThreadBudget
// changes it for the whole process. A process that shares a machine's cores with others (a
// farm slot, one of several Dask workers) sets it to its share: with a budget of 1 every
// piece runs on the calling thread, in turn, and since the pieces are independent the results
// are the same.
#pragma once

#include <algorithm>
#include <atomic>
#include <cstddef>
#include <cstdint>
#include <cstdlib>
#include <exception>
#include <system_error>
#include <thread>
#include <utility>
#include <vector>

namespace mocapedit {

namespace detail {
inline std::atomic<int>& BudgetSet() {
  static std::atomic<int> threads{0};
  return threads;
}
inline int BudgetOfEnvironment() {
  static const int threads = [] {
    const int hardware = static_cast<int>(std::max(1u, std::thread::hardware_concurrency()));
    const char* text = std::getenv("MOCAPEDIT_THREADS");
    if (text == nullptr || *text == '\0') return hardware;
    char* end = nullptr;
    const long n = std::strtol(text, &end, 10);
    return *end == '\0' && n > 0 && n <= 4096 ? static_cast<int>(n) : hardware;
  }();
  return threads;
}
}  // namespace detail

// The thread budget (see above): at least 1.
inline int ThreadBudget() {
  const int set = detail::BudgetSet().load(std::memory_order_relaxed);
  return set > 0 ? set : detail::BudgetOfEnvironment();
}

// Sets the thread budget of the process; 0 goes back to MOCAPEDIT_THREADS or the hardware's.
inline void SetThreadBudget(int threads) { detail::BudgetSet().store(std::max(threads, 0), std::memory_order_relaxed); }

// The threads of a job whose caller leaves the count to it: the jobs split their work in two
// at most, within the budget.
inline int DefaultThreads() { return std::min(2, ThreadBudget()); }

// `here` on the calling thread, `there` on a thread of its own (both on the calling thread,
// `here` first, when the budget is one thread or the system gives no thread).
template <typename Here, typename There>
void OnTwoThreads(Here&& here, There&& there) {
  std::exception_ptr error_here, error_there;
  auto run = [](auto& work, std::exception_ptr& error) {
    try {
      work();
    } catch (...) {
      error = std::current_exception();
    }
  };
  std::thread other;
  if (ThreadBudget() >= 2) {
    try {
      other = std::thread([&] { run(there, error_there); });
    } catch (const std::system_error&) {
      // No thread to be had (a farm slot's limit): both here, in turn.
    }
  }
  run(here, error_here);
  if (other.joinable())
    other.join();
  else
    run(there, error_there);
  if (error_here) std::rethrow_exception(error_here);
  if (error_there) std::rethrow_exception(error_there);
}

// work(t) for t = 0 .. threads - 1: t = 0 on the calling thread, the others on threads of
// their own (in turn on the calling thread, after its own, if the system has no thread to
// give). Rethrows the exception of the lowest t that threw.
template <typename Work>
void OnThreads(int threads, Work&& work) {
  if (threads <= 1) {
    work(0);
    return;
  }
  std::vector<std::exception_ptr> errors(static_cast<size_t>(threads));
  auto run = [&](int t) {
    try {
      work(t);
    } catch (...) {
      errors[static_cast<size_t>(t)] = std::current_exception();
    }
  };
  std::vector<std::thread> pool;
  pool.reserve(static_cast<size_t>(threads - 1));
  int started = 1;
  try {
    for (; started < threads; ++started) pool.emplace_back(run, started);
  } catch (const std::system_error&) {
    // No more threads: the rest run here.
  }
  run(0);
  for (int t = started; t < threads; ++t) run(t);
  for (auto& th : pool) th.join();
  for (const auto& e : errors)
    if (e) std::rethrow_exception(e);
}

// agent(a) for the #A agents of `offsets` (#A + 1 increasing pose offsets, agent a owning poses
// offsets[a] .. offsets[a + 1] - 1): contiguous runs of agents with about as many poses each,
// one run per thread (`threads`; 0: DefaultThreads()), agents in turn within a run.
template <typename Agent>
void OnAgentRuns(const std::int64_t* offsets, std::size_t agents, int threads, Agent&& agent) {
  const auto n = static_cast<std::size_t>(offsets[agents]);
  int count = threads > 0 ? threads : DefaultThreads();
  count = static_cast<int>(std::min<std::size_t>(static_cast<std::size_t>(count), std::max<std::size_t>(agents, 1)));
  std::vector<std::size_t> split(static_cast<std::size_t>(count) + 1, agents);
  split[0] = 0;
  for (int t = 1; t < count; ++t) {
    const auto goal = static_cast<std::int64_t>(n * static_cast<std::size_t>(t) / static_cast<std::size_t>(count));
    split[static_cast<std::size_t>(t)] =
        static_cast<std::size_t>(std::lower_bound(offsets, offsets + agents, goal) - offsets);
  }
  OnThreads(count, [&](int t) {
    for (std::size_t a = split[static_cast<std::size_t>(t)]; a < split[static_cast<std::size_t>(t) + 1]; ++a) agent(a);
  });
}

}  // namespace mocapedit
