#!/usr/bin/env bash
# Checks the Debian packages the C++ solver and its tests build against, and installs the
# missing ones with apt-get when running as root. Otherwise prints the exact command and fails.
set -euo pipefail

missing=()
need_file() { [ -e "$1" ] || missing+=("$2"); }
need_cmd()  { command -v "$1" >/dev/null 2>&1 || missing+=("$2"); }
need_glob() { compgen -G "$1" >/dev/null || missing+=("$2"); }

need_file /usr/include/eigen3/Eigen/Core              libeigen3-dev
need_file /usr/include/suitesparse/cholmod.h          libsuitesparse-dev
need_file /usr/include/suitesparse/SuiteSparseQR.hpp  libsuitesparse-dev
need_file /usr/include/gtest/gtest.h                  libgtest-dev
# CHOLMOD's supernodal factorization and SPQR spend their time in BLAS; Debian's default
# reference BLAS is several times slower than OpenBLAS. The threaded build, because the
# serial one cannot be called from two threads at once and the solver factors independent
# systems on threads of its own (it keeps each BLAS call on its calling thread).
need_glob '/usr/lib/*/openblas-pthread/libblas.so.3'  libopenblas0-pthread
need_cmd cmake   cmake
need_cmd ninja   ninja-build
need_cmd g++     g++
need_cmd python3 python3
if command -v python3 >/dev/null 2>&1; then
  python3 -c 'import venv, ensurepip' >/dev/null 2>&1 || missing+=(python3-venv)
  python3 -c 'import os, sysconfig; assert os.path.exists(os.path.join(sysconfig.get_paths()["include"], "Python.h"))' \
    >/dev/null 2>&1 || missing+=(python3-dev)
fi

if [ ${#missing[@]} -eq 0 ]; then
  exit 0
fi
# De-duplicate while keeping order.
pkgs=$(printf '%s\n' "${missing[@]}" | awk '!seen[$0]++' | tr '\n' ' ')
if [ "$(id -u)" -eq 0 ] && command -v apt-get >/dev/null 2>&1; then
  echo "mocapedit: installing Debian packages: $pkgs"
  export DEBIAN_FRONTEND=noninteractive
  apt-get update -qq
  # shellcheck disable=SC2086
  apt-get install -y -qq --no-install-recommends $pkgs
else
  echo "mocapedit: missing Debian packages: $pkgs" >&2
  echo "Install them with:" >&2
  echo "  sudo apt-get update && sudo apt-get install -y $pkgs" >&2
  exit 1
fi
