"""Smoke test of an installed evomesh wheel (run by tools/build-wheel.sh).

Run it with the Python of a fresh virtual environment into which only the wheel
was installed, from a directory outside the source tree, so that the evomesh
imported is the installed one and not the repository's python/evomesh:

    cd /tmp && /path/to/venv/bin/python /path/to/evomesh/tools/smoke_test.py

It checks that
  * evomesh is imported from the environment's site-packages;
  * the C extension's GMP (and GMPXX, MPFR, if it links them) resolve, per ldd, to the
    copies bundled in the wheel (evomesh.libs/), not to the system's, and
    they are the only copies mapped into the process (/proc/self/maps);
  * evolve() runs with "frfc" (refining, delta 0.7) and "drfc" (coarsening,
    delta 2.0) on a small mesh of the unit square, and gives valid meshes:
    indices in range, every triangle counter-clockwise with positive area, the
    area of the square kept to 1e-12;
and prints the versions of Python, evomesh, numpy, scipy, GMP and MPFR.
Exits non-zero (AssertionError) on the first failed check.
"""

from __future__ import annotations

import ctypes
import platform
import re
import subprocess
import sys
import sysconfig
from pathlib import Path

SOURCE_TREE = Path(__file__).resolve().parent.parent
AREA_TOLERANCE = 1e-12
# Libraries that must come from the wheel when the extension links them.
BUNDLED = ("libgmp", "libgmpxx", "libmpfr")


def check_import_location():
    import evomesh

    package_dir = Path(evomesh.__file__).resolve().parent
    site_dirs = {Path(sysconfig.get_paths()[key]).resolve() for key in ("purelib", "platlib")}
    assert package_dir.parent in site_dirs, (
        f"evomesh imported from {package_dir}, not from this environment's site-packages {sorted(site_dirs)}"
    )
    assert SOURCE_TREE / "python" not in package_dir.parents and package_dir != SOURCE_TREE / "python" / "evomesh", (
        f"evomesh imported from the source tree ({package_dir})"
    )
    return evomesh, package_dir


def ldd(path: Path) -> dict[str, str]:
    """soname -> resolved path (or 'not found') of every dependency, per ldd."""
    out = subprocess.run(["ldd", str(path)], check=True, capture_output=True, text=True).stdout
    deps = {}
    for line in out.splitlines():
        match = re.match(r"\s*(\S+)\s+=>\s+(.*?)\s*(\(0x[0-9a-f]+\))?$", line)
        if match:
            deps[match.group(1)] = match.group(2)
    return deps


def check_bundled_libraries(package_dir: Path) -> dict[str, Path]:
    cores = sorted(package_dir.glob("_core*.so"))
    assert len(cores) == 1, f"expected one _core*.so in {package_dir}, found {cores}"
    core = cores[0]
    deps = ldd(core)
    print(f"ldd {core.name}:")
    for soname, target in deps.items():
        print(f"    {soname} => {target}")
    missing = [soname for soname, target in deps.items() if target == "not found"]
    assert not missing, f"unresolved libraries: {missing}"

    site = package_dir.parent
    bundled = {}
    for soname, target in deps.items():
        base = soname.split(".so")[0]
        # auditwheel renames a grafted library libgmp.so.10 -> libgmp-<hash>.so.10
        stem = re.sub(r"-[0-9a-f]{8}$", "", base)
        if stem not in BUNDLED:
            continue
        resolved = Path(target).resolve()
        assert site in resolved.parents and resolved.parent.name.endswith(".libs"), (
            f"{soname} resolves to {resolved}, outside the wheel's {site}/*.libs"
        )
        bundled[stem] = resolved
    assert "libgmp" in bundled, f"_core does not link a bundled libgmp (dependencies: {sorted(deps)})"
    for stem, resolved in bundled.items():
        print(f"{stem}: bundled copy {resolved.relative_to(site)}")
    return bundled


