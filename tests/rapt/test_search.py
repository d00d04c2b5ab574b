"""rapt.search as a caller meets it: shapes, units, determinism, failures, resuming a killed study, executors."""

import concurrent.futures as cf
import os
import signal
import subprocess
import sys
import textwrap
import time
from pathlib import Path

import numpy as np
import pytest

import rapt
from rapt.samplers import Sampler
from rapt.store import StudyStore
from tests.support.systems import disk, first_of_two_outputs, flaky, projecting, two_outputs

ROOT = Path(__file__).resolve().parents[2]


def test_public_contract_shapes_and_order():
    study = rapt.search(disk, [(0, 1), (0, 1)], budget=450, method="s-ndv", batch_size=100, seed=0)
    assert study.X.shape == (450, 2) and study.Y.shape == (450, 1)
    assert study.batch.tolist() == sorted(study.batch.tolist())
    assert np.bincount(study.batch).tolist() == [100, 100, 100, 100, 50]
    assert np.array_equal(study.Y, disk(study.X))
    assert study.output_types == ("binary",)


def test_physical_units_reach_fn_and_come_back():
    seen = []

    def fn(X):
        seen.append(X.copy())
        return (X[:, :1] > 50).astype(float)

    study = rapt.search(fn, [(0, 100), (-5, 5)], budget=200, method="nndv", batch_size=50, seed=1)
    allx = np.vstack(seen)
    assert allx[:, 0].min() >= 0 and allx[:, 0].max() <= 100 and allx[:, 0].max() > 10
    assert np.allclose(study.X, allx)
    assert np.allclose(study.U, (allx - [0, -5]) / [100, 10])


@pytest.mark.parametrize("method", list(rapt.METHODS))
def test_every_method_is_deterministic(method):
    budget = 120 if method == "gpr" else 300
    a = rapt.search(two_outputs, [(0, 1)] * 3, budget, method=method, batch_size=40, seed=11)
    b = rapt.search(two_outputs, [(0, 1)] * 3, budget, method=method, batch_size=40, seed=11)
    assert np.array_equal(a.X, b.X) and np.array_equal(a.Y, b.Y)


def test_failed_rows_are_stored_and_kept_out_of_the_metamodel(tmp_path):
    db = tmp_path / "flaky.db"
    study = rapt.search(
        flaky,
        [(0, 1), (0, 1)],
        budget=600,
        method="nndv",
        batch_size=50,
        seed=3,
        store=db,
        chunk_size=10,
        executor=cf.ThreadPoolExecutor(2),
    )
    assert study.n_evaluated == 600
    assert len(study.failures) == study.X_failed.shape[0] > 0
    assert any(r == "score row contains NaN or inf" for r in study.failures)
    assert any(r.startswith("RuntimeError: simulator crashed") for r in study.failures)
    assert np.all(np.isfinite(study.Y))
    assert np.all(study.X[:, 0] >= 0.1)  # NaN rows never reached the successful set
    assert study.sampler.n_told == study.X.shape[0]
    with StudyStore(db) as s:
        statuses = [r[4] for r in s.samples()]
        assert statuses.count("failed") == len(study.failures) and s.count() == 600


def test_a_system_that_always_fails_stops_the_study():
    def broken(X):
        raise KeyError("missing scenario file")

    with pytest.raises(rapt.RunError, match="every row of the first 3 batches failed.*missing scenario file"):
        rapt.search(broken, [(0, 1)], budget=1000, method="sobol", batch_size=10)


def test_projected_states_are_what_the_study_records():
    study = rapt.search(projecting, [(0, 1), (0, 1)], budget=200, method="nndv", batch_size=50, seed=0)
    assert np.allclose(study.X, np.round(study.X / 0.05) * 0.05)
    assert np.array_equal(study.sampler.X, study.U)


