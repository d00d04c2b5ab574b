"""From a mission file to a field plan: search, analyse, choose pairs, dither (section 4.4).

The stages of ``rapt-plan generate``, each a function a test can run on a small budget:

1. :func:`search_mission` — a space-filling start, then S-NDV on the root scores, every
   batch written to the study store (a killed run resumes where it stopped); with
   ``--noisy-search`` on the stochastic simulator, steered by continuous metrics too.
2. :func:`planner.plan.analysis.analyse` — every valid run re-scored in full (the simulator is deterministic),
   the sub-boundary tree over the mission's score tree, sensitivity of each root score.
3. :func:`planner.plan.analysis.select_pairs` — K boundary pairs on different sub-boundaries, shortest first,
   kept clear of invalid scenarios and of isolated samples (noise rather than behaviour);
   with ``--refine``, :func:`planner.plan.refinement.refine_pairs` focuses a search on each
   candidate's own sub-scores and keeps the first K it makes sharp.
4. :func:`planner.plan.dithering.dither_many` — Gaussian dithers of the expected execution
   noise (:class:`~planner.plan.dithering.DitherNoise`) around every chosen scenario,
   re-simulated with the stochastic effects on: how likely each shows its predicted
   outcome, the nearest boundary in its neighbourhood, and sub-boundaries there that the
   pair does not test (orthogonal: another kind of element; parallel: another element of
   the same kind).
5. :func:`planner.plan.dithering.robust_variants` — fragile scenarios moved away from their
   boundary ("M") until they hold; each pair gets a verdict: sharp, robust or fragile.

:func:`generate` runs them all and writes ``plan.json`` (schema :data:`~planner.common.plans.PLAN_SCHEMA`,
documented in ``planner/plan.schema.json``) and, per scenario, a QGroundControl
``.plan``, a ``QGC WPL 110`` file and its predicted track as GeoJSON
(:mod:`planner.plan.plan_scenarios`), and ``report.html`` (:mod:`planner.plan.report`).
On the surrogate workflow the expert confirms the pairs first
(:func:`planner.plan.analysis.confirm_with_expert`).
"""

from __future__ import annotations

import json
import time
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

import rapt
import sim.uuv
from planner.common.atomic import write_text_atomic
from planner.common.plans import PLAN_SCHEMA, coordinate_sensitivity, embedded_mission
from planner.plan.analysis import Analysis, analyse, confirm_with_expert, pair_points, select_pairs
from planner.plan.confirmation import Confirmation
from planner.plan.dithering import DEFAULT_NOISE, DitherNoise
from planner.plan.mission_search import ROOT_OUTPUT_TYPES
from planner.plan.noisy_search import NoisyMissionScores, noisy_columns, search_record
from planner.plan.pair_choice import MAX_FLOWN_DISTANCE, Candidate, Dithering, evaluate_candidates, rank_candidates
from planner.plan.pair_shifts import with_shifted_pairs
from planner.plan.plan_scenarios import remove_unlisted, scenario_entries, variant_entries
from planner.plan.planned_for import planned_for
from planner.plan.refinement import MIN_REFINE_RUNS, refine_pairs
from planner.plan.report import write_report
from planner.plan.runtime import numerical_runtime
from planner.plan.search_status import SearchStatus
from planner.plan.unreached import no_boundary, unreached
from rapt.errors import InputError, StudyMismatchError
from sim.uuv.mission import Mission
from sim.uuv.scoring import MODE_NAMES

__all__ = ["GenerateConfig", "search_mission", "generate", "auto_batch_size", "make_executor"]


