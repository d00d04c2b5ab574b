"""``rapt.search``: run a boundary search against a vectorised system under test.

The runner owns everything a sampler must not: calling the system, splitting batches
over an executor, recording failures, and persisting every evaluated row so that a study
killed halfway resumes without re-running or duplicating a single point.
"""

from __future__ import annotations

import concurrent.futures as cf
import math
import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from rapt.errors import FileFormatError, InputError, RunError, StudyMismatchError
from rapt.executors import resolve_executor
from rapt.neighbours import GrowingGraph
from rapt.samplers import METHODS, Sampler, make_sampler
from rapt.scores import check_output_types, infer_output_types
from rapt.space import StateSpace
from rapt.store import SCHEMA_VERSION, StudyStore

__all__ = ["search", "Study"]

#: Stop a study whose first batches all failed: the system is broken, not the scenarios.
_ALL_FAILED_BATCHES = 3


@dataclass
class Study:
    """The result of :func:`search`.

    ``X`` (N, d) and ``Y`` (N, m) are the successfully evaluated samples in evaluation order,
    ``X`` in the units ``fn`` received (physical for bounds, unit cube for a general
    :class:`StateSpace`); ``U`` holds the same states in the unit cube.  Failed rows are in
    ``X_failed`` with one ``failures`` reason each.

    ``neighbours`` is the graph grown during the search when ``neighbour_graph=k`` was
    asked for: ``(dist, idx)``, (N, k) float32 and int32, each row's nearest other rows
    of ``U`` (unit-cube distances), nearest first; ready for
    :func:`rapt.subboundary_tree`'s ``graph`` with ``U`` as the states (``X`` is ``U``
    for a :class:`StateSpace`).  ``graph_seconds`` is the time spent growing
    it in this process (rebuilding it on a resume included).
    """

    X: np.ndarray
    Y: np.ndarray
    U: np.ndarray
    batch: np.ndarray
    X_failed: np.ndarray
    failures: list[str]
    method: str
    seed: int
    space: StateSpace
    output_types: tuple[str, ...]
    sampler: Sampler = field(repr=False)
    store: str | None = None
    neighbours: tuple[np.ndarray, np.ndarray] | None = field(default=None, repr=False)
    graph_seconds: float = 0.0

    @property
    def n_evaluated(self) -> int:
        """Rows evaluated, failed ones included (what the budget counts)."""
        return int(self.X.shape[0] + self.X_failed.shape[0])

    def scenarios(self) -> list[dict[str, Any]]:
        """The successful samples as named scenarios in physical units."""
        return self.space.decode(self.U)


