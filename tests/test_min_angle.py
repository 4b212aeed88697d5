"""Evolve's promise on the quality pass (its ``quality`` option): where
no two segments meet under less than 60 degrees the result has no angle below
``min_angle``, unless the pass says it stopped (``quality_capped``) after its
bound plus twice its estimate of the points Ruppert's rules need, or is
within rounding of flat. The grid domains of tests/strategies.py (squares,
holes, notches) have only 90 and 270 degree corners. (The thin channel, and
the bound that a small angle brings back: test_thin_features.py.)"""

from __future__ import annotations

import warnings

import numpy as np
import pytest
from hypothesis import given
from hypothesis import strategies as st

import evomesh
from invariants import check_evolved
from strategies import grid_mesh, mesh_and_delta

TARGET = {"frfc": 30.0, "drfc": 20.0}


def evolve_without_warning(mesh: evomesh.Mesh, delta: np.ndarray, method: str) -> evomesh.Mesh:
    with warnings.catch_warnings():
        warnings.simplefilter("error", evomesh.QualityWarning)
        return evomesh.evolve(mesh, delta, method=method)


@given(mesh_and_delta(max_side=14), st.sampled_from(["frfc", "drfc"]))
def test_no_small_angle_means_min_angle(case, method):
    mesh, delta = case
    new = evolve_without_warning(mesh, delta, method)
    check_evolved(mesh, new)
    assert new.stats["quality_capped"] == 0
    assert evomesh.quality(new).min_angle >= TARGET[method] - 1e-9


# A rough request (delta from 0.1 to 10 at random neighbours) grades the
# selected points so steeply that the pass needs more than 0.5 n + 1000
# insertions: it used to stop there, at 26.7 degrees with frfc.
@pytest.mark.parametrize("method", ["frfc", "drfc"])
def test_a_rough_request_meets_min_angle(method):
    mesh = grid_mesh(60, 60, jitter=0.2, seed=3)
    delta = np.exp(np.random.default_rng(0).uniform(np.log(0.1), np.log(10.0), mesh.n_points))
    new = evolve_without_warning(mesh, delta, method)
    check_evolved(mesh, new)
    s = new.stats
    assert s["quality_capped"] == 0 and s["min_angle"] >= TARGET[method] - 1e-9
    # what it costs stays bounded: the pass adds at most 1.5 times the selected points
    selected = new.n_points - s["quality_points_added"] + s["quality_points_removed"]
    assert s["quality_points_added"] <= 1.5 * selected