@pytest.mark.parametrize(
    "kwargs, match",
    [
        (dict(bounds=[(1, 0)]), "bounds: dimension 0 has low=1.0 >= high=0.0"),
        (dict(budget=50, batch_size=100), "budget: 50 is smaller than batch_size 100"),
        (dict(method="lola"), "method: unknown method 'lola'; allowed: random, sobol, lhs, gpr, nndv, s-ndv"),
        (dict(budget=0), "budget: expected a positive integer"),
        (dict(seed=-1), "seed: expected a non-negative"),
        (dict(output_types=("ordinal",)), "output_types: unknown type 'ordinal'"),
        (dict(executor="local"), "executor: expected None"),
    ],
)
def test_bad_arguments_raise_value_errors_naming_them(kwargs, match):
    args = dict(fn=disk, bounds=[(0, 1), (0, 1)], budget=200, method="nndv", batch_size=100)
    args.update(kwargs)
    with pytest.raises(ValueError, match=match):
        rapt.search(**args)


def test_wrong_shape_from_fn_is_a_value_error():
    with pytest.raises(ValueError, match=r"fn: returned scores of shape \(3, 1\) for 10 states"):
        rapt.search(lambda X: np.zeros((3, 1)), [(0, 1)], budget=20, batch_size=10)
    calls = []

    def changes_width(X):
        calls.append(1)
        return np.zeros((len(X), 1 if len(calls) == 1 else 2))

    with pytest.raises(ValueError, match=r"expected \(10, 1\)"):
        rapt.search(changes_width, [(0, 1)], budget=30, batch_size=10, method="sobol")


def test_store_resumes_and_extends_without_rerunning(tmp_path):
    db = tmp_path / "s.db"
    calls = []

    def counted(X):
        calls.append(len(X))
        return disk(X)

    first = rapt.search(counted, [(0, 1), (0, 1)], budget=300, method="s-ndv", batch_size=100, seed=5, store=db)
    assert sum(calls) == 300
    again = rapt.search(counted, [(0, 1), (0, 1)], budget=300, method="s-ndv", batch_size=100, seed=5, store=db)
    assert sum(calls) == 300 and np.array_equal(again.X, first.X)
    longer = rapt.search(counted, [(0, 1), (0, 1)], budget=500, method="s-ndv", batch_size=100, seed=5, store=db)
    assert sum(calls) == 500
    straight = rapt.search(disk, [(0, 1), (0, 1)], budget=500, method="s-ndv", batch_size=100, seed=5)
    assert np.array_equal(longer.X, straight.X)


class _FinishesEarly(Sampler):
    """Random points until ``total`` were asked, then none: a sampler that finishes early (the Sampler contract).

    Its end depends only on the ask counters, so a resumed (fast-forwarded) copy ends where the original did.
    """

    name = "finishes-early"

    def __init__(self, dim, *, seed=0, output_types=None, total=25):
        super().__init__(dim, seed=seed, output_types=output_types)
        self.total = total

    def _propose(self, n, rng):
        return rng.random((max(0, min(n, self.total - self.n_asked)), self.dim))


def test_a_sampler_that_finishes_early_ends_the_study(tmp_path, monkeypatch):
    monkeypatch.setitem(rapt.METHODS, _FinishesEarly.name, _FinishesEarly)
    db = tmp_path / "early.db"
    calls = []

    def counted(X):
        calls.append(len(X))
        return disk(X)

    study = rapt.search(counted, [(0, 1), (0, 1)], budget=100, method="finishes-early", batch_size=10, seed=4, store=db)
    assert calls == [10, 10, 5]  # the short batch counts 5 against the budget, then the empty ask ends it
    assert study.n_evaluated == 25 and np.bincount(study.batch).tolist() == [10, 10, 5]
    assert study.sampler.done and (study.sampler.n_batches, study.sampler.n_asked) == (3, 25)
    with StudyStore(db) as s:
        assert [len(asked) for _, asked in s.batches()] == [10, 10, 5]  # no empty batch recorded
    again = rapt.search(counted, [(0, 1), (0, 1)], budget=200, method="finishes-early", batch_size=10, seed=4, store=db)
    assert calls == [10, 10, 5]  # resumed: the replayed sampler has nothing left to ask
    assert np.array_equal(again.X, study.X) and again.sampler.done