def auto_batch_size(budget: int) -> int:
    """About 40 batches of 250 to 5,000 runs.

    Small batches steer the search more often; large ones keep the vectorised simulator
    at full speed (its runs per second grow with the batch: ``benchmarks/sim_throughput.py``
    measures them by batch size on the machine at hand).
    """
    return int(np.clip(budget // 40, 250, 5000))


@dataclass
class GenerateConfig:
    budget: int = 3000
    pairs: int = 5
    global_fraction: float = 0.2
    seed: int = 0
    batch_size: int | None = None  # None: auto_batch_size(budget)
    dithers: int = 2000
    # expected execution noise (planner.plan.dithering.DitherNoise); None: the mission file's [execution_noise],
    # the noise a morning's logs measured (rapt-plan calibrate --bias writes it), else DEFAULT_NOISE
    dither_sigma: str | float | None = None
    executor: Any = None
    store: Path | None = None
    refine: int = 0  # runs per candidate pair of the focused second search (0: off)
    refine_min_distance: float = 0.02  # refined pairs stay at least this far apart (unit cube)
    refine_max_distance: float = 0.05  # a refined pair further apart than this is not shipped
    # P(predicted outcome) under which a side gets a robust variant: two sides at 0.9 straddle at 0.81, above the
    # 0.8 a range day wants of each pair (pair_choice ranks the pairs by that product)
    fragile_below: float = 0.9
    surrogate: Any = None  # a sim.uuv.imitation Surrogate: search and dither with it, confirm pairs with the expert
    surrogate_file: str = ""
    confirm_runs: int = 100  # expert runs that look for the expert's boundary near the candidate pairs
    noisy_search: bool = False  # search the stochastic simulator, steered by continuous metrics too (noisy_search)

    def __post_init__(self) -> None:
        if self.batch_size is None and isinstance(self.budget, int):
            self.batch_size = auto_batch_size(self.budget)

    @property
    def pairs_wanted(self) -> int:
        """Pairs the selection must deliver: the plan's, or on the surrogate workflow the candidates to confirm."""
        return self.pairs if self.surrogate is None else self.confirm_runs // 2

    @property
    def refine_candidates(self) -> int:
        """Candidate pairs the refinement may try: twice the pairs wanted, so each can be replaced once."""
        return 2 * self.pairs_wanted if self.refine else 0

    @property
    def search_budget(self) -> int:
        """The runs left for the search once the refinement's are set aside (all count in ``budget``)."""
        return self.budget - self.refine * self.refine_candidates

    def noise(self, mission: Mission | None = None) -> DitherNoise:
        return DitherNoise.parse(self.noise_spec(mission))

    def noise_spec(self, mission: Mission | None = None) -> str | float:
        """``dither_sigma``, or without one the day's noise that ``mission`` carries, else :data:`DEFAULT_NOISE`."""
        if self.dither_sigma is not None:
            return self.dither_sigma
        if mission is not None and mission.execution_noise is not None:
            return mission.execution_noise.spec()
        return DEFAULT_NOISE

    def check(self) -> None:
        if self.noisy_search and (self.surrogate is not None or self.surrogate_file or self.refine):
            raise InputError(
                "--noisy-search: searches the stochastic expert itself; it cannot be combined with "
                + ("--surrogate" if self.surrogate is not None or self.surrogate_file else "--refine")
                + " (which re-searches a deterministic model)"
            )
        if not isinstance(self.batch_size, int) or self.batch_size < 1:
            raise InputError(f"--batch-size: expected a positive number of runs, got {self.batch_size}")
        if not isinstance(self.budget, int) or self.budget < 2 * self.batch_size:
            raise InputError(f"--budget: expected at least {2 * self.batch_size} runs, got {self.budget}")
        if not (0 < self.global_fraction < 1):
            raise InputError(f"--global-fraction: expected a share in (0, 1), got {self.global_fraction}")
        if not isinstance(self.pairs, int) or self.pairs < 1:
            raise InputError(f"--pairs: expected a positive number of pairs, got {self.pairs}")
        if not isinstance(self.refine, int) or self.refine < 0 or 0 < self.refine < MIN_REFINE_RUNS:
            raise InputError(f"--refine-runs: expected at least {MIN_REFINE_RUNS} runs per pair, got {self.refine}")
        if self.refine and self.search_budget < 2 * self.batch_size:
            raise InputError(
                f"--refine-runs: {self.refine} runs for each of {self.refine_candidates} candidate pairs leave "
                f"{self.search_budget} of --budget {self.budget} for the search, under two batches "
                f"({2 * self.batch_size}); lower --refine-runs or --pairs, or raise --budget"
            )
        if not (0 < self.refine_min_distance < self.refine_max_distance):
            raise InputError(
                f"refine_max_distance: expected more than refine_min_distance ({self.refine_min_distance}), "
                f"got {self.refine_max_distance}"
            )
        self.noise()
        if not isinstance(self.dithers, int) or self.dithers < 0:
            raise InputError(f"--dithers: expected a number of runs >= 0, got {self.dithers}")
        if not isinstance(self.confirm_runs, int) or self.confirm_runs < 2 * self.pairs:
            raise InputError(
                f"--confirm-runs: expected at least two runs per pair ({2 * self.pairs}), got {self.confirm_runs}"
            )


# -- 1. search --------------------------------------------------------------------------
@dataclass(frozen=True)
class MissionScores:
    """Every score of unit-cube scenarios (NaN rows for invalid ones); picklable, so it runs on any executor."""

    mission: Mission
    surrogate: Any = None  # fly a learned copy of the autonomy instead of the expert

    def __call__(self, U: np.ndarray) -> np.ndarray:
        return sim.uuv.simulate(self.mission, U, surrogate=self.surrogate).scores


ROOT_COLUMNS = (0, 1)  # mission and safety success: what the search steers on
# S-NDV's neighbours come from at most this many samples (rapt NNDVSampler.max_reference):
# a mission's parameters all matter, so its effective dimension is high and neighbour
# queries cost O(n) each; past this the asks of a 10^5-run study would dominate it.
SEARCH_REFERENCE = 10_000


def make_executor(spec: str):
    """``local`` (in process), ``processes`` (one per core) or ``dask://host:port``; returns (executor, close)."""
    if spec == "local":
        return None, lambda: None
    if spec == "processes":
        import concurrent.futures as cf
        import multiprocessing as mp
        import os

        pool = cf.ProcessPoolExecutor(max_workers=os.cpu_count() or 2, mp_context=mp.get_context("spawn"))
        return pool, lambda: pool.shutdown(cancel_futures=True)
    if spec.startswith("dask://"):
        try:
            from distributed import Client
        except ImportError:
            raise InputError("--executor: dask:// needs the cluster extra; pip install -e '.[cluster]'") from None
        client = Client(f"tcp://{spec[len('dask://') :]}", timeout=10)
        return client, client.close
    raise InputError(f"--executor: expected local, processes or dask://host:port, got {spec!r}")


def search_mission(
    mission: Mission,
    cfg: GenerateConfig,
    progress: Callable[[int, int], None] | None = None,
    on_batch: Callable[[np.ndarray, np.ndarray], None] | None = None,
) -> rapt.Study:
    """Global then adaptive search steered by mission and safety success; invalid scenarios fail.

    With ``cfg.noisy_search`` the runs are stochastic and continuous metrics steer too
    (:mod:`planner.plan.noisy_search`).

    Every score is stored with its run, so the sub-boundary analysis needs no second run,
    and the neighbour graph the analysis pairs through grows with the batches (and is
    stored with them), so it need not be built once the search ends.
    """
    batch_size = auto_batch_size(cfg.budget) if cfg.batch_size is None else cfg.batch_size  # as __post_init__
    fn: Callable[[np.ndarray], np.ndarray] = MissionScores(mission, cfg.surrogate)
    steer, types = list(ROOT_COLUMNS), ROOT_OUTPUT_TYPES
    if cfg.noisy_search:  # section 4.2.3: stochastic runs, steered by continuous metrics as well as the modes
        fn, (steer, types) = NoisyMissionScores(mission, cfg.seed), noisy_columns(mission)
    return rapt.search(
        fn,
        mission.space,
        cfg.search_budget,
        method="s-ndv",
        batch_size=batch_size,
        seed=cfg.seed,
        store=cfg.store,
        executor=cfg.executor,
        output_types=types,
        steer=steer,
        sampler_options={"max_reference": SEARCH_REFERENCE},
        n_initial=int(round(cfg.search_budget * cfg.global_fraction)),
        progress=progress,
        on_batch=on_batch,
        neighbour_graph=12,  # subboundary_tree's k
    )


# -- everything ------------------------------------------------------------------------------
def generate(
    mission: Mission,
    mission_path: Path,
    out_dir: Path,
    cfg: GenerateConfig,
    progress: Callable[[str, int, int, str], None] | None = None,
    timings: dict[str, float] | None = None,
) -> dict:
    """Run every stage and write ``plan.json`` (plus per-scenario files and the report) into ``out_dir``.

    ``progress(stage, done, total, detail)`` follows the stages; during the search
    ``detail`` says how many modes and boundary links the runs so far show
    (:class:`~planner.plan.search_status.SearchStatus`).  ``timings``, when given, receives the
    wall seconds of each stage (kept out of the plan, which depends on the seed only).
    """
    cfg.check()
    embedded = _mission_text(mission, Path(mission_path))
    noise = cfg.noise(mission)
    sigma = noise.sigmas(mission)  # a noise too wide for a parameter fails before the search
    out_dir = Path(out_dir)
    out_dir.mkdir(parents=True, exist_ok=True)
    clock = _StageClock(timings)
    a, candidates, confirmation, refinement = _choose_pairs(mission, cfg, progress, clock)
    sens = coordinate_sensitivity(mission.space, a.sensitivity)
    evaluated, spent = _evaluate(mission, cfg, a, candidates, sigma, sens)
    if candidates and not evaluated:  # the expert may confirm none on the surrogate workflow: that plan stands
        raise InputError(no_boundary(mission, a.result.modes, written_away=len(candidates)))
    if progress is not None and cfg.dithers:
        done = spent["dithering"] + spent["variants"] + spent["shifts"]
        progress("dither", len(evaluated), len(candidates), f"{done:,} runs")
    clock.lap("dithering")
    ranked = rank_candidates(evaluated, cfg.pairs)
    pairs = [c.pair for c in ranked]
    ids = [f"pair{p}{side}" for p in range(1, len(pairs) + 1) for side in "ab"]
    U = np.vstack([c.U for c in ranked]) if ranked else np.zeros((0, mission.dim))
    chosen = sim.uuv.simulate(mission, U, trajectories=True)  # as evaluate_candidates: the same modes, with tracks
    stats = [st for c in ranked for st in c.stats]
    dither_runs = {sid: ranked[k // 2].dithers[k % 2] for k, sid in enumerate(ids) if ranked[k // 2].dithers}
    flown = [k for k in range(len(ids)) if ranked[k // 2].flies_variant[k % 2]]
    found = [v for k in flown if (v := ranked[k // 2].variant(k % 2)) is not None]  # a flown variant exists
    clock.lap("variants")
    scenarios = scenario_entries(mission, a, U, ids, chosen, stats, out_dir)
    variants = variant_entries(mission, ids, flown, found, chosen, out_dir)
    remove_unlisted(out_dir, [sc["id"] for sc in scenarios + variants])
    verdicts = _verdicts(cfg, ranked)
    runs = {
        "search": cfg.search_budget,
        "refinement": refinement["runs"] if refinement else 0,
        "dithering": spent["dithering"],
        "variants": spent["variants"],
        "shifts": spent["shifts"],
    }
    dithering = {
        "expected": noise.as_dict(),
        "noise_source": _noise_source(cfg, mission),
        "sigma_u": [float(v) for v in sigma],
        "target": cfg.fragile_below,
        "candidates": len(candidates),
        "candidates_written": len(evaluated),
    }
    plan = _plan_document(
        mission,
        mission_path,
        embedded,
        cfg,
        a,
        pairs,
        verdicts,
        confirmation,
        refinement,
        runs,
        dithering,
        scenarios,
        variants,
    )
    write_text_atomic(out_dir / "plan.json", json.dumps(plan, indent=2))
    write_report(plan, out_dir, dither_runs)
    clock.lap("files")
    return plan


def _mission_text(mission: Mission, mission_path: Path) -> dict[str, str]:
    """The mission file's text and digest for ``plan.json``, so the plan carries the mission it was made for."""
    from sim.uuv.missionfile import load_mission_text

    try:
        text = mission_path.read_bytes().decode("utf-8")
    except (OSError, UnicodeDecodeError) as exc:
        raise InputError(f"MISSION_FILE: cannot read {mission_path} to embed it in the plan ({exc})") from None
    if load_mission_text(text, str(mission_path)) != mission:
        raise StudyMismatchError(
            f"MISSION_FILE: {mission_path} no longer holds the mission being planned (edited meanwhile?); "
            "run rapt-plan generate again"
        )
    return embedded_mission(text)


def _choose_pairs(
    mission: Mission, cfg: GenerateConfig, progress: Callable[[str, int, int, str], None] | None, clock: _StageClock
) -> tuple[Analysis, list[dict], Confirmation | None, dict | None]:
    """Stages 1-3 (with refinement, and the expert's confirmation on the surrogate workflow).

    Returns the analysis, the candidate pairs (more than the plan keeps), on the surrogate workflow the expert's
    :class:`~planner.plan.confirmation.Confirmation` (None otherwise), and the refinement's
    account (None without ``--refine``).
    """
    status: SearchStatus | None = None
    searched: Callable[[int, int], None] | None = None
    if progress is not None:
        status = SearchStatus(mission.dim)
        searched = _search_progress(progress, status)
    study = search_mission(mission, cfg, searched, on_batch=status)
    clock.lap("search")
    sur = cfg.surrogate
    a = analyse(mission, study, sur, stochastic_seed=cfg.seed if cfg.noisy_search else None)
    clock.lap("analysis")
    wanted = cfg.pairs_wanted
    # more candidates than pairs: the plan keeps those the vehicle is most likely to show (pair_choice)
    n_candidates = cfg.refine_candidates if cfg.refine else (wanted if sur is not None else 2 * wanted)
    pairs = select_pairs(a, n_candidates)
    if not pairs:
        raise InputError(no_boundary(mission, a.result.modes))
    clock.lap("selection")
    refinement = None
    if cfg.refine:
        pairs, refinement = refine_pairs(
            mission,
            a,
            pairs,
            wanted if sur is not None else len(pairs),  # every candidate sharpened: the ranking chooses
            runs=cfg.refine,
            min_distance=cfg.refine_min_distance,
            max_distance=cfg.refine_max_distance,
            seed=cfg.seed,
            surrogate=sur,
        )
        if progress is not None:
            progress("refine", refinement["sharp"], refinement["candidates"], f"{refinement['runs']:,} runs")
        clock.lap("refinement")
    confirmation = None
    if sur is not None:
        confirmation = confirm_with_expert(mission, a, pairs, cfg.pairs, cfg.confirm_runs)
        pairs = confirmation.pairs
        if progress is not None:
            progress(
                "confirm",
                len(pairs),
                confirmation.examined,
                f"{len(pairs)} of {confirmation.examined} candidate pairs examined confirmed, "
                f"{confirmation.runs} expert runs",
            )
        clock.lap("confirmation")
    return a, pairs, confirmation, refinement


def _search_progress(
    progress: Callable[[str, int, int, str], None], status: SearchStatus
) -> Callable[[int, int], None]:
    """The search's ``progress``: runs done of the budget, and what the runs so far show (``status``)."""
    return lambda done, total: progress("search", done, total, status.summary())


def _evaluate(
    mission: Mission, cfg: GenerateConfig, a: Analysis, candidates: list[dict], sigma, sens
) -> tuple[list[Candidate], dict[str, int]]:
    """The candidates written, dithered and given variants, then their fragile pairs moved as a whole
    (:func:`~planner.plan.pair_shifts.with_shifted_pairs`); the runs each stage spent."""
    how = Dithering(cfg.dithers, sigma, sens, cfg.fragile_below, cfg.seed, cfg.surrogate)
    points = lambda pair: pair_points(a, pair)  # noqa: E731
    evaluated, spent = evaluate_candidates(mission, a.tree.levels, candidates, points, how)
    budget = spent["dithering"] + spent["variants"]
    evaluated, spent["shifts"] = with_shifted_pairs(
        mission, a.tree.levels, evaluated, how, pairs=cfg.pairs, budget=budget
    )
    return evaluated, spent


def _verdicts(cfg: GenerateConfig, ranked: list[Candidate]) -> list[dict]:
    """Per pair: P(predicted outcome) of each side and of its flown variant, P(straddle) and a one-word verdict.

    *sharp*: refined to at most ``refine_max_distance`` and both sides hold as planned;
    *robust*: every side holds, as planned or through its variant; *fragile*: a side that
    does not hold has no variant the range can fly (``reason`` says why). No verdict without dithering.
    """
    out: list[dict] = []
    for cand in ranked:
        given = [cand.stats[s].get("p_predicted") for s in (0, 1)]
        if not cfg.dithers or None in given:
            out.append({})
            continue
        probs = [float(p) for p in given if p is not None]
        variant_p = [cand.p_side(s, True) if cand.flies_variant[s] else None for s in (0, 1)]
        holds = [pr >= cfg.fragile_below or (vp or 0.0) >= cfg.fragile_below for pr, vp in zip(probs, variant_p)]
        if all(pr >= cfg.fragile_below for pr in probs) and cand.pair["distance"] <= cfg.refine_max_distance:
            verdict = "sharp"
        else:
            verdict = "robust" if all(holds) else "fragile"
        entry: dict[str, Any] = {
            "p_predicted": probs,
            "variant_p_predicted": variant_p,
            "p_straddle": cand.p_straddle,
            "flown_distance": cand.flown_distance,
            "verdict": verdict,
        }
        if verdict == "fragile":
            entry["reason"] = "; ".join(
                f"side {'ab'[s]}: {_no_variant_reason(cand, s, cfg.fragile_below)}" for s in (0, 1) if not holds[s]
            )
        out.append(entry)
    return out


def _no_variant_reason(cand: Candidate, side: int, target: float) -> str:
    v = cand.variant(side)
    if v is None:
        return str((cand.variants[side] or {}).get("reason") or "no variant was sought")
    held = f"its closest variant holds {v['p_predicted']:.0%}, under the {target:.0%} target"
    if cand.flies_variant[side]:
        return held
    if v["p_predicted"] <= (cand.p_side(side, False) or 0.0):
        return f"{held}, and no more often than the side itself"
    return f"its variant lies more than {MAX_FLOWN_DISTANCE:g} from the other side"


def _plan_document(
    mission: Mission,
    mission_path: Path,
    embedded: dict[str, str],
    cfg: GenerateConfig,
    a: Analysis,
    pairs: list[dict],
    verdicts: list[dict],
    confirmation: Confirmation | None,
    refinement: dict | None,
    runs: dict[str, int],
    dithering: dict,
    scenarios: list[dict],
    variants: list[dict],
) -> dict:
    """What ``plan.json`` holds (schema :data:`~planner.common.plans.PLAN_SCHEMA`)."""
    sur = cfg.surrogate
    variant_ids = {v["id"] for v in variants}
    plan_pairs = []
    for p, (pair, verdict) in enumerate(zip(pairs, verdicts), start=1):
        sides = [f"pair{p}a", f"pair{p}b"]
        entry = {
            "id": p,
            "level": pair["level"],
            "elements": pair["elements"],
            "modes": pair["modes"],
            "distance": pair["distance"],
            "scenarios": sides,
            "refined": bool(pair.get("refined", False)),
            **({key: pair[key] for key in _CONFIRMED_FIELDS} if sur is not None else {}),
        }
        if pair.get("refined"):
            entry["refinement"] = {"start_distance": pair["start_distance"], "runs": pair["refine_runs"]}
        if pair.get("shifted"):
            entry["shifted"] = pair["shifted"]
        if verdict:
            entry.update(verdict)
            entry["variants"] = [f"{sid}M" if f"{sid}M" in variant_ids else None for sid in sides]
        plan_pairs.append(entry)
    modes = a.result.modes
    return {
        "schema": PLAN_SCHEMA,
        "mission": {
            "name": mission.name,
            "file": str(mission_path),
            "dim": mission.dim,
            "parameters": mission.space.names,
            **embedded,
            **_planned_for(mission, embedded),
        },
        "study": {
            "budget": cfg.budget,
            "seed": cfg.seed,
            "global_fraction": cfg.global_fraction,
            "search": search_record(mission, cfg.noisy_search, sur is not None, ROOT_COLUMNS),
            "valid_runs": int(len(a.X)),
            "invalid_runs": int(len(a.X_invalid)),
            "modes": {MODE_NAMES[m]: int(c) for m, c in zip(*np.unique(modes, return_counts=True))},
            "boundary_types": a.boundary_types[:30],
            "unreached": unreached(mission, a.result.scores, modes, a.result.names, a.result.output_types),
            "runs": runs,
            "dithering": {**dithering, "runs_per_scenario": cfg.dithers // 2},
            **({"refinement": refinement} if refinement is not None else {}),
            **({"surrogate": _surrogate_summary(cfg, confirmation)} if confirmation is not None else {}),
        },
        "runtime": numerical_runtime(),
        "sensitivity": a.sensitivity,
        "pairs": plan_pairs,
        "scenarios": scenarios,
        "variants": variants,
        "run_order": [s["id"] for s in scenarios] + [v["id"] for v in variants],
    }


def _noise_source(cfg: GenerateConfig, mission: Mission) -> str:
    """Where the plan's execution noise came from, for ``study.dithering.noise_source``."""
    if cfg.dither_sigma is not None:
        return "--dither-sigma"
    if mission.execution_noise is not None:
        return f"[execution_noise] of the mission file ({mission.execution_noise.source or 'no source given'})"
    return "the default assumption"


def _planned_for(mission: Mission, embedded: dict[str, str]) -> dict:
    """``{"planned_for": ...}`` when the mission file names its day's vehicle or water, else nothing."""
    rec = planned_for(mission, embedded.get("toml", ""), embedded.get("sha256", ""))
    return {} if rec is None else {"planned_for": rec}


_CONFIRMED_FIELDS = ("confirmed_by_expert", "surrogate_modes", "surrogate_elements", "moved_by", "expert_runs")


def _surrogate_summary(cfg: GenerateConfig, confirmation: Confirmation) -> dict:
    """The plan's account of a surrogate search: its file and method, expert runs, candidates examined and confirmed."""
    sur = cfg.surrogate
    return {
        "file": cfg.surrogate_file,
        "method": str(sur.training.get("method", "")),
        "expert_runs": {"training": int(sur.training.get("runs", 0)), "confirmation": confirmation.runs},
        "confirm_budget": cfg.confirm_runs,
        "candidates": confirmation.candidates,
        "examined": confirmation.examined,
        "confirmed": len(confirmation.pairs),
        "share_confirmed": confirmation.share_confirmed,
    }


class _StageClock:
    """Wall seconds per stage into a caller's dict (or nowhere)."""

    def __init__(self, into: dict[str, float] | None):
        self.into = into
        self.last = time.perf_counter()

    def lap(self, stage: str) -> None:
        now = time.perf_counter()
        if self.into is not None:
            self.into[stage] = self.into.get(stage, 0.0) + now - self.last
        self.last = now
