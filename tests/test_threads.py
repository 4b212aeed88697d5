"""The parallel stages' threads seen from Python: the default count
comes from EVOMESH_NUM_THREADS / OMP_NUM_THREADS (invalid values ignored), the
results never depend on it, and the persistent workers do not outlive a fork
(a forked child starts its own)."""
import hashlib
import multiprocessing
import os
import subprocess
import sys
import threading
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


# A step with threads=k keeps at most k threads working, also in the
# threads it starts beside its stages (the early triangulation, the old mesh's
# walker, the output's nn) and in the pool's workers, which an earlier call
# with more threads left behind (several processes per node each take their
# share of the cores). Seen from the process's threads in /proc (Linux), in a
# fresh process whose default is 8 threads.
_WATCH = r"""
import json, os, sys, threading, time, warnings
import numpy as np
sys.path.insert(0, sys.argv[1])
import evomesh
from strategies import grid_mesh

def threads_now():
    # thread id -> (state, utime + stime in clock ticks)
    out = {}
    for tid in os.listdir("/proc/self/task"):
        try:
            with open(f"/proc/self/task/{tid}/stat") as f:
                fields = f.read().rsplit(")", 1)[1].split()
        except OSError:
            continue  # ended meanwhile
        out[int(tid)] = (fields[0], int(fields[11]) + int(fields[12]))
    return out

warnings.simplefilter("ignore", evomesh.QualityWarning)
mesh = grid_mesh(120, 120, jitter=0.2, seed=3)
delta = np.exp(np.random.default_rng(0).uniform(np.log(0.3), np.log(3), mesh.n_points))
evomesh.evolve(mesh, 1.0)  # the pool now has default_thread_count() - 1 = 7 workers
main = threading.get_native_id()
report = {}
for threads in (1, 2):
    for method in ("frfc", "drfc"):
        before, seen, peak, done = threads_now(), set(), [0], threading.Event()
        def watch():
            me = threading.get_native_id()
            running = set()
            while not done.is_set():
                now = {t: v for t, v in threads_now().items() if t != me}
                seen.update(now)
                # running in two samples in a row: a thread caught in its start-up (or as it
                # hands its turn on) is seen running for a moment, which is not work
                now_running = {t for t, (state, _) in now.items() if state == "R"}
                peak[0] = max(peak[0], len(now_running & running))
                running = now_running
                # a millisecond between samples: the watcher does not take a core from
                # the step (a step thread it preempts waits runnable, "R" too), and
                # "running in two samples in a row" spans a millisecond, not a few
                # microseconds of a thread's start-up or hand-over
                time.sleep(0.001)
        watcher = threading.Thread(target=watch)
        watcher.start()
        new = evomesh.evolve(mesh, delta, method=method, threads=threads)
        done.set()
        watcher.join()
        after = threads_now()
        workers = [t for t in before if t != main and t in after and after[t][1] > before[t][1]]
        report[f"{method} {threads}"] = {"peak": peak[0], "new_threads": len(seen - set(before)),
                                         "workers_that_worked": len(workers),
                                         "bits": hash((new.points.tobytes(), new.triangles.tobytes()))}
print(json.dumps(report))
"""


@pytest.mark.skipif(not sys.platform.startswith("linux"), reason="reads /proc/self/task")
def test_a_step_keeps_to_its_threads():
    env = {k: v for k, v in os.environ.items() if k not in ("EVOMESH_NUM_THREADS", "OMP_NUM_THREADS")}
    env.update(EVOMESH_NUM_THREADS="8", OPENBLAS_NUM_THREADS="1", MKL_NUM_THREADS="1", PYTHONHASHSEED="0")
    out = subprocess.run([sys.executable, "-c", _WATCH, str(Path(__file__).parent)], env=env, capture_output=True,
                         text=True, timeout=300)
    assert out.returncode == 0, out.stderr
    report = __import__("json").loads(out.stdout.split("\n")[-2])
    for method in ("frfc", "drfc"):
        one, two = report[f"{method} 1"], report[f"{method} 2"]
        # threads=1: everything on the calling thread, no thread started, no worker woken
        assert one["peak"] <= 1 and one["new_threads"] == 0 and one["workers_that_worked"] == 0, (method, one)
        # threads=2: of the pool's 7 workers, one at most (the caller is the other
        # thread); at most 3 running at once: a thread that hands its turn on (or
        # is just started, to wait for one) may be seen running for a moment
        assert two["workers_that_worked"] <= 1 and two["peak"] <= 3, (method, two)
        assert one["bits"] == two["bits"], method


def test_a_thread_limit_opened_from_python_holds_for_core_calls():
    """_core.ThreadLimit (what a step on MPI ranks opens around its core calls):
    the loops of a core call run on exactly its threads (1: none on a second
    thread), an inner limit is in force until it is left, and the results do
    not change. The core's counts of its loops show it."""
    points = np.random.default_rng(4).uniform(0, 1, (200_000, 2))
    results, counts = [], []
    for threads in (1, 3):
        with evomesh._core.ThreadLimit(threads):
            evomesh._core._parallel_counts(reset=True)
            results.append(np.asarray(evomesh._core.nn_spacing(points)))
            counts.append(evomesh._core._parallel_counts(reset=True))
    assert counts[0]["regions"] == 0, counts
    assert counts[1]["widest"] == 3 and counts[1]["peak_running"] <= 3, counts
    assert np.array_equal(results[0], results[1])
    with evomesh._core.ThreadLimit(3):
        with evomesh._core.ThreadLimit(1):
            evomesh._core._parallel_counts(reset=True)
            evomesh._core.nn_spacing(points)
            assert evomesh._core._parallel_counts(reset=True)["regions"] == 0
        evomesh._core.nn_spacing(points)
        assert evomesh._core._parallel_counts(reset=True)["widest"] == 3


def test_a_thread_limit_refuses_to_be_left_wrongly():
    with pytest.raises(ValueError, match="threads"):
        evomesh._core.ThreadLimit(-1)
    outer, inner = evomesh._core.ThreadLimit(1), evomesh._core.ThreadLimit(2)
    outer.__enter__()
    inner.__enter__()
    with pytest.raises(RuntimeError, match="before a limit entered after it"):
        outer.__exit__(None, None, None)
    inner.__exit__(None, None, None)
    errors = []

    def leave():
        try:
            outer.__exit__(None, None, None)
        except RuntimeError as error:
            errors.append(str(error))

    other = threading.Thread(target=leave)
    other.start()
    other.join()
    assert errors and "another thread" in errors[0]
    outer.__exit__(None, None, None)
    with pytest.raises(RuntimeError, match="without being entered"):
        outer.__exit__(None, None, None)
