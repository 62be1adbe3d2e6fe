// Two independent pieces of work at once: `there` on a thread of its own, `here` on the
// calling one. Both always finish; an exception from `here` is rethrown first, as if the
// two had run in turn.
#pragma once

#include <exception>
#include <thread>
#include <utility>

namespace mocapedit {

template <typename Here, typename There>
void OnTwoThreads(Here&& here, There&& there) {
  std::exception_ptr error_there;
  std::thread other([&] {
    try {
      there();
    } catch (...) {
      error_there = std::current_exception();
    }
  });
  std::exception_ptr error_here;
  try {
    here();
  } catch (...) {
    error_here = std::current_exception();
  }
  other.join();
  if (error_here) std::rethrow_exception(error_here);
  if (error_there) std::rethrow_exception(error_there);
}

}  // namespace mocapedit
