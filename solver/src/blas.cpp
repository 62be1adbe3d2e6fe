#include <dlfcn.h>

#include <cstdlib>

#include "mocapedit/blas_lock.h"

namespace mocapedit {

namespace {

// OpenBLAS's own queries, found in the already loaded BLAS (CHOLMOD and SPQR link
// libblas.so.3, which Debian's alternatives point at one of its BLAS builds).
BlasInfo Probe() {
  BlasInfo info;
  for (const char* lib : {"libblas.so.3", "libopenblas.so.0"}) {
    void* h = dlopen(lib, RTLD_LAZY | RTLD_NOLOAD);
    if (!h) continue;
    auto parallel = reinterpret_cast<int (*)()>(dlsym(h, "openblas_get_parallel"));
    auto threads = reinterpret_cast<void (*)(int)>(dlsym(h, "openblas_set_num_threads"));
    if (parallel) {
      const int mode = parallel();  // 0: serial, 1: pthreads, 2: OpenMP
      info.name = mode == 0 ? "OpenBLAS (serial)" : mode == 1 ? "OpenBLAS (pthreads)" : "OpenBLAS (OpenMP)";
      info.concurrent = mode != 0;
      if (mode != 0 && threads && !std::getenv("OPENBLAS_NUM_THREADS")) threads(1);
    } else {  // the reference BLAS, ATLAS, BLIS and MKL are reentrant
      info.name = "not OpenBLAS";
      info.concurrent = true;
    }
    dlclose(h);
    return info;
  }
  return info;
}

}  // namespace

void SerialCholmod() {
  using SetLevels = void (*)(int);
  static const SetLevels set = [] {
    void* gomp = dlopen("libgomp.so.1", RTLD_LAZY | RTLD_NOLOAD);
    if (!gomp) return SetLevels{nullptr};
    auto f = reinterpret_cast<SetLevels>(dlsym(gomp, "omp_set_max_active_levels"));
    dlclose(gomp);  // still loaded: CHOLMOD holds it
    return f;
  }();
  thread_local bool done = false;
  if (set && !done) set(0);
  done = true;
}

const BlasInfo& Blas() {
  static const BlasInfo info = Probe();
  return info;
}

}  // namespace mocapedit
