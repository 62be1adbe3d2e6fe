#include "mocapedit/two_threads.h"
#include "registry.h"

namespace py = pybind11;

MOCAPEDIT_BINDINGS(BindThreads) {
  m.def("thread_budget", &mocapedit::ThreadBudget,
        "How many threads the solver's jobs may use at once in this process: set_thread_budget's, "
        "else the MOCAPEDIT_THREADS environment variable's as the process first asked, else the "
        "machine's hardware threads. Each job splits its work in two at most.");
  m.def(
      "set_thread_budget",
      [](int threads) {
        if (threads < 0) throw py::value_error("threads must be 0 (the default) or more, got " + std::to_string(threads));
        mocapedit::SetThreadBudget(threads);
      },
      py::arg("threads"),
      "Sets how many threads the solver's jobs may use at once in this process (1: every job on the "
      "calling thread; the results are the same). 0 goes back to MOCAPEDIT_THREADS or the hardware's.");
}
