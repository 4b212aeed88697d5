"""Options in one place: the core's option types, their presets and
their validation, as Python sees them."""

import copy
import pickle
import pkgutil

import numpy as np
import pytest

import evomesh
from evomesh import DrfcOptions, FrfcOptions
from invariants import check_evolved
from strategies import grid_mesh


def test_presets_hold_what_they_promise():
    paper = FrfcOptions.paper()
    assert (paper.radius_scale, paper.boundary_scale, paper.cell_factor) == (1.0, 1.0, 1.0)
    assert not paper.ring_samples and paper.repair_ratio == 0 and not paper.quality and not paper.adaptive_cells
    assert FrfcOptions.recommended() == FrfcOptions()
    assert DrfcOptions.paper().radius_scale == 1.0 and not DrfcOptions.paper().quality
    # FRFC_DEFAULTS is the recommended preset, as Python users write it
    for name, value in evomesh.FRFC_DEFAULTS.items():
        assert evomesh.evolution.make_options("frfc", **{name: value}) == FrfcOptions.recommended()


def test_every_field_is_a_keyword_of_evolve():
    known = set(evomesh.FRFC_DEFAULTS)
    assert known == set(FrfcOptions.fields) - {"seed"}
    assert set(evomesh.DRFC_DEFAULTS) == set(DrfcOptions.fields)


@pytest.mark.parametrize("method", ["frfc", "drfc"])
def test_paper_preset_runs_and_equals_its_keywords(method):
    mesh = grid_mesh(9, 9, jitter=0.2, seed=4)
    delta = np.where(mesh.points[:, 0] < 0.5, 0.4, 2.5)
    kind = FrfcOptions if method == "frfc" else DrfcOptions
    by_object = evomesh.evolve(mesh, delta, method=method, options=kind.paper(), seed=3)
    check_evolved(mesh, by_object)
    keywords = evomesh.evolution._as_dict(kind.paper())
    by_keywords = evomesh.evolve(mesh, delta, method=method, seed=3, **keywords)
    assert by_object.points.tobytes() == by_keywords.points.tobytes()
    assert by_object.stats.get("quality_points_added") is None  # no quality pass


def test_options_object_is_not_modified_and_overrides_apply():
    options = FrfcOptions.paper()
    before = copy.copy(options)
    mesh = grid_mesh(7, 7)
    new = evomesh.evolve(mesh, 0.5, options=options, quality=True, min_angle=25.0)
    assert options == before
    assert new.stats["min_angle"] >= 25.0 - 1e-9


@pytest.mark.parametrize(
    "overrides, error, match",
    [
        ({"radius_scale": 1.5}, ValueError, "radius_scale must be in"),
        ({"min_angle": 31.0}, ValueError, "min_angle must be in"),
        ({"crowding_angle": 45.0}, ValueError, "crowding_angle"),
        ({"quality_max_fraction": -1.0}, ValueError, "quality_max_fraction"),
        ({"samples": "grid"}, ValueError, "samples must be one of"),
        ({"ring_samples": 1}, TypeError, "must be a bool"),
        ({"cell_factor": True}, TypeError, "real number"),
        ({"nope": 1}, TypeError, "unknown option"),
    ],
)
def test_validation_names_the_field(overrides, error, match):
    with pytest.raises(error, match=match):
        evomesh.evolve(grid_mesh(5, 5), 1.0, **overrides)


def test_wrong_options_type_is_refused():
    with pytest.raises(TypeError, match="FrfcOptions"):
        evomesh.evolve(grid_mesh(5, 5), 1.0, options=DrfcOptions())


def test_options_pickle_copy_and_repr():
    options = FrfcOptions.paper()
    options.min_angle = 22.5
    assert pickle.loads(pickle.dumps(options)) == options
    assert copy.deepcopy(options) == options
    assert "min_angle=22.5" in repr(options)


def test_no_module_is_hidden_by_a_function():
    import evomesh as package

    for info in pkgutil.iter_modules(package.__path__):
        attribute = getattr(package, info.name, None)
        assert attribute is None or type(attribute).__name__ == "module", info.name
