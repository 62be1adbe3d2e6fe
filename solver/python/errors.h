// Binds the solver's exception family (mocapedit/errors.h) into the module.
#pragma once

#include <pybind11/pybind11.h>

namespace mocapedit::python {

// Adds SolverError, InvalidInput, NumericalError, ContradictionError and TimeWarpConflict
// to `m` and translates the C++ exceptions into them. Runs before any other binding.
void BindErrors(pybind11::module_& m);

}  // namespace mocapedit::python
