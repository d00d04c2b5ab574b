"""Score trees: how a mission's scores nest (section 4.3.1, Figure 4.11).

Mission success and safety success sit at the root; below them waypoints, mission areas,
transmission, each obstacle…; the leaves are continuous metrics such as closest
approach.  A node holds the score-vector columns it owns and its children.  Trees are
declared in data (nested mappings, TOML or JSON) so each mission ships its own.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from typing import Any

from rapt.errors import InputError

__all__ = ["ScoreTree"]


@dataclass(frozen=True)
class ScoreTree:
    """A node: score columns ``indices`` and child nodes; ``name`` is for people."""

    indices: tuple[int, ...]
    children: tuple[ScoreTree, ...] = ()
    name: str = ""

    def __post_init__(self) -> None:
        object.__setattr__(self, "indices", tuple(int(i) for i in self.indices))
        object.__setattr__(self, "children", tuple(self.children))
        if not self.indices:
            raise InputError(
                f"tree: node {self.name or '(unnamed)'} has no score indices; every node needs at least one column"
            )

    @classmethod
    def from_mapping(cls, spec: ScoreTree | Mapping[str, Any], _path: str = "tree") -> ScoreTree:
        """Build from ``{"indices": [...], "children": [...], "name": "..."}`` (children likewise)."""
        if isinstance(spec, ScoreTree):
            return spec
        if not isinstance(spec, Mapping):
            raise InputError(
                f"{_path}: expected a mapping with 'indices' and optional 'children', got {type(spec).__name__}"
            )
        unknown = set(spec) - {"indices", "children", "name"}
        if unknown:
            raise InputError(f"{_path}: unknown field(s) {sorted(unknown)}; allowed: indices, children, name")
        if "indices" not in spec:
            raise InputError(f"{_path}: missing 'indices' (the score columns this node owns)")
        indices = spec["indices"]
        if isinstance(indices, (str, bytes)) or not isinstance(indices, Sequence):
            raise InputError(f"{_path}.indices: expected a list of column numbers, got {indices!r}")
        for k in indices:
            if isinstance(k, bool) or not isinstance(k, int) or k < 0:
                raise InputError(f"{_path}.indices: {k!r} is not a column number (a non-negative integer)")
        children = spec.get("children", [])
        if not isinstance(children, Sequence) or isinstance(children, (str, bytes)):
            raise InputError(f"{_path}.children: expected a list of nodes")
        kids = tuple(cls.from_mapping(c, f"{_path}.children[{n}]") for n, c in enumerate(children))
        return cls(tuple(indices), kids, str(spec.get("name", "")))

    def to_mapping(self) -> dict[str, Any]:
        out: dict[str, Any] = {"indices": list(self.indices)}
        if self.name:
            out["name"] = self.name
        if self.children:
            out["children"] = [c.to_mapping() for c in self.children]
        return out

    def levels(self) -> list[tuple[int, ...]]:
        """Score columns at each depth: the root's, then the union of its children's, and so on."""
        out, frontier = [], [self]
        while frontier:
            cols: list[int] = []
            for node in frontier:
                cols.extend(i for i in node.indices if i not in cols)
            out.append(tuple(cols))
            frontier = [c for node in frontier for c in node.children]
        return out

    def nodes(self) -> list[ScoreTree]:
        out, stack = [], [self]
        while stack:
            node = stack.pop(0)
            out.append(node)
            stack.extend(node.children)
        return out

    def leaves(self) -> list[ScoreTree]:
        return [n for n in self.nodes() if not n.children]

    @property
    def depth(self) -> int:
        return len(self.levels())

    def validate(self, n_columns: int) -> None:
        """Raise if a node names a score column that does not exist or one column appears twice."""
        seen: dict[int, str] = {}
        for node in self.nodes():
            for i in node.indices:
                if i >= n_columns:
                    raise InputError(
                        f"tree: node {node.name or node.indices} names score column {i}, but Y has {n_columns} "
                        f"columns (0..{n_columns - 1}); fix the tree or the scores"
                    )
                if i in seen:
                    raise InputError(
                        f"tree: score column {i} appears in two nodes ({seen[i]} and {node.name or node.indices})"
                    )
                seen[i] = node.name or str(node.indices)
