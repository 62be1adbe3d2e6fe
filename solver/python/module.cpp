#include <pybind11/pybind11.h>

#include <stdexcept>

#include "errors.h"
#include "registry.h"

namespace mocapedit::python {

std::vector<BindFunction>& Registry() {
  static std::vector<BindFunction> functions;
  return functions;
}

}  // namespace mocapedit::python

PYBIND11_MODULE(_solver, m) {
  m.doc() = "mocapedit's C++ solver (Eigen + SuiteSparse). Arrays in, arrays out; no USD.";
  mocapedit::python::BindErrors(m);
  for (auto fn : mocapedit::python::Registry()) fn(m);
}
