"""A plan that agrees with itself: what ``plan.json`` says of a pair is what its written scenarios predict.

A crew reads a pair's modes ("TF/SS") and flies its scenarios; when the scenarios' own
predictions say otherwise, the plan contradicts itself and the day's comparison judges a
boundary that no scenario was written to show. :func:`plan_contradictions` lists every
such disagreement; the test suite runs it over every plan the suite generates.
"""

from __future__ import annotations

import math

__all__ = ["plan_contradictions"]


def plan_contradictions(plan: dict) -> list[str]:
    """One line per contradiction in a ``plan.json`` document (an empty list: it agrees with itself).

    - a pair's ``modes`` are the predicted modes of its two scenarios;
    - its ``elements`` that the scenarios' predicted scores hold differ between them;
    - a named variant exists, is a variant of that side and predicts the side's mode;
    - ``p_straddle`` is the product of the flown sides' P (the variant's where one is flown).
    """
    out: list[str] = []
    scenarios = {s["id"]: s for s in plan.get("scenarios", [])}
    variants = {v["id"]: v for v in plan.get("variants", [])}
    for pair in plan.get("pairs", []):
        name = f"pair {pair.get('id')}"
        sides = [scenarios.get(sid) for sid in pair.get("scenarios", [])]
        if len(sides) != 2 or None in sides:
            out.append(f"{name}: its scenarios {pair.get('scenarios')} are not both in the plan")
            continue
        predicted = [s["predicted"]["mode"] for s in sides]  # type: ignore[index]
        if list(pair.get("modes", [])) != predicted:
            out.append(
                f"{name}: written as {'/'.join(pair.get('modes', []))}, its scenarios predict {'/'.join(predicted)}"
            )
        scores = [s["predicted"].get("scores", {}) for s in sides]  # type: ignore[index]
        for element in pair.get("elements", []):
            if element in scores[0] and element in scores[1] and scores[0][element] == scores[1][element]:
                out.append(f"{name}: its element {element} is {scores[0][element]:g} on both written scenarios")
        out.extend(_variant_contradictions(name, pair, sides, variants))
    return out


def _variant_contradictions(name: str, pair: dict, sides: list, variants: dict) -> list[str]:
    out = []
    flown_p = []
    for s, vid in enumerate(pair.get("variants") or [None, None]):
        side = sides[s]
        if vid is None:
            flown_p.append((pair.get("p_predicted") or [None, None])[s])
            continue
        v = variants.get(vid)
        if v is None:
            out.append(f"{name}: its variant {vid} is not in the plan")
            flown_p.append(None)
            continue
        if v.get("variant_of") != side["id"]:
            out.append(f"{name}: {vid} is a variant of {v.get('variant_of')}, not of {side['id']}")
        if v["predicted"]["mode"] != side["predicted"]["mode"]:
            out.append(f"{name}: {vid} predicts {v['predicted']['mode']}, its side {side['predicted']['mode']}")
        flown_p.append(v.get("p_predicted"))
    p = pair.get("p_straddle")
    if p is not None and None not in flown_p and not math.isclose(p, flown_p[0] * flown_p[1], abs_tol=1e-9):
        out.append(f"{name}: p_straddle {p:.4f} is not the flown sides' {flown_p[0]:.4f} x {flown_p[1]:.4f}")
    return out
