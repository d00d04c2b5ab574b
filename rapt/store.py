"""SQLite study store: every evaluated row is on disk as soon as its chunk completes.

One file per study (stdlib ``sqlite3``, WAL journal), so a study killed halfway resumes
where it stopped: asked batches are recorded before they are evaluated, and a resumed run
evaluates only the rows of a batch that are not in the store yet.

Tables
------
``meta(key, value)``                     JSON values: configuration the study was created with.
``batches(batch, n, asked)``             the unit-cube points asked for each batch (float64 bytes).
``samples(batch, row, x, y, status, reason)``
                                         one row per evaluated point; ``status`` is ``ok`` or
                                         ``failed`` (``reason`` says why; ``y`` is NULL).
``neighbours(node, idx, dist)``          the study's k-nearest-neighbour graph (:mod:`rapt.neighbours`):
                                         node n's current list (int32 ids, float32 distances),
                                         for the n-th successful row; meta ``neighbour_graph``
                                         says for which k and up to which batch.

Schema 2 added the ``neighbours`` table.  A schema-1 store opens as schema 2 (the table
is created empty); a resumed search then rebuilds the graph from the stored rows.
"""

from __future__ import annotations

import json
import sqlite3
from collections.abc import Iterable
from pathlib import Path
from types import TracebackType
from typing import Any

import numpy as np

from rapt.errors import FileFormatError, InputError, RunError

__all__ = ["StudyStore", "SCHEMA_VERSION"]

SCHEMA_VERSION = 2

_SCHEMA = """
CREATE TABLE IF NOT EXISTS meta (key TEXT PRIMARY KEY, value TEXT NOT NULL);
CREATE TABLE IF NOT EXISTS batches (
    batch INTEGER PRIMARY KEY,
    n INTEGER NOT NULL,
    asked BLOB NOT NULL
);
CREATE TABLE IF NOT EXISTS samples (
    batch INTEGER NOT NULL,
    row INTEGER NOT NULL,
    x BLOB NOT NULL,
    y BLOB,
    status TEXT NOT NULL CHECK (status IN ('ok', 'failed')),
    reason TEXT,
    PRIMARY KEY (batch, row)
);
CREATE TABLE IF NOT EXISTS neighbours (
    node INTEGER PRIMARY KEY,
    idx BLOB NOT NULL,
    dist BLOB NOT NULL
);
"""


