// The solver's one exception family. Everything the library throws is a SolverError:
//
//   SolverError              base; what() says what went wrong and where
//   ├── InvalidInput         bad shapes, indices out of range, non-finite or out-of-range
//   │   │                    values, a job's inputs that fail its Validate()
//   │   ├── ContradictionError   path editing: hard constraints that cannot all hold
//   │   └── TimeWarpConflict     time warping: hard constraints that contradict each other
//   │                            or the minimum interval
//   └── NumericalError       a factorization or solve failed on valid input
//
// The subclasses carry what a caller needs to name the offending inputs (constraint
// indices, agents, frames) as typed members. The Python module binds the family as
// `_solver.SolverError` and subclasses of the same names, with the same members as
// attributes; InvalidInput is also a ValueError there, NumericalError a RuntimeError.
#pragma once

#include <stdexcept>
#include <string>
#include <utility>
#include <vector>

namespace mocapedit {

class SolverError : public std::runtime_error {
 public:
  explicit SolverError(const std::string& what) : std::runtime_error(what) {}
};

class InvalidInput : public SolverError {
 public:
  // where: the function or job that rejected its input ("PathEditPrecompute",
  // "LayeringJob"); what() is "where: message".
  InvalidInput(const std::string& where, const std::string& message)
      : SolverError(where + ": " + message), where(where) {}
  std::string where;

 protected:
  // For subclasses whose message stands without the prefix.
  struct Unprefixed {};
  InvalidInput(const std::string& where, const std::string& message, Unprefixed)
      : SolverError(message), where(where) {}
};

class NumericalError : public SolverError {
 public:
  NumericalError(const std::string& where, const std::string& message)
      : SolverError(where + ": " + message), where(where) {}
  std::string where;
};

// Which input of a path-editing problem a contradiction refers to: an index into
// PathEditProblem::handles, ::links or ::rigid.
struct ConstraintRef {
  enum Kind { kHandle, kLink, kRigid } kind;
  int index;
};

// Hard constraints of a path-editing problem that cannot all hold: a cycle of hard links
// (and rigid ranges) whose offsets do not add up, several hard handles on vertices tied
// together at places that disagree, or a rigid range holding more hard constraints than it
// can.
class ContradictionError : public InvalidInput {
 public:
  ContradictionError(const std::string& message, std::vector<ConstraintRef> constraints, double mismatch)
      : InvalidInput("PathEdit", message, Unprefixed{}), constraints(std::move(constraints)), mismatch(mismatch) {}
  std::vector<ConstraintRef> constraints;  // every input in the cycle, each once
  double mismatch;                         // stage units by which the cycle fails to close (0: too many)
};

// Time and sync constraints of a time-warp problem that cannot all be met.
class TimeWarpConflict : public InvalidInput {
 public:
  enum class Kind {
    kCycle,     // hard constraints fix a frame's time (or two frames' difference) twice, differently
    kBackwards  // hard constraints make time run backwards, or faster than the minimum interval allows
  };
  TimeWarpConflict(Kind kind, std::vector<int> time_constraints, std::vector<int> sync_constraints,
                   double mismatch, int agent, int frame_a, int frame_b, double gap, double minimum,
                   const std::string& message)
      : InvalidInput("TimeWarp", message),
        kind(kind),
        time_constraints(std::move(time_constraints)),
        sync_constraints(std::move(sync_constraints)),
        mismatch(mismatch),
        agent(agent),
        frame_a(frame_a),
        frame_b(frame_b),
        gap(gap),
        minimum(minimum) {}
  Kind kind;
  std::vector<int> time_constraints;  // indices into TimeWarpProblem::time_frames
  std::vector<int> sync_constraints;  // indices into TimeWarpProblem::sync_frames
  double mismatch;                    // kCycle: how far the constraints disagree (time codes)
  // kBackwards, when one agent's two frames are involved (else agent = -1): the frames,
  // the time the constraints leave between them and the least the minimum interval allows.
  int agent, frame_a, frame_b;
  double gap, minimum;
};

namespace detail {

// Throws InvalidInput(where, message) unless ok. The const char* form builds no string
// unless it throws (validation loops run it per element).
inline void Require(bool ok, const char* where, const char* message) {
  if (!ok) throw InvalidInput(where, message);
}
inline void Require(bool ok, const char* where, const std::string& message) {
  if (!ok) throw InvalidInput(where, message);
}

}  // namespace detail

}  // namespace mocapedit