def search(
    fn: Callable[[np.ndarray], Any],
    bounds: Any,
    budget: int,
    method: str = "s-ndv",
    batch_size: int = 100,
    seed: int = 0,
    *,
    store: str | Path | None = None,
    executor: Any = None,
    chunk_size: int | None = None,
    output_types: Sequence[str] | None = None,
    n_initial: int | None = None,
    sampler_options: dict[str, Any] | None = None,
    progress: Callable[[int, int], None] | None = None,
    on_batch: Callable[[np.ndarray, np.ndarray], None] | None = None,
    steer: Sequence[int] | None = None,
    neighbour_graph: int | None = None,
) -> Study:
    """Search the space for performance boundaries of ``fn``.

    Parameters
    ----------
    fn:
        Maps an (n, d) float array of states to an (n, m) array of scores.  It may also
        return ``(X_evaluated, Y)`` when it evaluated different states than it was given
        (a projection onto valid states).  Rows of NaN, or an exception for a chunk, are
        recorded as failed and the search goes on.
    bounds:
        ``[(low, high), ...]`` per input (``fn`` gets physical values), or a
        :class:`~rapt.space.StateSpace` (``fn`` gets unit-cube rows; decode with the space).
    budget:
        Total rows to evaluate, failed rows included.  With a ``store`` holding fewer, the
        study continues up to ``budget``.
    method:
        One of ``random``, ``sobol``, ``lhs``, ``gpr``, ``nndv``, ``s-ndv``.
    batch_size, seed:
        Points per batch (``L``); the seed of every random choice.
    store:
        SQLite file.  If it already holds this study, the search resumes; with the same
        seed the result equals an uninterrupted run.
    executor:
        ``None`` (call ``fn`` in process on whole batches), any
        ``concurrent.futures.Executor``, or a ``dask.distributed.Client``.
    chunk_size:
        Rows per task when an executor is used (default: two tasks per worker per batch).
    output_types:
        Per score column ``categorical``, ``binary`` or ``continuous``; inferred from the
        first successful batch when omitted.
    n_initial:
        Space-filling samples before the adaptive metric takes over (default: one batch).
    sampler_options:
        Extra keyword arguments for the sampler (e.g. ``k``, ``g``, ``v``).
    progress:
        Called as ``progress(evaluated, budget)`` after every batch.
    on_batch:
        Called as ``on_batch(U, Y)`` with the unit-cube rows and scores of each completed
        batch's successful evaluations, replayed batches of a resumed study included: how
        a caller follows the modes found so far without reading the store.
    steer:
        Score columns the sampler steers on (default: all).  Every column ``fn`` returns
        is stored and comes back in ``Study.Y``; ``output_types`` then describes the
        steered columns.  Searching on the root scores of a hierarchy while keeping every
        sub-score for the sub-boundary analysis (section 4.3.6) spares a second run of
        each sample.
    neighbour_graph:
        ``k``: grow the study's k-nearest-neighbour graph batch by batch
        (:class:`rapt.neighbours.GrowingGraph`; exact up to 20,000 rows, HNSW beyond),
        keep it in the store, and return it as ``Study.neighbours``, so the sub-boundary
        analysis does not build one after the search.  A resumed study continues the stored
        graph (or rebuilds it from the stored rows) and ends with the same graph as an
        uninterrupted run.  Off by default: in total it costs more CPU than building the
        graph once at the end (about 1.6x for 10^6 rows in 18-D), spread over the batches.
    """
    if not callable(fn):
        raise InputError("fn: expected a callable mapping an (n, d) array to an (n, m) array")
    space = bounds if isinstance(bounds, StateSpace) else StateSpace.from_bounds(bounds)
    physical = not isinstance(bounds, StateSpace)
    steer, output_types = _checked_arguments(
        method, budget, batch_size, seed, chunk_size, n_initial, steer, output_types
    )
    graph = None if neighbour_graph is None else GrowingGraph(space.dim, neighbour_graph)
    options = _sampler_options(method, budget, batch_size, n_initial, sampler_options)
    sampler = make_sampler(method, space.dim, seed=int(seed), output_types=output_types, **options)
    ex, workers = resolve_executor(executor)

    config = {
        "schema_version": SCHEMA_VERSION,
        "method": method,
        "seed": int(seed),
        "dim": space.dim,
        "batch_size": int(batch_size),
        "space": space.to_config(),
        "physical": physical,
        "sampler_options": {k: v for k, v in options.items() if k != "size" and _json_storable(v)},
        "steer": steer,
    }
    db = StudyStore(":memory:" if store is None else store)
    try:
        runner = _Runner(
            fn, space, physical, sampler, db, ex, workers, chunk_size, int(batch_size), on_batch, steer, graph
        )
        runner.open(config, output_types)
        runner.run(int(budget), progress)
        return runner.study(method, int(seed), None if store is None else str(store))
    finally:
        db.close()


