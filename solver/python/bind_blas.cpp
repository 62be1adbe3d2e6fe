#include "mocapedit/blas_lock.h"
#include "registry.h"

namespace py = pybind11;

MOCAPEDIT_BINDINGS(BindBlas) {
  m.def(
      "blas",
      [] {
        const mocapedit::BlasInfo& b = mocapedit::Blas();
        py::dict d;
        d["name"] = b.name;
        d["concurrent"] = b.concurrent;
        return d;
      },
      "The BLAS that CHOLMOD and SPQR call in this process: {'name': str, 'concurrent': bool}.\n"
      "concurrent: several solver threads may call it at once (otherwise those calls take turns).");
}