def test_store_refuses_a_different_study(tmp_path):
    db = tmp_path / "s.db"
    rapt.search(disk, [(0, 1), (0, 1)], budget=100, method="nndv", batch_size=50, seed=5, store=db)
    with pytest.raises(ValueError, match="store: .* holds a study with seed=5, not 6; pass the same seed"):
        rapt.search(disk, [(0, 1), (0, 1)], budget=100, method="nndv", batch_size=50, seed=6, store=db)
    with pytest.raises(ValueError, match="method='nndv'"):
        rapt.search(disk, [(0, 1), (0, 1)], budget=100, method="sobol", batch_size=50, seed=5, store=db)
    (tmp_path / "junk.db").write_bytes(b"this is not sqlite at all" * 100)
    with pytest.raises(ValueError, match="not a RAPT study database"):
        rapt.search(disk, [(0, 1), (0, 1)], budget=100, store=tmp_path / "junk.db")


KILLED_STUDY = textwrap.dedent("""
    import os, sys, time
    import numpy as np
    sys.path.insert(0, {root!r})
    import rapt
    from tests.support.systems import disk

    progress = {progress!r}

    def slow(X):
        n = len(open(progress).read()) if os.path.exists(progress) else 0
        with open(progress, "a") as f:
            f.write("x")
        if n >= 5:
            time.sleep(60)   # the parent kills us here, mid-batch
        return disk(X)

    rapt.search(slow, [(0, 1), (0, 1)], budget=1000, method="s-ndv", batch_size=100, seed=9,
                store={db!r}, executor=None)
""")


def test_study_killed_mid_run_resumes_to_the_uninterrupted_result(tmp_path):
    db, progress = str(tmp_path / "killed.db"), str(tmp_path / "progress")
    script = tmp_path / "run.py"
    script.write_text(KILLED_STUDY.format(root=str(ROOT), progress=progress, db=db))
    proc = subprocess.Popen([sys.executable, str(script)])
    try:
        deadline = time.time() + 60
        while time.time() < deadline:
            if os.path.exists(progress) and len(open(progress).read()) >= 6:
                break
            time.sleep(0.05)
        else:
            pytest.fail("study did not reach the sixth batch")
        time.sleep(0.2)
        proc.send_signal(signal.SIGKILL)
    finally:
        proc.wait(timeout=30)
    with StudyStore(db) as s:
        assert s.count() == 500  # five batches on disk, the sixth was in flight
    calls = []

    def counted(X):
        calls.append(len(X))
        return disk(X)

    resumed = rapt.search(counted, [(0, 1), (0, 1)], budget=1000, method="s-ndv", batch_size=100, seed=9, store=db)
    assert sum(calls) == 500  # nothing evaluated twice
    straight = rapt.search(disk, [(0, 1), (0, 1)], budget=1000, method="s-ndv", batch_size=100, seed=9)
    assert np.array_equal(resumed.X, straight.X) and np.array_equal(resumed.Y, straight.Y)


def test_partially_evaluated_batch_is_completed_not_rerun(tmp_path):
    """Chunks of a batch reach the store as they finish; a resume evaluates only the rest."""
    db = tmp_path / "p.db"
    state = {"n": 0}

    def dies_in_batch_3(X):
        state["n"] += 1
        if state["n"] == 14:  # batch 4 (chunks of 25 -> 4 per batch), second chunk
            raise KeyboardInterrupt
        return disk(X)

    with pytest.raises(KeyboardInterrupt):
        rapt.search(
            dies_in_batch_3,
            [(0, 1), (0, 1)],
            budget=400,
            method="nndv",
            batch_size=100,
            seed=2,
            store=db,
            chunk_size=25,
            executor=_Serial(),
        )
    with StudyStore(db) as s:
        stored = s.count()
    # Batches 1-3 are on disk, plus whichever chunks of batch 4 were collected before the
    # interrupt surfaced (futures complete in no fixed order).
    assert stored in (300, 325, 350, 375)
    calls = []

    def counted(X):
        calls.append(len(X))
        return disk(X)

    resumed = rapt.search(
        counted,
        [(0, 1), (0, 1)],
        budget=400,
        method="nndv",
        batch_size=100,
        seed=2,
        store=db,
        chunk_size=25,
        executor=_Serial(),
    )
    assert sum(calls) == 400 - stored
    straight = rapt.search(disk, [(0, 1), (0, 1)], budget=400, method="nndv", batch_size=100, seed=2)
    assert np.array_equal(resumed.X, straight.X)