def _checked_arguments(
    method: str,
    budget: Any,
    batch_size: Any,
    seed: Any,
    chunk_size: Any,
    n_initial: Any,
    steer: Sequence[int] | None,
    output_types: Sequence[str] | None,
) -> tuple[list[int] | None, tuple[str, ...] | None]:
    """:func:`search`'s arguments checked (InputError naming the argument); returns ``steer`` and
    ``output_types`` normalised (a list of ints and a tuple)."""
    if method not in METHODS:
        raise InputError(f"method: unknown method {method!r}; allowed: {', '.join(METHODS)}")
    for name, value in (("budget", budget), ("batch_size", batch_size)):
        if not isinstance(value, (int, np.integer)) or isinstance(value, bool) or value < 1:
            raise InputError(f"{name}: expected a positive integer, got {value!r}")
    if budget < batch_size:
        raise InputError(f"budget: {budget} is smaller than batch_size {batch_size}; raise budget or lower batch_size")
    if not isinstance(seed, (int, np.integer)) or isinstance(seed, bool) or seed < 0:
        raise InputError(f"seed: expected a non-negative integer, got {seed!r}")
    if chunk_size is not None and (not isinstance(chunk_size, (int, np.integer)) or chunk_size < 1):
        raise InputError(f"chunk_size: expected a positive integer or None, got {chunk_size!r}")
    if n_initial is not None and (not isinstance(n_initial, (int, np.integer)) or n_initial < 0):
        raise InputError(f"n_initial: expected a non-negative integer or None, got {n_initial!r}")
    if steer is not None:
        steer = [int(c) for c in steer] if all(isinstance(c, (int, np.integer)) for c in steer) else None
        if not steer or min(steer) < 0 or len(set(steer)) != len(steer):
            raise InputError("steer: expected distinct non-negative score column indices, e.g. steer=[0, 1]")
    if output_types is not None:
        output_types = tuple(output_types)
        check_output_types(output_types, len(output_types))
        if steer is not None and len(output_types) != len(steer):
            raise InputError(
                f"output_types: expected one type per steered column ({len(steer)}), got {len(output_types)}"
            )
    return steer, output_types


def _sampler_options(
    method: str, budget: int, batch_size: int, n_initial: int | None, sampler_options: dict[str, Any] | None
) -> dict[str, Any]:
    """The sampler's keyword arguments: the caller's, with the space-filling start (adaptive
    methods) or the design size (``lhs``) filled in."""
    options = dict(sampler_options or {})
    if METHODS[method].adaptive:
        options.setdefault("n_initial", batch_size if n_initial is None else int(n_initial))
    elif method == "lhs":
        options.setdefault("size", int(budget))
    return options


def _json_storable(v: Any) -> bool:
    """Whether a sampler option is a plain JSON value, kept in the store's config to recognise the study."""
    return isinstance(v, (int, float, str, bool, type(None), list, tuple, dict))