class StudyStore:
    """A study's batches and samples in one SQLite file."""

    def __init__(self, path: str | Path):
        """Open or create the store at ``path`` (``":memory:"`` keeps it in memory)."""
        self.path = Path(path)
        self._con: sqlite3.Connection | None = None  # None once closed
        if str(path) == ":memory:":
            self._con = sqlite3.connect(":memory:", isolation_level=None)
            self._con.executescript(_SCHEMA)
            return
        if self.path.exists() and self.path.is_dir():
            raise InputError(f"store: {self.path} is a directory; give a file path such as study.db")
        if not self.path.parent.exists():
            raise InputError(f"store: folder {self.path.parent} does not exist; create it or choose another path")
        try:
            self._con = sqlite3.connect(self.path, isolation_level=None)
            self._con.execute("PRAGMA journal_mode=WAL")
            self._con.execute("PRAGMA synchronous=NORMAL")
            self._con.executescript(_SCHEMA)
        except sqlite3.DatabaseError as exc:
            raise FileFormatError(
                f"store: {self.path} is not a RAPT study database ({exc}); choose another path"
            ) from None
        if self.get_meta().get("schema_version") == 1:  # only the neighbours table is new
            self.set_meta({"schema_version": SCHEMA_VERSION})

    # -- lifecycle ----------------------------------------------------------------------
    def close(self) -> None:
        if self._con is not None:
            self._con.close()
            self._con = None

    @property
    def _db(self) -> sqlite3.Connection:
        """The open connection; a closed store cannot be read or written."""
        if self._con is None:
            raise RunError(f"store: {self.path} is closed; open a new StudyStore to use it")
        return self._con

    def __enter__(self) -> StudyStore:
        return self

    def __exit__(self, *exc: Any) -> None:
        self.close()

    # -- metadata -----------------------------------------------------------------------
    def get_meta(self) -> dict[str, Any]:
        rows = self._db.execute("SELECT key, value FROM meta").fetchall()
        return {k: json.loads(v) for k, v in rows}

    def set_meta(self, values: dict[str, Any]) -> None:
        with self._tx():
            self._db.executemany(
                "INSERT OR REPLACE INTO meta(key, value) VALUES (?, ?)",
                [(k, json.dumps(v, sort_keys=True)) for k, v in values.items()],
            )

    # -- batches and samples --------------------------------------------------------------
    def add_batch(self, batch: int, asked: np.ndarray) -> None:
        asked = np.ascontiguousarray(asked, dtype="<f8")
        with self._tx():
            self._db.execute(
                "INSERT INTO batches(batch, n, asked) VALUES (?, ?, ?)",
                (int(batch), int(asked.shape[0]), asked.tobytes()),
            )

    def batches(self) -> list[tuple[int, np.ndarray]]:
        """All asked batches in order as (batch index, asked points)."""
        dim = self.get_meta().get("dim")
        out = []
        for b, n, blob in self._db.execute("SELECT batch, n, asked FROM batches ORDER BY batch"):
            if dim is None:
                raise FileFormatError(
                    f"store: {self.path} holds batches but no dim in its meta table; "
                    "it was not written by rapt.search, choose another path"
                )
            out.append((int(b), np.frombuffer(blob, dtype="<f8").reshape(int(n), int(dim)).copy()))
        return out

    def add_samples(
        self,
        batch: int,
        rows: Iterable[int],
        X: np.ndarray,
        Y: np.ndarray | None,
        status: Iterable[str],
        reasons: Iterable[str | None],
    ) -> None:
        """Write evaluated rows of one batch in a single transaction."""
        X = np.ascontiguousarray(X, dtype="<f8")
        records = []
        for i, (row, st, why) in enumerate(zip(rows, status, reasons)):
            y = None if (Y is None or st != "ok") else np.ascontiguousarray(Y[i], dtype="<f8").tobytes()
            records.append((int(batch), int(row), X[i].tobytes(), y, st, why))
        with self._tx():
            self._db.executemany(
                "INSERT INTO samples(batch, row, x, y, status, reason) VALUES (?, ?, ?, ?, ?, ?)", records
            )

    def done_rows(self, batch: int) -> set[int]:
        return {int(r) for (r,) in self._db.execute("SELECT row FROM samples WHERE batch = ?", (int(batch),))}

    def samples(
        self, batch: int | None = None
    ) -> list[tuple[int, int, np.ndarray, np.ndarray | None, str, str | None]]:
        """Rows as (batch, row, x, y, status, reason), in (batch, row) order."""
        sql = "SELECT batch, row, x, y, status, reason FROM samples"
        args: tuple = ()
        if batch is not None:
            sql += " WHERE batch = ?"
            args = (int(batch),)
        out = []
        for b, r, x, y, st, why in self._db.execute(sql + " ORDER BY batch, row", args):
            out.append(
                (
                    int(b),
                    int(r),
                    np.frombuffer(x, dtype="<f8").copy(),
                    None if y is None else np.frombuffer(y, dtype="<f8").copy(),
                    st,
                    why,
                )
            )
        return out

    # -- neighbour graph ------------------------------------------------------------------
    def put_neighbours(self, state: dict[str, Any], nodes: np.ndarray, idx: np.ndarray, dist: np.ndarray) -> None:
        """Write the lists of ``nodes`` (rows of ``idx``/``dist``) and the graph's ``state`` in one transaction.

        ``state`` (meta ``neighbour_graph``) names the batches the stored lists cover, so a
        stop between a batch's samples and its graph leaves a store that says so.
        """
        idx = np.ascontiguousarray(idx, dtype="<i4")
        dist = np.ascontiguousarray(dist, dtype="<f4")
        with self._tx():
            self._db.executemany(
                "INSERT OR REPLACE INTO neighbours(node, idx, dist) VALUES (?, ?, ?)",
                [(int(n), i.tobytes(), d.tobytes()) for n, i, d in zip(nodes, idx, dist)],
            )
            self._db.execute(
                "INSERT OR REPLACE INTO meta(key, value) VALUES ('neighbour_graph', ?)", (json.dumps(state),)
            )

    def neighbours(self, k: int) -> tuple[np.ndarray, np.ndarray]:
        """The stored graph: (idx, dist), (N, k) in node order; FileFormatError when nodes are missing."""
        idx = bytearray()
        dist = bytearray()
        n = 0
        for node, i, d in self._db.execute("SELECT node, idx, dist FROM neighbours ORDER BY node"):
            if node != n or len(i) != 4 * k or len(d) != 4 * k:
                raise FileFormatError(
                    f"store: {self.path} holds a damaged neighbour graph (node {node}); "
                    "delete its neighbours table to rebuild it"
                )
            idx += i
            dist += d
            n += 1
        return (
            np.frombuffer(bytes(idx), dtype="<i4").reshape(n, k).astype(np.int32),
            np.frombuffer(bytes(dist), dtype="<f4").reshape(n, k).astype(np.float32),
        )

    def clear_neighbours(self) -> None:
        """Forget the stored graph (another k was asked for): it is rebuilt from the rows."""
        with self._tx():
            self._db.execute("DELETE FROM neighbours")
            self._db.execute("DELETE FROM meta WHERE key = 'neighbour_graph'")

    def count(self) -> int:
        return int(self._db.execute("SELECT COUNT(*) FROM samples").fetchone()[0])

    def _tx(self) -> _Transaction:
        return _Transaction(self._db)


class _Transaction:
    """``BEGIN IMMEDIATE`` ... ``COMMIT`` (rollback on error) for an autocommit connection."""

    def __init__(self, con: sqlite3.Connection):
        self.con = con

    def __enter__(self) -> None:
        self.con.execute("BEGIN IMMEDIATE")

    def __exit__(
        self, exc_type: type[BaseException] | None, exc: BaseException | None, tb: TracebackType | None
    ) -> None:
        self.con.execute("ROLLBACK" if exc_type else "COMMIT")