class _Serial(cf.Executor):
    """Runs each task at submit time in this thread (deterministic chunk order)."""

    _max_workers = 2

    def submit(self, fn, *args, **kwargs):
        fut = cf.Future()
        try:
            fut.set_result(fn(*args, **kwargs))
        except BaseException as exc:  # delivered through the future, like a worker's crash
            fut.set_exception(exc)
        return fut


def test_process_pool_gives_the_same_study_as_in_process():
    local = rapt.search(two_outputs, [(0, 1)] * 3, budget=400, method="s-ndv", batch_size=100, seed=4)
    with cf.ProcessPoolExecutor(max_workers=2) as pool:
        pooled = rapt.search(
            two_outputs, [(0, 1)] * 3, budget=400, method="s-ndv", batch_size=100, seed=4, executor=pool
        )
    assert np.array_equal(local.X, pooled.X) and np.array_equal(local.Y, pooled.Y)


def test_dask_local_cluster_gives_the_same_study():
    distributed = pytest.importorskip("distributed")
    local = rapt.search(disk, [(0, 1), (0, 1)], budget=300, method="nndv", batch_size=100, seed=8)
    with (
        distributed.LocalCluster(
            n_workers=2, threads_per_worker=1, processes=True, dashboard_address=None, host="127.0.0.1"
        ) as cluster,
        distributed.Client(cluster) as client,
    ):
        remote = rapt.search(
            disk, [(0, 1), (0, 1)], budget=300, method="nndv", batch_size=100, seed=8, executor=client, chunk_size=30
        )
    assert np.array_equal(local.X, remote.X) and np.array_equal(local.Y, remote.Y)


def test_general_state_space_passes_unit_rows():
    space = rapt.StateSpace([rapt.Continuous("t", 0, 12), rapt.Permutation("order", ("A", "B", "C"))])

    def fn(U):
        scen = space.decode(U)
        return np.array([[float(s["order"][0] == "A"), s["t"]] for s in scen])

    study = rapt.search(fn, space, budget=200, method="s-ndv", batch_size=50, seed=0)
    assert study.X.shape == (200, 4) and np.array_equal(study.X, study.U)
    assert study.output_types == ("binary", "continuous")
    assert study.scenarios()[0]["order"] in {
        p
        for p in [("A", "B", "C"), ("A", "C", "B"), ("B", "A", "C"), ("B", "C", "A"), ("C", "A", "B"), ("C", "B", "A")]
    }


def test_steer_searches_on_some_columns_and_keeps_them_all(tmp_path):
    kw = dict(bounds=[(0, 1)] * 3, budget=400, batch_size=100, seed=3)
    steered = rapt.search(two_outputs, steer=[0], output_types=("binary",), store=tmp_path / "s.db", **kw)
    alone = rapt.search(first_of_two_outputs, output_types=("binary",), **kw)
    np.testing.assert_array_equal(steered.X, alone.X)  # the sampler saw column 0 only
    np.testing.assert_array_equal(steered.Y, two_outputs(steered.X))  # every column is kept
    resumed = rapt.search(two_outputs, steer=[0], output_types=("binary",), store=tmp_path / "s.db", **kw)
    np.testing.assert_array_equal(resumed.Y, steered.Y)
    with pytest.raises(ValueError, match="steer"):
        rapt.search(two_outputs, steer=[1], output_types=("binary",), store=tmp_path / "s.db", **kw)
    with pytest.raises(ValueError, match="steer: column 5 does not exist"):
        rapt.search(two_outputs, steer=[5], **kw)
    with pytest.raises(ValueError, match="steer: expected distinct"):
        rapt.search(two_outputs, steer=[0, 0], **kw)


