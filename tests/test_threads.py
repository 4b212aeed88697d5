"""The parallel stages' threads seen from Python (issue 10): the default count
comes from EVOMESH_NUM_THREADS / OMP_NUM_THREADS (invalid values ignored), the
results never depend on it, and the persistent workers do not outlive a fork
(a forked child starts its own)."""
import hashlib
import multiprocessing
import os
import subprocess
import sys
import warnings
from pathlib import Path

import numpy as np
import pytest

import evomesh
from strategies import grid_mesh


def _step(threads):
    """A digest of one evolution step of a fixed mesh."""
    mesh = grid_mesh(60, 60, jitter=0.2, seed=3)
    delta = np.exp(np.random.default_rng(0).uniform(np.log(0.3), np.log(3), mesh.n_points))
    new = evomesh.evolve(mesh, delta, seed=5, threads=threads)
    # the mesh, its parent map (walked in parallel rounds) and its nn (completed in parallel)
    arrays = (new.points, new.triangles, new.kind, new.lineage.parent_triangle, new.lineage.barycentric,
              new.nn_spacing, new._nn_grew)
    return hashlib.sha256(b"".join(np.ascontiguousarray(a).tobytes() for a in arrays)).hexdigest()


@pytest.mark.skipif(not hasattr(os, "fork"), reason="needs fork()")
def test_forked_child_runs_the_parallel_stages():
    parent = _step(2)  # the worker pool now has a thread, which a forked child lacks
    with warnings.catch_warnings():
        # Python >= 3.12 warns about fork() in a multi-threaded process.
        warnings.simplefilter("ignore", DeprecationWarning)
        with multiprocessing.get_context("fork").Pool(1) as pool:
            child = pool.apply_async(_step, (3,)).get(timeout=120)
    assert child == parent


def test_thread_environment_variables_do_not_change_results():
    reference = _step(1)
    tests = Path(__file__).parent
    script = f"import sys; sys.path.insert(0, {str(tests)!r}); import test_threads; print(test_threads._step(None))"
    for variables in ({"EVOMESH_NUM_THREADS": "1"}, {"EVOMESH_NUM_THREADS": "abc", "OMP_NUM_THREADS": "3,1"}):
        env = {k: v for k, v in os.environ.items() if k not in ("EVOMESH_NUM_THREADS", "OMP_NUM_THREADS")}
        env.update(variables)
        out = subprocess.run([sys.executable, "-c", script], env=env, capture_output=True, text=True, timeout=120)
        assert out.returncode == 0, out.stderr
        assert out.stdout.split()[-1] == reference, variables


def test_sampling_that_asks_f_gives_the_same_bits_on_any_number_of_threads():
    # A sliver from a close pair: its adaptive grid asks the Apollonius graph for
    # f at block centres (Spacing_queries) from the sampling threads.
    case = np.load(Path(__file__).parent / "data" / "fuzz_sliver_refinement.npz")
    mesh = evomesh.Mesh(case["points"], case["triangles"], case["segments"], kind=case["kind"])
    digests = set()
    for threads in (1, 2, 3):
        with warnings.catch_warnings():
            warnings.simplefilter("ignore", evomesh.QualityWarning)
            new = evomesh.evolve(mesh, np.full(mesh.n_points, 0.1), seed=3, threads=threads)
        digests.add(hashlib.sha256(new.points.tobytes() + new.triangles.tobytes()).hexdigest())
    assert len(digests) == 1