class _Runner:
    """One study in progress: replay what the store holds, then evaluate the rest."""

    def __init__(
        self,
        fn,
        space: StateSpace,
        physical: bool,
        sampler: Sampler,
        db: StudyStore,
        executor: cf.Executor | None,
        workers: int,
        chunk_size: int | None,
        batch_size: int,
        on_batch: Callable[[np.ndarray, np.ndarray], None] | None = None,
        steer: list[int] | None = None,
        graph: GrowingGraph | None = None,
    ):
        self.fn = fn
        self.space = space
        self.physical = physical
        self.sampler = sampler
        self.db = db
        self.executor = executor
        self.workers = workers
        self.chunk_size = chunk_size
        self.batch_size = batch_size
        self.on_batch = on_batch
        self.steer = steer
        self.graph = graph
        self.graph_batches = 0  # batches whose graph lists the store holds
        self.graph_seconds = 0.0
        self.n_outputs: int | None = None
        # Per evaluated row, in (batch, row) order.
        self.U: list[np.ndarray] = []
        self.Y: list[np.ndarray] = []
        self.batch_of: list[np.ndarray] = []
        self.U_failed: list[np.ndarray] = []
        self.reasons: list[str] = []
        self.asked = 0
        self.batches = 0
        # Rows recorded by this process for the batch in progress (same shape as StudyStore.samples).
        self._fresh: list[tuple] = []
        # (batch, asked points) of a batch found incomplete in the store, set by _replay.
        self._unfinished: tuple[int, np.ndarray] | None = None

    # -- opening and replay ------------------------------------------------------------
    def open(self, config: dict[str, Any], output_types: tuple[str, ...] | None) -> None:
        meta = self.db.get_meta()
        if not meta:
            self.db.set_meta(config)
            if output_types is not None:
                self.db.set_meta({"output_types": list(output_types)})
            return
        for key in (
            "schema_version",
            "method",
            "seed",
            "dim",
            "batch_size",
            "space",
            "physical",
            "sampler_options",
            "steer",
        ):
            if meta.get(key) != config[key]:
                raise StudyMismatchError(
                    f"store: {self.db.path} holds a study with {key}={meta.get(key)!r}, not {config[key]!r}; "
                    f"pass the same {key} to resume it, or use a new store path"
                )
        stored_types = meta.get("output_types")
        if stored_types is not None:
            if output_types is not None and tuple(stored_types) != output_types:
                raise StudyMismatchError(
                    f"output_types: the store was created with {stored_types}; pass the same or omit output_types"
                )
            self.sampler.output_types = tuple(stored_types)
        self._restore_graph(meta.get("neighbour_graph"))
        self._replay()

    def _restore_graph(self, state: dict[str, Any] | None) -> None:
        """Load the stored graph lists; the replay then takes in the rows of the batches they cover.

        A graph stored for another ``k`` is dropped and rebuilt from the rows as they replay.
        """
        if self.graph is None or state is None:
            return
        if state.get("k") != self.graph.k:
            self.db.clear_neighbours()
            return
        started = time.perf_counter()
        idx, dist = self.db.neighbours(self.graph.k)
        if idx.shape[0] != state.get("rows"):
            raise FileFormatError(
                f"store: {self.db.path}'s neighbour graph holds {idx.shape[0]} rows, its meta says {state.get('rows')}; "
                "delete its neighbours table to rebuild it"
            )
        self.graph.restore(idx, dist)
        self.graph_batches = int(state["batches"])
        self.graph_seconds += time.perf_counter() - started

    def _replay(self) -> None:
        batches = self.db.batches()
        rows_by_batch: dict[int, list] = {}
        for rec in self.db.samples():
            rows_by_batch.setdefault(rec[0], []).append(rec)
        for b, asked in batches:
            recs = rows_by_batch.get(b, [])
            self.asked += asked.shape[0]
            self.batches = b + 1
            if len(recs) == asked.shape[0]:
                self._accept(b, recs)
            else:  # only the last asked batch can be incomplete
                self._unfinished = (b, asked)
        self.sampler.fast_forward(self.batches, self.asked)

    def _accept(self, b: int, recs: list) -> None:
        """Add a completed batch's rows (in row order) to the study and tell the sampler."""
        recs = sorted(recs, key=lambda r: r[1])
        ok = [r for r in recs if r[4] == "ok"]
        bad = [r for r in recs if r[4] != "ok"]
        self._grow_graph(b, np.vstack([r[2] for r in ok]) if ok else np.empty((0, self.space.dim)))
        if ok:
            U = np.vstack([r[2] for r in ok])
            Y = np.vstack([r[3] for r in ok])
            if self.n_outputs is None:
                self.n_outputs = Y.shape[1]
            if self.steer is not None and max(self.steer) >= Y.shape[1]:
                raise InputError(
                    f"steer: column {max(self.steer)} does not exist; fn returns {Y.shape[1]} score columns"
                )
            steered = Y if self.steer is None else Y[:, self.steer]
            if self.sampler.output_types is None:
                self.sampler.output_types = infer_output_types(steered)
                self.db.set_meta({"output_types": list(self.sampler.output_types)})
            self.sampler.tell(U, steered)
            self.U.append(U)
            self.Y.append(Y)
            self.batch_of.append(np.full(len(ok), b, dtype=np.int64))
            if self.on_batch is not None:
                self.on_batch(U, Y)
        if bad:
            Uf = np.vstack([r[2] for r in bad])
            self.sampler.tell_failed(Uf)
            self.U_failed.append(Uf)
            self.reasons.extend(r[5] or "failed" for r in bad)

    def _grow_graph(self, b: int, U: np.ndarray) -> None:
        """Link batch ``b``'s successful rows into the graph and store the changed lists.

        Batches the stored graph already covers only hand their rows to the graph (its
        HNSW index is refilled batch by batch, as when they were first added).
        """
        if self.graph is None:
            return
        started = time.perf_counter()
        if b < self.graph_batches:
            self.graph.extend(U)
        else:
            changed = self.graph.add(U)
            changed = np.union1d(changed, np.arange(self.graph.n - U.shape[0], self.graph.n))  # every node once
            idx, dist = self.graph.lists(changed)
            state = {"k": self.graph.k, "batches": b + 1, "rows": self.graph.n}
            self.db.put_neighbours(state, changed, idx, dist)
            self.graph_batches = b + 1
        self.graph_seconds += time.perf_counter() - started

    # -- evaluation --------------------------------------------------------------------
    def run(self, budget: int, progress) -> None:
        """Evaluate batches until ``budget`` rows were asked, or the sampler finished early.

        A sampler may return fewer points than asked, and finishes early by returning none
        (:attr:`Sampler.done`, see :class:`~rapt.samplers.base.Sampler`): the budget counts
        the points it did return, and an empty ask ends the study without recording a batch.
        """
        # Finish a batch that was asked but not fully evaluated before the last stop.
        if self._unfinished is not None:
            self._evaluate_batch(*self._unfinished)
            self._unfinished = None
            self._report(progress, budget)
        while self.asked < budget and not self.sampler.done:
            n = min(self.batch_size, budget - self.asked)
            asked = self.sampler.ask(n)
            if not len(asked):  # finished early: sampler.done is now set
                break
            b = self.batches
            self.db.add_batch(b, asked)
            self.batches += 1
            self.asked += len(asked)
            self._evaluate_batch(b, asked)
            self._report(progress, budget)

    def _report(self, progress, budget: int) -> None:
        if not any(len(u) for u in self.U) and len(self.reasons) and self.batches >= _ALL_FAILED_BATCHES:
            raise RunError(
                f"fn: every row of the first {self.batches} batches failed (last reason: {self.reasons[-1]}); "
                "fix the system under test before searching"
            )
        if progress is not None:
            progress(self.db.count(), budget)

    def _evaluate_batch(self, b: int, asked: np.ndarray) -> None:
        done = self.db.done_rows(b)
        todo = np.array([i for i in range(asked.shape[0]) if i not in done], dtype=np.int64)
        if todo.size:
            if self.executor is None:
                self._record(b, todo, asked[todo], *self._call(asked[todo]))
            else:
                size = self.chunk_size or max(1, math.ceil(todo.size / (2 * self.workers)))
                futures = {}
                for start in range(0, todo.size, size):
                    rows = todo[start : start + size]
                    fut = self.executor.submit(_call_fn, self.fn, self._to_fn(asked[rows]))
                    futures[fut] = rows
                for fut in cf.as_completed(futures):
                    rows = futures[fut]
                    self._record(b, rows, asked[rows], *self._unpack(fut, len(rows)))
        if done:  # part of this batch was evaluated by an earlier run: read it all back
            self._accept(b, self.db.samples(b))
        else:
            self._accept(b, self._fresh)
        self._fresh = []

    def _to_fn(self, U: np.ndarray) -> np.ndarray:
        return self.space.from_unit_array(U) if self.physical else U

    def _call(self, U: np.ndarray):
        try:
            out = _call_fn(self.fn, self._to_fn(U))
        except Exception as exc:  # the system under test failed for this chunk
            return None, None, _reason(exc)
        return (*out, None)

    def _unpack(self, fut: cf.Future, n: int):
        try:
            return (*fut.result(), None)
        except Exception as exc:
            return None, None, _reason(exc)

    def _record(self, b: int, rows: np.ndarray, U_asked: np.ndarray, X_eval, Y, error: str | None) -> None:
        n = rows.size
        if error is not None:
            self.db.add_samples(b, rows, U_asked, None, ["failed"] * n, [error] * n)
            self._fresh.extend((b, int(r), U_asked[k], None, "failed", error) for k, r in enumerate(rows))
            return
        Y = np.asarray(Y, dtype=float)
        if Y.ndim == 1 and Y.shape[0] == n:
            Y = Y[:, None]
        expected_m = (
            self.n_outputs
            if self.n_outputs is not None
            else (len(self.sampler.output_types) if self.sampler.output_types and self.steer is None else None)
        )
        if Y.ndim != 2 or Y.shape[0] != n or (expected_m is not None and Y.shape[1] != expected_m):
            shape = f"({n}, {expected_m})" if expected_m else f"({n}, m)"
            raise InputError(f"fn: returned scores of shape {Y.shape} for {n} states; expected {shape}")
        if self.n_outputs is None:
            self.n_outputs = Y.shape[1]
        if X_eval is None:
            U = U_asked
        else:
            X_eval = np.asarray(X_eval, dtype=float)
            if X_eval.shape != (n, self.space.dim):
                raise InputError(
                    f"fn: returned evaluated states of shape {X_eval.shape}; expected ({n}, {self.space.dim})"
                )
            U = self.space.to_unit_array(X_eval) if self.physical else X_eval
        finite = np.all(np.isfinite(Y), axis=1) & np.all(np.isfinite(U), axis=1)
        status = np.where(finite, "ok", "failed")
        reasons = [None if f else "score row contains NaN or inf" for f in finite]
        Y_clean = np.where(finite[:, None], Y, 0.0)
        self.db.add_samples(b, rows, U, Y_clean, status, reasons)
        self._fresh.extend(
            (b, int(r), U[k], Y_clean[k] if finite[k] else None, str(status[k]), reasons[k]) for k, r in enumerate(rows)
        )

    def study(self, method: str, seed: int, store: str | None) -> Study:
        m = self.n_outputs or 0
        U = np.vstack(self.U) if self.U else np.empty((0, self.space.dim))
        Y = np.vstack(self.Y) if self.Y else np.empty((0, m))
        Uf = np.vstack(self.U_failed) if self.U_failed else np.empty((0, self.space.dim))
        to_x = self.space.from_unit_array if self.physical else (lambda a: a)
        return Study(
            X=to_x(U) if len(U) else U.copy(),
            Y=Y,
            U=U,
            batch=np.concatenate(self.batch_of) if self.batch_of else np.empty(0, dtype=np.int64),
            X_failed=to_x(Uf) if len(Uf) else Uf.copy(),
            failures=list(self.reasons),
            method=method,
            seed=seed,
            space=self.space,
            output_types=tuple(self.sampler.output_types or ()),
            sampler=self.sampler,
            store=store,
            neighbours=None if self.graph is None else self.graph.graph(),
            graph_seconds=self.graph_seconds,
        )


def _call_fn(fn, X: np.ndarray):
    """Call ``fn`` and split an optional ``(X_evaluated, Y)`` answer (runs on workers too)."""
    out = fn(X)
    if isinstance(out, tuple) and len(out) == 2:
        return np.asarray(out[0], dtype=float), np.asarray(out[1], dtype=float)
    return None, np.asarray(out, dtype=float)


def _reason(exc: BaseException) -> str:
    text = " ".join(str(exc).split())
    return f"{type(exc).__name__}: {text}"[:500]
