// Calls that spend their time in BLAS and LAPACK (CHOLMOD's supernodal factorization and
// solves, SPQR) hold a BlasLock. It locks only when the BLAS loaded in this process cannot
// be entered by two threads at once.
//
// Debian's serial OpenBLAS (libopenblas0-serial: built without threads and without
// locking) is such a BLAS. Measured: two threads each factoring a group mesh with CHOLMOD's
// supernodal Cholesky failed 2 to 11 times in 20 ("matrix not positive definite"). The
// threaded OpenBLAS (libopenblas0-pthread, which tools/system-deps.sh installs), the
// reference BLAS, ATLAS, BLIS and MKL are reentrant: with them the lock does nothing, and
// independent factorizations (components, the two steps of one path solve) run at once.
#pragma once

#include <mutex>

namespace mocapedit {

// What the solver found out about the BLAS it calls, once per process.
struct BlasInfo {
  const char* name = "unknown";  // "OpenBLAS (serial)", "OpenBLAS (pthreads)", ...
  bool concurrent = false;       // several threads may call it at once (false until known)
};

// Looks the BLAS up on first use. When it is a threaded OpenBLAS and OPENBLAS_NUM_THREADS
// is not set, its calls are kept on the calling thread (the solver parallelises over
// independent factorizations instead, which beats threads inside BLAS on these small
// fronts).
const BlasInfo& Blas();

// CHOLMOD's supernodal factorization parallelises its inner loops with OpenMP on up to four
// threads. The solver runs independent factorizations on threads of its own, and on a
// two-core machine those extra threads make a group mesh's factorization slower than one
// thread does. Call this on every thread before it calls CHOLMOD: it keeps
// CHOLMOD's parallel regions on the calling thread. libgomp keeps that setting per thread:
// a thread that did not make it spawns a team for every supernode and waits for it on
// futexes. Without an OpenMP runtime loaded it does nothing.
void SerialCholmod();

class BlasLock {
 public:
  BlasLock() : lock_(Mutex(), std::defer_lock) {
    if (!Blas().concurrent) lock_.lock();
  }

 private:
  static std::mutex& Mutex() {
    static std::mutex m;
    return m;
  }
  std::unique_lock<std::mutex> lock_;
};

}  // namespace mocapedit
