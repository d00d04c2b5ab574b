"""Decision columns learned as classifiers: switch-weighted updates, then a sharp refit (section 6.4).

``decisions`` names action columns that are discrete switches (+1 / -1: abort, return,
transmit).  Regressed on +-1 with squared error, a switch the expert throws once per run
(after which the run no longer shows the state) is a rare label, and the learned output
is a ramp whose zero crossing lies late or early by more than the boundary it should
place.  A decision column instead gets a network of its own trained as a classifier
(logistic output, cross-entropy, which keeps sharpening a separable switch where squared
error settles), its two classes weighed equally, and the states within ``switch_window``
steps of one of the expert's switches in their run weighed ``switch_weight`` times more:
those states fix where the switch lies (:func:`near_switches`, :class:`DecisionLearner`).
Its output is ``2 p - 1`` (p the probability of +1), on the scale of the labels.  Adam
over a few epochs an update still leaves a ramp a few percent of the input range wide
(the expert's switch on charge is a fraction of a watt-hour), so once the updates are
done each decision is refitted by L-BFGS to convergence on standardised inputs by a few
small networks whose logits are averaged (:func:`sharp_classifier`, :data:`SHARP_HIDDEN`,
:data:`SHARP_MEMBERS`), on the states where it is taken, all those near a switch and a
seeded ``far_share`` of the rest.
The updates themselves keep the smoother Adam classifier: trained to convergence on the
first updates' handful of switches, a network generalises them badly and the learner,
turning home early, never shows the late states that would correct it.
"""

from __future__ import annotations

import warnings
from collections.abc import Sequence

import numpy as np

from rapt.imitation.policies import MLPPolicy

__all__ = ["near_switches", "DecisionLearner", "SHARP_HIDDEN", "SHARP_MEMBERS", "sharp_classifier"]


def near_switches(A: np.ndarray, lengths: list[int], decisions: Sequence[int], window: int) -> np.ndarray:
    """Whether each stacked state lies within ``window`` steps of a switch of a ``decisions`` column
    in its own run (``lengths``: the runs' numbers of states, in order)."""
    near = np.zeros(A.shape[0], dtype=bool)
    start = 0
    for n in lengths:
        for d in decisions:
            label = A[start : start + n, d] > 0
            for k in (np.flatnonzero(label[1:] != label[:-1]) + 1).tolist():
                near[start + max(k - window, 0) : start + min(k + window, n)] = True
        start += n
    return near


class DecisionLearner:
    """One decision column's classifier across updates (see the module docstring)."""

    def __init__(self, options: dict, epochs: int, weight: float, seed: int):
        from sklearn.neural_network import MLPClassifier

        self.model = MLPClassifier(**options, random_state=seed)
        self.epochs, self.weight = epochs, weight

    def fit(self, x: np.ndarray, positive: np.ndarray, near: np.ndarray) -> MLPPolicy:
        """``epochs`` more passes over states ``x`` labelled ``positive``; the classifier as a policy."""
        w = np.where(near, self.weight, 1.0)
        if positive.any() and not positive.all():  # each class carries half the weight
            total = w.sum()
            for cls in (positive, ~positive):
                w[cls] *= total / (2.0 * w[cls].sum())
        self.model.set_params(batch_size=min(int(self.model.batch_size), x.shape[0]))
        for _ in range(self.epochs):  # one pass each; the classes are fixed up front, as the first
            # runs may show no switch at all
            self.model.partial_fit(x, positive.astype(np.int64), classes=[0, 1], sample_weight=w)
        return MLPPolicy.from_sklearn(self.model)


#: The classifier that sharpens a decision at the end: SHARP_MEMBERS networks of one small hidden
#: layer, each trained to convergence by L-BFGS from its own start, their logits averaged.  A
#: switch depends on a few features; a small network has little room to lean on the others, and
#: the average steadies where members trained on the same states place it.
SHARP_HIDDEN = 4
SHARP_MEMBERS = 5


def sharp_classifier(
    x: np.ndarray, positive: np.ndarray, near: np.ndarray, iterations: int, far_share: float, seed: int
) -> MLPPolicy | None:
    """A classifier of ``positive`` on ``x`` trained by L-BFGS on standardised inputs, from the states
    ``near`` a switch and a seeded ``far_share`` of the rest; None without both classes.  The
    members' average logit is itself one network (their hidden units side by side)."""
    from sklearn.exceptions import ConvergenceWarning
    from sklearn.neural_network import MLPClassifier

    rng = np.random.default_rng([seed, 0x736861])
    keep = near | (rng.random(near.size) < far_share)
    x, positive = x[keep], positive[keep]
    if positive.all() or not positive.any():
        return None
    mu, sd = x.mean(axis=0), np.maximum(x.std(axis=0), 1e-3)
    members = []
    for k in range(SHARP_MEMBERS):
        model = MLPClassifier(
            (SHARP_HIDDEN,),
            activation="logistic",
            solver="lbfgs",
            max_iter=iterations,
            tol=0.0,
            random_state=seed * SHARP_MEMBERS + k,
        )
        with warnings.catch_warnings():
            warnings.simplefilter("ignore", ConvergenceWarning)
            model.fit((x - mu) / sd, positive.astype(np.int64))
        members.append(model)
    W0 = np.concatenate([m.coefs_[0] for m in members], axis=1) / sd[:, None]  # standardisation folded in
    b0 = np.concatenate([m.intercepts_[0] for m in members]) - mu @ W0
    W1 = np.concatenate([m.coefs_[1] for m in members], axis=0) / SHARP_MEMBERS
    b1 = np.mean([m.intercepts_[1] for m in members], axis=0)
    return MLPPolicy(
        [W0.astype(np.float32), W1.astype(np.float32)],
        [b0.astype(np.float32), b1.astype(np.float32)],
        "logistic",
        "decision",
    )
