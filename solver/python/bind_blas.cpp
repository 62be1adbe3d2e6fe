#include "mocapedit/blas_lock.h"
#include "registry.h"

namespace py = pybind11;

MOCAPEDIT_BINDINGS(BindBlas) {
  py::class_<mocapedit::BlasInfo>(m, "BlasInfo", "The BLAS that CHOLMOD and SPQR call in this process.")
      .def_readonly("name", &mocapedit::BlasInfo::name, "its library name")
      .def_readonly("concurrent", &mocapedit::BlasInfo::concurrent,
                    "several solver threads may call it at once (otherwise those calls take turns)");
  m.def(
      "blas", [] { return mocapedit::Blas(); }, "The BLAS that CHOLMOD and SPQR call in this process (BlasInfo).");
}
