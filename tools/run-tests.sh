#!/usr/bin/env bash
# Sets everything up (tools/bootstrap.sh), builds and runs the C++ tests (ctest,
# cpp/tests/) and builds the benchmarks, then runs ruff, mypy and the Python test suite.
# Arguments go to pytest. The C++ build dir build/ctest is kept, so later runs
# rebuild only what changed; EVOMESH_SKIP_CPP_TESTS=1 skips that part.
set -euo pipefail
cd "$(dirname "$0")/.."
bash tools/bootstrap.sh

if [ "${EVOMESH_SKIP_CPP_TESTS:-0}" != 1 ]; then
  build=build/ctest
  # cmake/ctest from the venv when pip put them there, else from PATH.
  cmake=cmake ctest=ctest
  if [ -x .venv/bin/cmake ]; then cmake=.venv/bin/cmake ctest=.venv/bin/ctest; fi
  # Configured once; the build step re-runs CMake when CMakeLists.txt changes.
  if [ ! -f "$build/build.ninja" ] && [ ! -f "$build/Makefile" ]; then
    configure=("$cmake" -S . -B "$build" -DCMAKE_BUILD_TYPE=Release -DEVOMESH_BUILD_TESTS=ON -DEVOMESH_BUILD_BENCH=ON)
    # The generator is fixed by the first configure of a build dir.
    if [ ! -f "$build/CMakeCache.txt" ]; then
      if [ -x .venv/bin/ninja ]; then
        configure+=(-G Ninja -DCMAKE_MAKE_PROGRAM="$(pwd)/.venv/bin/ninja")
      elif command -v ninja >/dev/null 2>&1; then
        configure+=(-G Ninja)
      fi
    fi
    "${configure[@]}" >/dev/null
  fi
  # At most two compile jobs: the machines are shared.
  "$cmake" --build "$build" --parallel "${CMAKE_BUILD_PARALLEL_LEVEL:-2}"
  (cd "$build" && "$ctest" --output-on-failure)
fi

# ruff and mypy (tools/lint.sh), then the Python suite.
bash tools/lint.sh
.venv/bin/python -m pytest -p no:cacheprovider "$@"
