// The solver's exception family (mocapedit/errors.h) as Python classes of the same names,
// each carrying its C++ members as attributes.
#include "errors.h"

#include <pybind11/eval.h>
#include <pybind11/stl.h>

#include "mocapedit/errors.h"

namespace py = pybind11;

namespace mocapedit::python {
namespace {

// The classes, created once in BindErrors and alive as long as the interpreter.
PyObject* g_solver_error = nullptr;
PyObject* g_invalid_input = nullptr;
PyObject* g_numerical_error = nullptr;
PyObject* g_contradiction = nullptr;
PyObject* g_time_warp_conflict = nullptr;

constexpr const char* kClasses = R"(
class SolverError(Exception):
    """Base of every error the solver raises."""


class InvalidInput(SolverError, ValueError):
    """The solver rejected its input: a bad shape, an index out of range, a non-finite or
    out-of-range value. ``where`` names the solver function or job that rejected it."""

    def __init__(self, message: str, where: str = "") -> None:
        super().__init__(message)
        self.where = where


class NumericalError(SolverError, RuntimeError):
    """A factorization or solve failed on valid input. ``where`` names the solver."""

    def __init__(self, message: str, where: str = "") -> None:
        super().__init__(message)
        self.where = where


class ContradictionError(InvalidInput):
    """Hard path-editing constraints that cannot all hold. ``constraints``: list of
    (kind, index), kind one of 'handle', 'link', 'rigid', every input in the cycle;
    ``mismatch``: stage units by which the cycle fails to close."""

    def __init__(self, message: str, constraints=(), mismatch: float = 0.0) -> None:
        super().__init__(message, "PathEdit")
        self.constraints = list(constraints)
        self.mismatch = mismatch


class TimeWarpConflict(InvalidInput):
    """Time and sync constraints that cannot all be met. ``kind``: 'cycle' (they fix a time
    twice, differently; ``mismatch`` time codes apart) or 'backwards' (time would run
    backwards or below the minimum interval; when one agent's two frames are involved,
    ``agent`` >= 0, ``frames`` (a, b), the ``gap`` left between them and the ``minimum``).
    ``time_constraints`` and ``sync_constraints``: indices of the constraints involved."""

    def __init__(self, message: str, kind: str = "cycle", time_constraints=(), sync_constraints=(),
                 mismatch: float = 0.0, agent: int = -1, frames=(-1, -1), gap: float = 0.0,
                 minimum: float = 0.0) -> None:
        super().__init__(message, "TimeWarp")
        self.kind = kind
        self.time_constraints = list(time_constraints)
        self.sync_constraints = list(sync_constraints)
        self.mismatch = mismatch
        self.agent = agent
        self.frames = tuple(frames)
        self.gap = gap
        self.minimum = minimum
)";

void Raise(PyObject* type, const py::object& instance) { PyErr_SetObject(type, instance.ptr()); }

py::object Type(PyObject* type) { return py::reinterpret_borrow<py::object>(type); }

void Translate(std::exception_ptr p) {
  using namespace pybind11::literals;
  try {
    if (p) std::rethrow_exception(p);
  } catch (const ContradictionError& e) {
    static const char* kinds[] = {"handle", "link", "rigid"};
    py::list refs;
    for (const auto& r : e.constraints) refs.append(py::make_tuple(kinds[r.kind], r.index));
    Raise(g_contradiction, Type(g_contradiction)(e.what(), "constraints"_a = refs, "mismatch"_a = e.mismatch));
  } catch (const TimeWarpConflict& e) {
    Raise(g_time_warp_conflict,
          Type(g_time_warp_conflict)(
              e.what(), "kind"_a = e.kind == TimeWarpConflict::Kind::kCycle ? "cycle" : "backwards",
              "time_constraints"_a = e.time_constraints, "sync_constraints"_a = e.sync_constraints,
              "mismatch"_a = e.mismatch, "agent"_a = e.agent, "frames"_a = py::make_tuple(e.frame_a, e.frame_b),
              "gap"_a = e.gap, "minimum"_a = e.minimum));
  } catch (const InvalidInput& e) {
    Raise(g_invalid_input, Type(g_invalid_input)(e.what(), e.where));
  } catch (const NumericalError& e) {
    Raise(g_numerical_error, Type(g_numerical_error)(e.what(), e.where));
  } catch (const SolverError& e) {
    PyErr_SetString(g_solver_error, e.what());
  }
}

}  // namespace

void BindErrors(py::module_& m) {
  py::dict scope;
  scope["__builtins__"] = py::module_::import("builtins");
  scope["__name__"] = m.attr("__name__");
  py::exec(kClasses, scope);
  auto keep = [&](const char* name) {
    py::object cls = scope[name];
    m.attr(name) = cls;
    return cls.release().ptr();
  };
  g_solver_error = keep("SolverError");
  g_invalid_input = keep("InvalidInput");
  g_numerical_error = keep("NumericalError");
  g_contradiction = keep("ContradictionError");
  g_time_warp_conflict = keep("TimeWarpConflict");
  py::register_exception_translator(&Translate);
}

}  // namespace mocapedit::python
