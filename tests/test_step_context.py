"""The step context (docs/distributed-step.md section 2.3) from Python.

The core reads no environment variable; the bindings build each step's context from
the options and from EVOMESH_SITE_FILTER / EVOMESH_STAGE_PROFILE, read at every call.
Neither changes an output bit.
"""

import numpy as np

import evomesh
from strategies import grid_mesh


def _step(mesh, delta, method="frfc"):
    extra = {"incremental": False} if method == "frfc" else {}
    return evomesh.evolve(mesh, delta, seed=0, method=method, **extra)


def test_site_filter_variable_keeps_every_site_and_the_mesh(monkeypatch):
    mesh = grid_mesh(12, 12, jitter=0.2, seed=4)
    delta = np.where(mesh.points[:, 0] < 0.5, 0.3, 3.0)
    for method in ("frfc", "drfc"):
        monkeypatch.delenv("EVOMESH_SITE_FILTER", raising=False)
        filtered = _step(mesh, delta, method)
        monkeypatch.setenv("EVOMESH_SITE_FILTER", "0")
        kept = _step(mesh, delta, method)
        if method == "frfc":  # (DRFC does not report the count)
            assert filtered.stats["n_filtered_sites"] > 0 and kept.stats["n_filtered_sites"] == 0
        assert np.array_equal(kept.points, filtered.points)
        assert np.array_equal(kept.triangles, filtered.triangles)


def test_stage_profile_variable_adds_stats_only(monkeypatch):
    mesh = grid_mesh(10, 10, jitter=0.2, seed=1)
    delta = np.full(mesh.n_points, 0.7)
    monkeypatch.delenv("EVOMESH_STAGE_PROFILE", raising=False)
    plain = _step(mesh, delta)
    monkeypatch.setenv("EVOMESH_STAGE_PROFILE", "1")
    profiled = _step(mesh, delta)
    assert not any(k.startswith("cpu_seconds_") for k in plain.stats)
    assert any(k.startswith("cpu_seconds_") for k in profiled.stats)
    assert np.array_equal(plain.points, profiled.points)
    assert np.array_equal(plain.triangles, profiled.triangles)
