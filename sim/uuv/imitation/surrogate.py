"""A trained surrogate as a file: its policy, its feature definition and the mission it imitates.

A surrogate learned on one mission knows nothing of another's obstacles, waypoints or
battery: loading it for a different mission (any change to the mission file's content)
is refused with the two missions named.  The file is a numpy ``.npz`` archive holding
the networks' float32 weights and a JSON header (format, mission name and digest,
feature definition, how it was trained).
"""

from __future__ import annotations

import dataclasses
import hashlib
import json
import zipfile
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from rapt.errors import FileFormatError, InputError, MissingFileError, StudyMismatchError
from rapt.imitation.policies import HeadsPolicy, MLPPolicy, policy_from_arrays
from sim.uuv.imitation.features import OBSERVATIONS, FeatureSpec, feature_spec
from sim.uuv.mission import Mission
from sim.uuv.sonar import SCAN_BEAMS

__all__ = ["Surrogate", "mission_digest", "FORMAT"]

FORMAT = "rapt.surrogate/4"
#: Formats this version reads: /4 records its observation model (the expert's remembered
#: contacts, or the 360-degree scan).  /3 saw a scan without memory, /1 and /2 flew a velocity
#: vector: all must be retrained.
READS = (FORMAT,)
#: What each older format observed, for the message that refuses it.
OLDER = {
    "rapt.surrogate/3": "a 360-degree scan with no memory of contacts",
    "rapt.surrogate/2": "a velocity vector on a 360-degree scan",
    "rapt.surrogate/1": "a velocity vector on a 360-degree scan",
}


def mission_digest(mission: Mission) -> str:
    """A digest of everything that defines the mission (not where its file lies)."""
    text = repr(dataclasses.replace(mission, source=""))
    return hashlib.sha256(text.encode()).hexdigest()[:16]


@dataclass
class Surrogate:
    """A learned back-seat for ``mission_name`` (digest ``mission_sha``)."""

    policy: MLPPolicy | HeadsPolicy
    spec: FeatureSpec
    mission_name: str
    mission_sha: str
    training: dict = field(default_factory=dict)
    #: The goal output above which the back-seat gives the waypoint up (calibrated on held-out
    #: expert runs: a decision seen once per aborted run is learned late, see planner.plan.surrogate).
    goal_threshold: float = 0.0

    @classmethod
    def for_mission(
        cls,
        mission: Mission,
        policy: MLPPolicy | HeadsPolicy,
        training: dict | None = None,
        goal_threshold: float = 0.0,
        observation: str = "contacts",
    ) -> Surrogate:
        spec = feature_spec(mission, observation)
        if policy.n_features != spec.size:
            raise InputError(f"policy: takes {policy.n_features} features, the mission's definition has {spec.size}")
        if policy.n_outputs != spec.actions:
            raise InputError(
                f"policy: gives {policy.n_outputs} outputs, a back-seat needs {spec.actions} "
                "(heading forward and starboard, the goal decision and the speed)"
            )
        return cls(policy, spec, mission.name, mission_digest(mission), dict(training or {}), float(goal_threshold))

    def check(self, mission: Mission) -> None:
        """Refuse a mission this surrogate was not trained for."""
        if mission_digest(mission) != self.mission_sha:
            raise StudyMismatchError(
                f"surrogate: trained for mission '{self.mission_name}' ({self.mission_sha}), not for "
                f"'{mission.name}' ({mission_digest(mission)}); train one for this mission"
            )
        if self.spec.observation not in OBSERVATIONS:
            raise StudyMismatchError(
                f"surrogate: observation model {self.spec.observation!r} is not one this version flies "
                f"({', '.join(OBSERVATIONS)}); retrain it with `rapt-plan surrogate`"
            )
        mine = feature_spec(mission, self.spec.observation, self.spec.beams or SCAN_BEAMS)
        if mine != self.spec:
            raise StudyMismatchError(
                f"surrogate: it observes {self.spec.describe()}, this mission's learner observes {mine.describe()}; "
                "retrain it with `rapt-plan surrogate`"
            )

    def autonomy(self, scen):
        """The back-seat flying ``scen``."""
        from sim.uuv.imitation.driver import PolicyAutonomy

        return PolicyAutonomy(scen, self.policy, self.spec, self.goal_threshold)

    def driver_options(self) -> dict:
        """Keyword arguments for :func:`sim.uuv.simulate.run_scenarios` to fly this surrogate."""
        return {"driver": self.autonomy, "scan_beams": self.spec.beams}

    def save(self, path: str | Path) -> Path:
        path = Path(path)
        if path.suffix != ".npz":
            raise InputError(f"path: a surrogate file ends in .npz, got {str(path)!r}")
        header = {
            "format": FORMAT,
            "mission": self.mission_name,
            "mission_sha": self.mission_sha,
            "features": self.spec.to_dict(),
            "feature_names": self.spec.names(),
            "training": self.training,
            "goal_threshold": self.goal_threshold,
        }
        arrays = self.policy.to_arrays()
        path.parent.mkdir(parents=True, exist_ok=True)
        tmp = path.with_name(path.name + ".part.npz")
        # numpy's stub lets **arrays bind savez's allow_pickle (a bool); the policy's keys are array names only
        np.savez(tmp, header=np.array(json.dumps(header)), **arrays)  # type: ignore[arg-type]
        tmp.replace(path)
        return path

    @classmethod
    def load(cls, path: str | Path, mission: Mission | None = None) -> Surrogate:
        """Read a surrogate file; with ``mission``, refuse it unless trained for that mission."""
        path = Path(path)
        if not path.is_file():
            raise MissingFileError(f"surrogate: {str(path)!r} does not exist; train one with `rapt-plan surrogate`")
        not_ours = (OSError, ValueError, KeyError, TypeError, EOFError, zipfile.BadZipFile)  # truncated too
        try:
            with np.load(path, allow_pickle=False) as z:
                header = json.loads(str(z["header"]))
                arrays = {k: z[k] for k in z.files if k != "header"}
        except not_ours as exc:
            raise FileFormatError(f"surrogate: {str(path)!r} is not a surrogate file ({exc})") from exc
        got = header.get("format") if isinstance(header, dict) else None
        if got in OLDER:
            raise FileFormatError(
                f"surrogate: {str(path)!r} ({got}) observes {OLDER[got]}, not the expert's remembered contacts; "
                "retrain it with `rapt-plan surrogate`"
            )
        if got not in READS:
            raise FileFormatError(
                f"surrogate: {str(path)!r} has format {got!r}, expected one of "
                f"{', '.join(READS)}; retrain it with `rapt-plan surrogate`"
            )
        try:
            policy = policy_from_arrays(arrays)
            spec = FeatureSpec.from_dict(header["features"])
        except not_ours as exc:
            raise FileFormatError(f"surrogate: {str(path)!r} is not a surrogate file ({exc})") from exc
        out = cls(
            policy,
            spec,
            header["mission"],
            header["mission_sha"],
            header.get("training", {}),
            float(header.get("goal_threshold", 0.0)),
        )
        if mission is not None:
            out.check(mission)
        return out
