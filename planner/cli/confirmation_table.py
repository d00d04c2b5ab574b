"""The day's confirmation table, as ``rapt-plan compare`` and ``rapt-plan next`` print it."""

from __future__ import annotations

from rich.table import Table

from planner.review.confirmations import side_summary

__all__ = ["confirmation_rich_table"]


def confirmation_rich_table(pairs: list[dict], p_confirm: dict[int, float] | None = None) -> Table:
    """Per pair: its elements, each side's record and status, the pair's status (and P(confirmed) when given)."""
    table = Table(title="Boundaries confirmed by the day's runs (a side shows at P(q > 1/2) >= 0.75)")
    cols = ["pair", "elements", "side a", "side b", "status"] + (["P(confirmed)"] if p_confirm is not None else [])
    for col in cols:
        table.add_column(col, justify="right" if col in ("pair", "P(confirmed)") else "left")
    for pair in pairs:
        name = f"{pair['id']} (for {pair['replaces']})" if "replaces" in pair else str(pair["id"])
        row = [name, ", ".join(pair["elements"]), side_summary(pair["sides"][0]), side_summary(pair["sides"][1])]
        row.append(pair["status"])
        if p_confirm is not None:
            row.append(f"{p_confirm.get(pair['id'], 0.0):.2f}")
        table.add_row(*row)
    return table
