#!/usr/bin/env bash
# Sets up evomesh on a fresh Debian machine: installs the Debian packages it
# needs when they are missing (CGAL's libcgal-dev, a C++ compiler, Python headers
# and venv), creates the virtual environment .venv and installs evomesh into it
# with its test tools (building the C++ core takes a few minutes; it says so and
# shows one line per compiled file). Safe to run again: it only installs what is missing.
set -euo pipefail
cd "$(dirname "$0")/.."

sudo_cmd=()
if [ "$(id -u)" -ne 0 ]; then sudo_cmd=(sudo); fi

missing=()
dpkg -s libcgal-dev >/dev/null 2>&1 || missing+=(libcgal-dev)
command -v g++ >/dev/null 2>&1 || missing+=(g++)
# For the C++ tests and benchmarks that tools/run-tests.sh builds.
command -v cmake >/dev/null 2>&1 || missing+=(cmake)
command -v ninja >/dev/null 2>&1 || command -v make >/dev/null 2>&1 || missing+=(make)
command -v python3 >/dev/null 2>&1 || missing+=(python3)
if command -v python3 >/dev/null 2>&1; then
  python3 -c 'import ensurepip, venv' >/dev/null 2>&1 || missing+=(python3-venv)
  python3 -c 'import os, sysconfig; assert os.path.exists(os.path.join(sysconfig.get_paths()["include"], "Python.h"))' \
    >/dev/null 2>&1 || missing+=(python3-dev)
fi
if [ ${#missing[@]} -gt 0 ]; then
  echo "evomesh: installing Debian packages: ${missing[*]}"
  "${sudo_cmd[@]}" apt-get update -qq
  DEBIAN_FRONTEND=noninteractive "${sudo_cmd[@]}" apt-get install -y -qq "${missing[@]}" >/dev/null
fi

if [ ! -x .venv/bin/python ]; then
  python3 -m venv .venv
fi
# The install is skipped when the sources it is built from are the ones installed
# last time (a content hash, kept in the venv with the installed module's file
# and mtime, so an in-place developer rebuild since then counts as a change) and
# the module still imports, and the build dir below is there; an install
# recompiles only what changed there. EVOMESH_REINSTALL=1 forces it.
stamp=.venv/.evomesh-installed
source_hash="$(find CMakeLists.txt pyproject.toml cpp/include cpp/src cpp/bindings python -type f \
  ! -path '*/__pycache__/*' -print0 | LC_ALL=C sort -z | xargs -0 sha256sum | sha256sum | cut -d' ' -f1)"
installed_module() {
  .venv/bin/python -c 'import os, evomesh._core as m, pytest, hypothesis
print(m.__file__, os.stat(m.__file__).st_mtime_ns)' 2>/dev/null
}
if [ "${EVOMESH_REINSTALL:-0}" != 1 ] && [ -f "$stamp" ] && [ -f build/core/CMakeCache.txt ] &&
  [ "$(cat "$stamp")" = "$source_hash $(installed_module || echo none)" ]; then
  echo "evomesh: up to date in $(pwd)/.venv"
  exit 0
fi
rm -f "$stamp"
.venv/bin/python -m pip install -q --upgrade pip
# The build requirements go into .venv (ninja: scikit-build-core's generator),
# and the package is built without isolation in the fixed CMake build dir
# build/core: tools/run-tests.sh builds the C++ tests and benchmarks in that same
# dir against the core compiled here, so the core compiles once, and a later
# install recompiles only what changed. (The developers' in-place rebuild,
# pip install --no-build-isolation -ve . -Cbuild-dir=build/dev, uses them too.)
.venv/bin/python -m pip install -q "scikit-build-core>=0.10" "pybind11>=2.12" ninja
# pip's verbose output goes to a log; the terminal gets one line per compiled
# file, and the end of the log if the install fails.
log=.venv/evomesh-install.log
echo "evomesh: building the C++ core against CGAL and installing it with its Python dependencies"
echo "evomesh: this takes a few minutes (about 5 minutes of CPU time, 3-5 minutes on 2 idle cores); log: $(pwd)/$log"
start=$SECONDS
compile_progress() {
  local line
  while IFS= read -r line; do
    if [[ $line =~ \[([0-9]+/[0-9]+)\]\ (Building|Linking)\ .*[\ /]([^\ /]+)$ ]]; then
      echo "evomesh:   [${BASH_REMATCH[1]}] ${BASH_REMATCH[2],,} ${BASH_REMATCH[3]%.o}"
    fi
  done
}
if ! .venv/bin/python -m pip install -v --no-build-isolation -Cbuild-dir=build/core ".[test]" 2>&1 |
  tee "$log" | compile_progress; then
  echo "evomesh: the install failed; the end of $log:" >&2
  tail -n 40 "$log" >&2
  exit 1
fi
echo "$source_hash $(installed_module)" >"$stamp"
echo "evomesh: installed in $(pwd)/.venv ($((SECONDS - start)) s)"
