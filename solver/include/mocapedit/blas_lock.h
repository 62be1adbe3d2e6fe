// One lock for the calls that spend their time in BLAS and LAPACK (CHOLMOD's supernodal
// factorization and solves, SPQR).
//
// tools/system-deps.sh installs Debian's serial OpenBLAS ("SINGLE_THREADED", built without
// locking): two threads inside it at once corrupt each other's results. Measured: two
// threads each factoring a group mesh with CHOLMOD's supernodal Cholesky failed 2 to 11
// times in 20 ("matrix not positive definite"), and the path solve fell back to QR whose
// refinement then did not converge; with the reference BLAS, or one thread at a time, never.
// The solver runs independent components on threads of its own, so every such call holds
// this lock; work outside BLAS (assembly, orderings, simplicial and envelope
// factorizations) still runs in parallel.
#pragma once

#include <mutex>

namespace mocapedit {

inline std::mutex& BlasMutex() {
  static std::mutex m;
  return m;
}

}  // namespace mocapedit
