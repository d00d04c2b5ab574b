"""The [score_tree] of a mission file: a rapt score tree over the mission's metric names.

Nodes name metrics (:func:`sim.uuv.metrics.metric_names`); ``for_each`` replicates a node
per element of a kind, substituting ``{name}``.  The resolved mapping lists column indices,
every score column in exactly one node (format: :mod:`sim.uuv.missionfile`).
"""

from __future__ import annotations

import difflib
import re
from collections.abc import Mapping
from typing import Any

from rapt.scoretree import ScoreTree
from sim.uuv.metrics import ELEMENT_KINDS, element_names, metric_names
from sim.uuv.mission import Mission
from sim.uuv.missionfields import FieldChecker, names

__all__ = ["ScoreTreeReader"]


class ScoreTreeReader(FieldChecker):
    """Reads the [score_tree] of the file ``label`` for ``mission``."""

    def __init__(self, label: str, mission: Mission):
        super().__init__(label)
        self.mission = mission

    def read(self, spec: Any) -> dict:
        """The resolved tree (``{"name", "indices", "children"}``), every metric column in one node."""
        self.metric_list = metric_names(self.mission)
        self.metric_index = {n: i for i, n in enumerate(self.metric_list)}
        self.check_node(spec, "score_tree", root=True)
        self.used: dict[int, str] = {}
        (tree,) = self.resolve(spec, "score_tree", None)
        for i, metric in enumerate(self.metric_list):
            if i not in self.used:
                self.fail(
                    "score_tree",
                    f"metric {metric!r} (column {i}) is not in the tree; add it to the scores of "
                    "one node (every score column must appear exactly once)",
                )
        try:
            ScoreTree.from_mapping(tree).validate(len(self.metric_list))
        except ValueError as exc:  # pragma: no cover - checked above
            self.fail("score_tree", str(exc))
        return tree

    def check_node(self, spec: Any, where: str, root: bool = False) -> None:
        """Syntax of a node and its descendants (before replication, so empty for_each nodes are checked too)."""
        bare = re.sub(r"\[\d+\]", "", where)
        self.table(spec, where, f"[{bare}]" if root else f"[[{bare}]]")
        self.keys(spec, where, ("scores",), ("name", "children", "for_each"))
        if "name" in spec and not isinstance(spec["name"], str):
            self.fail(f"{where}.name", f'expected a string, got {spec["name"]!r}; write name = "..."')
        scores = spec["scores"]
        if not isinstance(scores, list) or not scores or not all(isinstance(s, str) for s in scores):
            self.fail(
                f"{where}.scores",
                f'expected a non-empty list of metric names, got {scores!r}; write e.g. scores = ["mission_success"]',
            )
        if "for_each" in spec:
            fe = spec["for_each"]
            if root:
                self.fail(f"{where}.for_each", "the root node cannot be replicated; move for_each to a child node")
            if fe not in ELEMENT_KINDS:
                self.fail(f"{where}.for_each", f"unknown element kind {fe!r}; allowed: {names(ELEMENT_KINDS)}")
        children = spec.get("children", [])
        if not isinstance(children, list):
            self.fail(
                f"{where}.children",
                f"expected an array of tables, got {type(children).__name__}; write each child as [[{bare}.children]]",
            )
        for j, child in enumerate(children):
            self.check_node(child, f"{where}.children[{j}]")

    def resolve(self, spec: Mapping, where: str, current: tuple[str, str] | None) -> list[dict]:
        if "for_each" in spec:
            kind = spec["for_each"]
            return [self.resolve_body(spec, where, (kind, e)) for e in element_names(self.mission, kind)]
        return [self.resolve_body(spec, where, current)]

    def resolve_body(self, spec: Mapping, where: str, current: tuple[str, str] | None) -> dict:
        elem = f" ({current[0]} {current[1]!r})" if current else ""

        def sub(text: str, field: str) -> str:
            if "{name}" in text:
                if current is None:
                    self.fail(
                        field,
                        f'{text!r} uses {{name}} outside a for_each node; add for_each = "..." to this '
                        "node or an ancestor, or write the element name",
                    )
                text = text.replace("{name}", current[1])
            return text

        indices = []
        for j, pattern in enumerate(spec["scores"]):
            field = f"{where}.scores[{j}]"
            metric = sub(pattern, field)
            if metric not in self.metric_index:
                hint = difflib.get_close_matches(metric, self.metric_list, n=1)
                known = f"did you mean {hint[0]!r}?" if hint else f"known metrics: {names(self.metric_list)}"
                self.fail(
                    field,
                    f"unknown metric {metric!r}{elem} ({known}); use a name from "
                    "sim.uuv.metrics.metric_names for this mission",
                )
            i = self.metric_index[metric]
            if i in self.used:
                self.fail(
                    field,
                    f"metric {metric!r}{elem} appears twice (also at {self.used[i]}); "
                    "list each metric in exactly one node",
                )
            self.used[i] = field + elem
            indices.append(i)
        name = sub(spec["name"], f"{where}.name") if "name" in spec else self.metric_list[indices[0]]
        children = []
        for j, child in enumerate(spec.get("children", [])):
            children.extend(self.resolve(child, f"{where}.children[{j}]", current))
        return {"name": name, "indices": indices, "children": children}
