"""Output hashes of a fixed set of steps (both methods, several options, meshes
with holes, a reflex corner and an interior constraint): a refactor leaves them
unchanged. See tests/pinned.py for how to regenerate after an intended change."""

import json

import pytest

from pinned import HASHES, compute


@pytest.fixture(scope="module")
def computed():
    return compute()


def test_every_pinned_step_reproduces_its_hash(computed):
    pinned = json.loads(HASHES.read_text())
    assert set(computed) == set(pinned)
    changed = sorted(name for name in pinned if computed[name] != pinned[name])
    assert not changed, f"outputs changed: {changed}"
