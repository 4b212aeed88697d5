#!/usr/bin/env bash
# Build the evomesh extension with AddressSanitizer and UndefinedBehaviorSanitizer
# and run the test suite under it.
#
#   tools/sanitize.sh                      # build, then the whole suite ("ci" profile)
#   tools/sanitize.sh tests/test_fuzz.py   # build, then these pytest arguments
#   SKIP_BUILD=1 tools/sanitize.sh ...     # reuse the last sanitizer build
#
# The build has its own venv (.venv-asan) and build dir (build/asan), so the
# developer venv is untouched. On top of CMake's EVOMESH_SANITIZE=ON
# (-fsanitize=address,undefined, no recovery) it adds:
#   -fsanitize=float-cast-overflow   (not part of GCC's -fsanitize=undefined)
#   -D_GLIBCXX_ASSERTIONS            (bounds-checked std::vector/array operator[])
#   no -DNDEBUG, -O1                 (CGAL preconditions and assertions are live)
#   -DCGAL_NO_POSTCONDITIONS          (CGAL 5.5's MP_Float::split postcondition
#                                      left-shifts a negative limb: UB in C++17,
#                                      benign, and only compiled without NDEBUG)
# Any finding aborts the test process with a report on stderr; the exit status
# is then non-zero.
set -euo pipefail

root="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"
venv="${EVOMESH_ASAN_VENV:-$root/.venv-asan}"
python="$venv/bin/python"

if [[ ! -x "$python" ]]; then
  python3 -m venv "$venv"
  "$venv/bin/pip" install -q numpy scipy pybind11 scikit-build-core pytest hypothesis meshio matplotlib tqdm ninja
fi
# test dependencies added later (XDMF round trips, the scikit-fem interop)
"$venv/bin/python" -c "import h5py, skfem" 2>/dev/null || "$venv/bin/pip" install -q h5py scikit-fem

if [[ "${SKIP_BUILD:-0}" != 1 ]]; then
  # Serial compile by default: the machine is shared (override with CMAKE_BUILD_PARALLEL_LEVEL).
  CMAKE_BUILD_PARALLEL_LEVEL="${CMAKE_BUILD_PARALLEL_LEVEL:-1}" "$venv/bin/pip" install -q --no-build-isolation \
    -e "$root" -Cbuild-dir=build/asan \
    -Ccmake.build-type=RelWithDebInfo \
    -Ccmake.define.EVOMESH_SANITIZE=ON \
    "-Ccmake.define.CMAKE_CXX_FLAGS=-fsanitize=float-cast-overflow -D_GLIBCXX_ASSERTIONS -DCGAL_NO_POSTCONDITIONS" \
    "-Ccmake.define.CMAKE_CXX_FLAGS_RELWITHDEBINFO=-O1 -g -fno-omit-frame-pointer"
fi

# CPython itself is not instrumented: the sanitizer runtimes must be loaded
# first, so preload the ones the extension links against.
# (found without importing evomesh: that would load the extension unpreloaded)
so="$(ls "$venv"/lib/python3*/site-packages/evomesh/_core*.so | head -n 1)"
runtimes="$(ldd "$so" | awk '/lib(asan|ubsan)\.so/ {print $3}' | tr '\n' ' ')"
if [[ "$runtimes" != *asan* ]]; then
  echo "sanitize.sh: $so is not an ASan build" >&2
  exit 1
fi
export LD_PRELOAD="$runtimes"
# Leak checking is off: CPython keeps its interned objects alive at exit.
export ASAN_OPTIONS="detect_leaks=0:halt_on_error=1:abort_on_error=1:handle_abort=1:detect_stack_use_after_return=1:strict_init_order=1:check_initialization_order=1"
export UBSAN_OPTIONS="print_stacktrace=1:halt_on_error=1:abort_on_error=1"
# Python's small-object allocator would hide heap errors in buffers from ASan.
export PYTHONMALLOC=malloc

cd "$root"
if [[ $# -eq 0 ]]; then set -- tests; fi
# --capture=sys: pytest captures Python's output only, so a sanitizer report
# (written by the C runtime to file descriptor 2) reaches the terminal even
# when it aborts the process.
"$python" -m pytest -p no:cacheprovider -q --capture=sys "$@"