def check_loaded_libraries(site: Path) -> None:
    """After evolve() ran: every GMP/MPFR mapped into this process is the wheel's
    copy (the system's libgmp.so.10 is never loaded, per /proc/self/maps)."""
    maps = Path("/proc/self/maps")
    if not maps.exists():
        return
    loaded = {line.split(None, 5)[5].strip() for line in maps.read_text().splitlines() if len(line.split(None, 5)) == 6}
    found = sorted(path for path in loaded if re.search(r"/(libgmp|libgmpxx|libmpfr)[-.]", path))
    outside = [path for path in found if site not in Path(path).resolve().parents]
    assert found, "no GMP mapped into the process after evolve()"
    assert not outside, f"system copies of GMP/MPFR loaded: {outside}"
    print("loaded (/proc/self/maps): " + ", ".join(str(Path(path).resolve().relative_to(site)) for path in found))


def library_versions(bundled: dict[str, Path]) -> dict[str, str]:
    versions = {}
    if "libgmp" in bundled:
        gmp = ctypes.CDLL(str(bundled["libgmp"]))
        versions["GMP"] = ctypes.c_char_p.in_dll(gmp, "__gmp_version").value.decode()
    if "libmpfr" in bundled:
        mpfr = ctypes.CDLL(str(bundled["libmpfr"]))
        mpfr.mpfr_get_version.restype = ctypes.c_char_p
        versions["MPFR"] = mpfr.mpfr_get_version().decode()
    return versions


def check_mesh(mesh, what: str, area: float) -> None:
    n = mesh.n_points
    assert mesh.n_triangles > 0, f"{what}: no triangles"
    assert mesh.triangles.min() >= 0 and mesh.triangles.max() < n, f"{what}: triangle index out of range"
    areas = mesh.triangle_areas
    assert (areas > 0).all(), f"{what}: {(areas <= 0).sum()} triangles with area <= 0 (min {areas.min():.3e})"
    assert abs(mesh.area - area) <= AREA_TOLERANCE * area, (
        f"{what}: area {mesh.area!r} differs from {area!r} by {abs(mesh.area - area):.3e}"
    )
    assert mesh.euler_characteristic() == 1, f"{what}: Euler characteristic {mesh.euler_characteristic()}, not 1"


def main() -> int:
    evomesh, package_dir = check_import_location()
    bundled = check_bundled_libraries(package_dir)

    mesh = evomesh.unit_square_mesh(500)
    check_mesh(mesh, "input", 1.0)
    refined = evomesh.evolve(mesh, 0.7, seed=0)
    check_mesh(refined, "frfc, delta 0.7", 1.0)
    assert refined.n_points > mesh.n_points, f"frfc 0.7 did not refine: {mesh.n_points} -> {refined.n_points}"
    again = evomesh.evolve(mesh, 0.7, seed=0)
    assert (again.points == refined.points).all() and (again.triangles == refined.triangles).all(), (
        "frfc with the same seed is not reproducible"
    )
    coarse = evomesh.evolve(mesh, 2.0, method="drfc")
    check_mesh(coarse, "drfc, delta 2.0", 1.0)
    assert coarse.n_points < mesh.n_points, f"drfc 2.0 did not coarsen: {mesh.n_points} -> {coarse.n_points}"
    print(f"mesh: {mesh.n_points} points, {mesh.n_triangles} triangles")
    print(f"frfc 0.7: {refined.n_points} points, {refined.n_triangles} triangles, area error {abs(refined.area - 1):.1e}")
    print(f"drfc 2.0: {coarse.n_points} points, {coarse.n_triangles} triangles, area error {abs(coarse.area - 1):.1e}")

    check_loaded_libraries(package_dir.parent)

    import numpy
    import scipy

    versions = {
        "Python": platform.python_version(),
        "evomesh": evomesh.__version__,
        "numpy": numpy.__version__,
        "scipy": scipy.__version__,
        **library_versions(bundled),
    }
    print("versions: " + ", ".join(f"{name} {version}" for name, version in versions.items()))
    print(f"evomesh from {package_dir}")
    print("smoke test passed")
    return 0


if __name__ == "__main__":
    if Path.cwd().resolve() == SOURCE_TREE or SOURCE_TREE in Path.cwd().resolve().parents:
        print(f"warning: running inside the source tree {SOURCE_TREE}", file=sys.stderr)
    sys.exit(main())
