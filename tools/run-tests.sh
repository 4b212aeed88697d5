#!/usr/bin/env bash
# Sets everything up (tools/bootstrap.sh), builds and runs the C++ tests (ctest,
# cpp/tests/) and builds the benchmarks, then runs ruff, mypy, the Python test
# suite and the MPI tests. Arguments go to pytest. The C++ tests and benchmarks
# are built in bootstrap's CMake build dir (build/core), against the core its
# install compiled: the core compiles once, and later runs rebuild only what
# changed. EVOMESH_SKIP_CPP_TESTS=1 skips that part. The script fails if any part fails.
set -euo pipefail
cd "$(dirname "$0")/.."
bash tools/bootstrap.sh

if [ "${EVOMESH_SKIP_CPP_TESTS:-0}" != 1 ]; then
  build=build/core  # (tools/bootstrap.sh's -Cbuild-dir)
  # cmake/ctest from the venv when pip put them there, else from PATH.
  cmake=cmake ctest=ctest
  if [ -x .venv/bin/cmake ]; then cmake=.venv/bin/cmake ctest=.venv/bin/ctest; fi
  # The tests and benchmarks turned on once (the generator, the build type and
  # the core's flags are the install's); the build step re-runs CMake when
  # CMakeLists.txt changes.
  if ! grep -q '^EVOMESH_BUILD_TESTS:BOOL=ON$' "$build/CMakeCache.txt"; then
    "$cmake" -S . -B "$build" -DEVOMESH_BUILD_TESTS=ON -DEVOMESH_BUILD_BENCH=ON >/dev/null
  fi
  # At most two compile jobs: the machines are shared.
  "$cmake" --build "$build" --parallel "${CMAKE_BUILD_PARALLEL_LEVEL:-2}"
  (cd "$build" && "$ctest" --output-on-failure)
fi

# ruff and mypy (tools/lint.sh), then the Python suite, then the MPI tests: each
# runs whatever the others gave, and the script fails at the end if any failed.
status=0
bash tools/lint.sh || status=1
.venv/bin/python -m pytest -p no:cacheprovider "$@" || status=1

# DistributedMesh, its transfers and the distributed step on MPI ranks
# (tests/test_distributed*.py: every test file that uses MPI). MPI and its
# bindings come from the package index: the mpich wheel brings the library and
# mpiexec, mpi4py the bindings (evomesh[mpi]). One, two and four ranks (the plain
# run above skips these files when mpi4py is not installed yet), oversubscribed on
# small machines (MPICH allows it by default). A failure or a hang on any rank
# makes mpiexec, and so this script, fail: each test runs under a watchdog
# (tests/mpi_support.py: 120 s, then the rank exits with its traceback), and each
# mpiexec under `timeout` (30 minutes) for a hang outside a test.
# EVOMESH_SKIP_MPI_TESTS=1 skips it.
if [ "${EVOMESH_SKIP_MPI_TESTS:-0}" != 1 ]; then
  if [ ! -x .venv/bin/mpiexec ] || ! .venv/bin/python -c 'import mpi4py' >/dev/null 2>&1; then
    echo "evomesh: installing mpich and mpi4py into .venv for the MPI tests"
    .venv/bin/python -m pip install -q mpich "mpi4py>=3.1"
  fi
  for ranks in 1 2 4; do
    echo "== mpiexec -n $ranks: tests/test_distributed*.py"
    timeout --kill-after=30 1800 .venv/bin/mpiexec -n "$ranks" .venv/bin/python -m pytest -q -p no:cacheprovider \
      tests/test_distributed*.py || status=1
  done
fi
exit $status
