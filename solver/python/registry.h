// Each binding file registers itself, so a new solver feature adds its own bind_*.cpp
// without editing a central list.
#pragma once

#include <pybind11/pybind11.h>

#include <functional>
#include <vector>

namespace mocapedit::python {

using BindFunction = void (*)(pybind11::module_&);

std::vector<BindFunction>& Registry();

struct Registration {
  explicit Registration(BindFunction fn) { Registry().push_back(fn); }
};

}  // namespace mocapedit::python

// Defines a function `void NAME(pybind11::module_& m)` that runs when _solver is imported.
#define MOCAPEDIT_BINDINGS(NAME)                                                   \
  static void NAME(pybind11::module_& m);                                          \
  static const ::mocapedit::python::Registration NAME##_registration{&NAME};       \
  static void NAME(pybind11::module_& m)
