"""Figures stay readable on dense meshes: fields with colour bars,
rasterised, small files."""

import numpy as np
import pytest

import evomesh
from evomesh import plotting
from evomesh.plotting import plot_mesh, plot_step, save


@pytest.fixture
def step():
    mesh = evomesh.unit_square_mesh(3000, seed=1)
    delta = np.where(mesh.points[:, 0] < 0.5, 0.6, 1.8)
    return mesh, evomesh.evolve(mesh, delta, seed=0), delta


@pytest.mark.parametrize("dense", [False, True])
def test_step_figure_has_a_colour_bar_and_stays_small(step, dense, monkeypatch, tmp_path):
    mesh, new, delta = step
    if dense:
        monkeypatch.setattr(plotting, "DENSE_TRIANGLES", 100)
    fig = plot_step(mesh, new, delta, title="step")
    colour_bars = [ax for ax in fig.axes if ax.get_label() == "<colorbar>"]
    assert len(colour_bars) == (3 if dense else 1)
    if dense:
        assert all(artist.get_rasterized() for ax in fig.axes[:3] for artist in ax.collections)
    path = save(fig, tmp_path / "step.png")
    assert path.stat().st_size < 500_000 or not dense


def test_dense_mesh_figure_shows_the_spacing(step, monkeypatch):
    monkeypatch.setattr(plotting, "DENSE_TRIANGLES", 100)
    fig = plot_mesh(step[1])
    assert any(ax.get_label() == "<colorbar>" for ax in fig.axes)
