#!/usr/bin/env bash
# Installs the peer remeshers that benchmarks/compare_peers.py measures evomesh
# against. They are never dependencies of evomesh:
#   - MMG2D: the mmg2d_O3 binary shipped inside the pymmg 1.0.0 wheel (PyPI),
#     unpacked to build/peers/mmg2d_O3;
#   - Gmsh: the `gmsh` PyPI package (Python API), pip-installed into .venv.
# Safe to run again: it only fetches what is missing.
set -euo pipefail
cd "$(dirname "$0")/.."

py=.venv/bin/python
if [ ! -x "$py" ]; then
  echo "get-peers: no .venv; run tools/bootstrap.sh first" >&2
  exit 1
fi
peers=build/peers
mkdir -p "$peers"

if [ ! -x "$peers/mmg2d_O3" ]; then
  tmp="$(mktemp -d)"
  trap 'rm -rf "$tmp"' EXIT
  echo "get-peers: fetching the pymmg 1.0.0 wheel for mmg2d_O3"
  "$py" -m pip download --quiet --no-deps pymmg==1.0.0 -d "$tmp"
  wheel="$(ls "$tmp"/pymmg-1.0.0-*.whl | head -n 1)"
  "$py" - "$wheel" "$peers" <<'EOF'
import os, stat, sys, zipfile
wheel, dest = sys.argv[1], sys.argv[2]
with zipfile.ZipFile(wheel) as z:
    names = [n for n in z.namelist() if os.path.basename(n) == "mmg2d_O3"]
    if not names:
        sys.exit(f"get-peers: no mmg2d_O3 in {wheel}: {z.namelist()}")
    target = os.path.join(dest, "mmg2d_O3")
    with z.open(names[0]) as src, open(target, "wb") as dst:
        dst.write(src.read())
    os.chmod(target, os.stat(target).st_mode | stat.S_IXUSR | stat.S_IXGRP | stat.S_IXOTH)
    print(f"get-peers: {names[0]} -> {target}")
EOF
fi
# `mmg2d_O3 -h` exits 2 after printing its usage; check that it runs at all.
usage="$("$peers/mmg2d_O3" -h 2>&1 || true)"
grep -q MMG2D <<<"$usage" || echo "get-peers: warning: $peers/mmg2d_O3 does not run" >&2

if ! "$py" -c 'import gmsh' >/dev/null 2>&1; then
  echo "get-peers: pip-installing gmsh into .venv"
  "$py" -m pip install --quiet gmsh
fi
"$py" -c 'import gmsh; print("get-peers: gmsh", gmsh.__version__)'
echo "get-peers: mmg2d_O3 at $peers/mmg2d_O3"