class _Killed(BaseException):
    """Stands for the process dying: not an Exception, so the runner does not record it as a failed chunk."""


def _graph_study(store, k=12, kill_at=None, fn=None):
    calls = [0]

    def system(X):
        calls[0] += 1
        if kill_at is not None and calls[0] == kill_at:
            raise _Killed
        return (fn or two_outputs)(X)

    return rapt.search(
        system, [(0, 1)] * 4, 3000, method="s-ndv", batch_size=250, seed=4, store=store, neighbour_graph=k
    )


def _same_graph(a, b):
    return (
        a.neighbours[0].tobytes() == b.neighbours[0].tobytes()
        and a.neighbours[1].tobytes() == b.neighbours[1].tobytes()
    )


@pytest.fixture
def small_exact_regime(monkeypatch):
    """Studies of a few thousand rows cross into the HNSW regime, as 10^5-row ones do."""
    import rapt.neighbours

    monkeypatch.setattr(rapt.neighbours, "EXACT_GRAPH_MAX_SAMPLES", 1000)


def test_neighbour_graph_is_stored_and_a_killed_study_resumes_to_the_same_graph(tmp_path, small_exact_regime):
    straight = _graph_study(None)
    assert straight.neighbours[1].shape == (len(straight.X), 12)
    db = tmp_path / "s.db"
    with pytest.raises(_Killed):
        _graph_study(db, kill_at=7)  # mid-study: six batches stored, the seventh in flight
    with StudyStore(db) as s:
        assert s.get_meta()["neighbour_graph"] == {"k": 12, "batches": 6, "rows": 1500}
    resumed = _graph_study(db)
    assert np.array_equal(resumed.X, straight.X) and _same_graph(resumed, straight)
    again = _graph_study(db)  # a finished study replays its stored graph without linking a row
    assert _same_graph(again, straight)


def test_store_without_a_graph_rebuilds_it_on_resume(tmp_path, small_exact_regime):
    """A schema-1 store (no neighbours table), or one searched without the graph or with another k."""
    straight = _graph_study(None)
    db = tmp_path / "old.db"
    with pytest.raises(_Killed):
        _graph_study(db, k=5, kill_at=9)
    with StudyStore(db) as s:  # make it a schema-1 store: no graph table
        s._db.execute("DROP TABLE neighbours")
        s._db.execute("DELETE FROM meta WHERE key = 'neighbour_graph'")
        s._db.execute("UPDATE meta SET value = '1' WHERE key = 'schema_version'")
    resumed = _graph_study(db)
    assert _same_graph(resumed, straight)
    with StudyStore(db) as s:
        assert s.get_meta()["schema_version"] == 2
    other_k = tmp_path / "k5.db"
    with pytest.raises(_Killed):
        _graph_study(other_k, k=5, kill_at=4)
    assert _same_graph(_graph_study(other_k), straight)  # the k=5 graph is dropped and rebuilt for k=12


def test_neighbour_graph_skips_failed_rows():
    def half_invalid(X):
        return np.where(X[:, :1] < 0.3, np.nan, disk(X))

    study = rapt.search(half_invalid, [(0, 1)] * 2, budget=400, method="random", batch_size=100, neighbour_graph=6)
    assert len(study.X_failed) and study.neighbours[1].shape == (len(study.X), 6)
    _, exact = rapt.boundaries.knn_graph(study.U, 6, method="exact")
    assert all(set(a) == set(b) for a, b in zip(study.neighbours[1].tolist(), exact.tolist()))
