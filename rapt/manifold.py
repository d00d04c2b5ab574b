"""Manifold-constrained adaptive sampling (chapter 5, Algorithms 6 and 7).

Some systems accept only states on unknown constraint manifolds: a tipped-over robot can
rest only on a face of its convex hull, so of a state ``[θ, φ]`` (free joint angles θ,
constrained body angles φ) only the φ in a finite set ``Z_θ`` are valid.  The system
*projects* each query onto a valid state and reports it, the valid set ``Z_θ`` and the
label (Algorithm 5).  :class:`ManifoldSampler` follows that protocol on rapt's ask/tell
core:

* it learns from the states the system *used* (``tell(X_start, Y, faces)``), not the ones
  asked;
* candidates come from a nearest-neighbour metamodel of ``θ → Z_θ``: random θ, each paired
  with every valid φ of the nearest evaluated θ (Algorithm 7);
* NNDV information (section 5.4.3): over the K nearest evaluated states, the label
  variance σ and the volume ``V`` (distance to the farthest of the K); ``I = α σ/σ_max + β V``
  (σ scaled to [0, 1] so that α and β weigh comparable terms);
* outcomes (optional, ``tell(..., outcomes=...)``): where each unstable state ends up.
  Neighbours on one manifold that tip to different places then disagree too, and σ is their
  unalikeability (eq. 3.6) on the variance's scale (the label variance when there are two
  classes).  A stable
  island on a face, narrower than the sample spacing, reads "unstable" on both sides, but
  its two sides tip over opposite edges of the face: different outcomes bracket it.
* resolution cut-offs end the search (Algorithm 6): a candidate whose neighbours all agree
  is dropped once ``V < r_max``, one on a boundary once ``V < r_min``; when no candidate is
  left the sampler has finished early, as :class:`~rapt.samplers.base.Sampler` defines it:
  :meth:`ask` returns no points and :attr:`done` is set.
* ``whole_hulls=True`` is for systems that label *every* valid φ of each asked θ (one hull
  computation settles every face): candidates are then ranked per free state θ (its best
  face's information), a batch holds distinct θ, and ``ask(n)`` returns about
  ``n / mean faces`` of them so that ``n`` stays the number of labelled states.  A θ told
  with one face only (a single-face query, as the transition refinement asks) still names
  its hull's other faces: there they are present, not gone, and read as the nearest θ
  that labelled them.

Distances are taken between angles embedded as ``(cos a, sin a)``: section 5.4.1's cosine
distance ``|cos x₀ − cos x₁|`` is periodic but maps ``a`` and ``−a`` together; the
embedding keeps its periodicity without that ambiguity, and its chord length equals the
angle for small differences (so resolutions are in radians).
"""

from __future__ import annotations

from collections.abc import Callable, Sequence

import numpy as np
from scipy.spatial import cKDTree

from rapt.candidates import select_batch
from rapt.errors import InputError
from rapt.information import neighbour_variance, unalikeability
from rapt.parallel import query_workers
from rapt.samplers.base import Sampler
from rapt.transitions import separate

__all__ = ["angular_embedding", "full_turn", "ManifoldSampler", "manifold_search"]


def full_turn(lo, hi) -> np.ndarray | bool:
    """Whether a radian range ``[lo, hi]`` is a whole turn: such a coordinate wraps around."""
    return np.asarray(hi) - np.asarray(lo) >= 2 * np.pi - 1e-9


def angular_embedding(U: np.ndarray, bounds: np.ndarray) -> np.ndarray:
    """Unit-cube states (n, d) → ``(cos a, sin a)`` per coordinate (n, 2d), ``a = lo + u (hi − lo)`` radians."""
    U = np.asarray(U, dtype=float)
    bounds = np.asarray(bounds, dtype=float).reshape(-1, 2)
    a = bounds[:, 0] + U * (bounds[:, 1] - bounds[:, 0])
    out = np.empty(U.shape[:-1] + (2 * U.shape[-1],))
    out[..., 0::2] = np.cos(a)
    out[..., 1::2] = np.sin(a)
    return out


class ManifoldSampler(Sampler):
    """Algorithms 6-7: NNDV search over states whose last coordinates lie on estimated manifolds.

    Parameters
    ----------
    n_free: number of leading free coordinates (joint angles θ); the rest are constrained (φ).
    bounds: (d, 2) angle range in radians of every coordinate (unit-cube ``u`` ↔ ``lo + u (hi − lo)``).
    k: neighbours of the NNDV metamodel.
    alpha, beta: weights of the variance (exploit the boundary) and volume (explore) terms.
    r_min, r_max: boundary and interior resolutions (radians, embedded distance).
    n_initial: uniform random queries before the search turns adaptive.
    candidates_per_point, min_candidates: about ``max(candidates_per_point · n, min_candidates)`` candidates a batch.
    separation: near-duplicate suppression inside a batch, a multiple of each candidate's ``V``.
    whole_hulls: the system labels every valid constrained value of each asked free state;
        rank and batch free states, not single states (see the module docstring).
    """

    name = "manifold-nndv"
    adaptive = True

    def __init__(
        self,
        n_free: int,
        bounds: np.ndarray | Sequence[Sequence[float]],
        *,
        seed: int = 0,
        k: int = 6,
        alpha: float = 1.0,
        beta: float = 1.0,
        r_min: float = np.radians(1.0),
        r_max: float = np.radians(10.0),
        n_initial: int = 100,
        candidates_per_point: float = 10.0,
        min_candidates: int = 1000,
        separation: float = 0.5,
        whole_hulls: bool = False,
    ):
        ranges = np.asarray(bounds, dtype=float)
        if ranges.ndim != 2 or ranges.shape[1] != 2 or not np.all(ranges[:, 1] > ranges[:, 0]):
            raise InputError(f"bounds: expected (d, 2) ranges with lower < upper, got {ranges.tolist()}")
        super().__init__(len(ranges), seed=seed, output_types=("binary",))
        if not 0 <= n_free < self.dim:
            raise InputError(
                f"n_free: expected 0 <= n_free < {self.dim} (at least one constrained coordinate), got {n_free}"
            )
        for name, value in (
            ("alpha", alpha),
            ("beta", beta),
            ("r_min", r_min),
            ("r_max", r_max),
            ("candidates_per_point", candidates_per_point),
            ("separation", separation),
        ):
            if not np.isfinite(value) or value < 0:
                raise InputError(f"{name}: expected a finite number >= 0, got {value!r}")
        if r_min > r_max:
            raise InputError(
                f"r_min: the boundary resolution ({r_min}) must not exceed the interior one, r_max ({r_max})"
            )
        if k < 2:
            raise InputError(f"k: need at least 2 neighbours for a variance, got {k}")
        self.n_free = int(n_free)
        self.bounds = ranges
        self.k = int(k)
        self.alpha, self.beta = float(alpha), float(beta)
        self.r_min, self.r_max = float(r_min), float(r_max)
        self.n_initial = int(n_initial)
        self.candidates_per_point = float(candidates_per_point)
        self.min_candidates = int(min_candidates)
        self.separation = float(separation)
        self.whole_hulls = bool(whole_hulls)
        if self.whole_hulls and self.n_free < 1:
            raise InputError("whole_hulls: needs at least one free coordinate (n_free >= 1) to group faces by")
        self._faces: list[np.ndarray] = []
        self._ids: list[int] = []
        self._face_ids: list[np.ndarray] | None = []
        self._outcomes: list[float] | None = []
        self.last_information: np.ndarray | None = None

    # -- data --------------------------------------------------------------------------------
    def tell(
        self,
        X: np.ndarray,
        Y: np.ndarray,
        faces: Sequence[np.ndarray] | None = None,
        ids: np.ndarray | None = None,
        face_ids: Sequence[np.ndarray] | None = None,
        outcomes: np.ndarray | None = None,
    ) -> None:
        """Record the states the system used, their labels and, per state, its valid constrained values.

        ``faces[i]`` is a (k_i, d − n_free) array of unit-cube constrained coordinates valid
        at ``X[i]``'s free coordinates (``Z_θ``); without it only ``X[i]`` itself is known.
        ``ids[i]`` and ``face_ids[i]`` (k_i,) optionally name the manifolds (a hull face's
        vertices): whole-hull information then follows a face by name, and a face that has
        disappeared at a neighbour counts as a change there (section 5.2: a face ceasing to
        exist ends its node), so the search resolves where faces appear and vanish too.
        ``outcomes[i]`` optionally names where an unstable ``X[i]`` ends up (any number, e.g.
        its resting face's identity; ignored for stable states); see the module docstring.
        Like identities they count only when every state has them.
        """
        X = np.asarray(X, dtype=float).reshape(-1, self.dim)
        if faces is None:
            faces = [x[None, self.n_free :] for x in X]
        if len(faces) != len(X):
            raise InputError(f"faces: expected one face set per state ({len(X)}), got {len(faces)}")
        faces = [np.asarray(f, dtype=float).reshape(-1, self.dim - self.n_free) for f in faces]
        if (ids is None) != (face_ids is None) or (
            ids is not None and face_ids is not None and (len(ids) != len(X) or len(face_ids) != len(X))
        ):
            raise InputError(f"ids, face_ids: give both, one per state ({len(X)}), or neither")
        if ids is None or self._face_ids is None or (self.n_told and not self._ids):
            self._face_ids = None  # identities only help when every state has them
        if outcomes is not None and len(outcomes) != len(X):
            raise InputError(f"outcomes: expected one per state ({len(X)}), got {len(outcomes)}")
        if outcomes is None or self._outcomes is None or (self.n_told and not self._outcomes):
            self._outcomes = None  # as identities: every state's, or none
        super().tell(X, Y)
        if self._outcomes is not None:
            self._outcomes.extend(np.asarray(outcomes, dtype=float).reshape(-1).tolist())
        self._faces.extend(faces)
        if self._face_ids is not None and ids is not None and face_ids is not None:  # kept only while both are told
            self._ids.extend(int(v) for v in ids)
            self._face_ids.extend(np.asarray(f, dtype=np.int64).reshape(-1) for f in face_ids)

    @property
    def faces(self) -> list[np.ndarray]:
        """Valid constrained values told with each state, in tell order."""
        return self._faces

    def embed(self, U: np.ndarray) -> np.ndarray:
        """The metric space of the search: :func:`angular_embedding` with this sampler's bounds."""
        return angular_embedding(U, self.bounds)

    def known_states(self) -> np.ndarray:
        """``X^Z``: every told free state paired with each of its valid constrained values (unit cube)."""
        X = self.X
        if not len(X):
            return np.empty((0, self.dim))
        counts = np.array([len(f) for f in self._faces])
        return np.column_stack([np.repeat(X[:, : self.n_free], counts, axis=0), np.concatenate(self._faces)])

    # -- Algorithm 7 ---------------------------------------------------------------------------
    def candidates(self, n: int, rng: np.random.Generator) -> np.ndarray:
        """Random free states, each with every valid constrained value of the nearest told free state."""
        return self._candidates(n, rng, self._free_tree())[0]

    def _free_tree(self) -> cKDTree | None:
        """k-d tree of the told free states (embedded), for :meth:`_on_nearest_faces`; None without free coordinates."""
        return cKDTree(angular_embedding(self.X[:, : self.n_free], self.bounds[: self.n_free])) if self.n_free else None

    def _candidates(self, n: int, rng: np.random.Generator, tree: cKDTree | None):
        """:meth:`candidates` with their groups and identities (see :meth:`_on_nearest_faces`)."""
        mean_faces = max(float(np.mean([len(f) for f in self._faces])), 1.0)
        p = max(int(np.ceil(max(self.candidates_per_point * n, self.min_candidates) / mean_faces)), 1)
        return self._on_nearest_faces(rng.random((p, self.n_free)), tree)

    def _on_nearest_faces(self, theta: np.ndarray, tree: cKDTree | None):
        """Algorithm 7's metamodel Π: each free state of ``theta`` (p, n_free) with every valid constrained value of
        the nearest told free state (``tree``: :meth:`_free_tree`).

        Returns the candidates, which row of ``theta`` each belongs to, and their manifold
        identities (None when the states were told without them).
        """
        p = len(theta)
        if tree is not None:  # there are free coordinates
            _, nn = tree.query(angular_embedding(theta, self.bounds[: self.n_free]), k=1, workers=query_workers(p))
        else:
            nn = np.zeros(p, dtype=int)
        sets = [self._faces[i] for i in nn]
        counts = np.array([len(s) for s in sets])
        groups = np.repeat(np.arange(p), counts)
        ids = np.concatenate([self._face_ids[i] for i in nn]) if self._face_ids else None
        return np.column_stack([np.repeat(theta, counts, axis=0), np.concatenate(sets)]), groups, ids

    def information(self, candidates: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """NNDV: (information I, label variance σ, volume V) per candidate."""
        tree = cKDTree(self.embed(self.X))
        k = min(self.k, self.n_told)
        dist, nbr = tree.query(self.embed(candidates), k=k, workers=query_workers(len(candidates)))
        dist, nbr = dist.reshape(len(candidates), k), nbr.reshape(len(candidates), k)
        sigma = self._spread(self._codes()[nbr])
        volume = dist.max(axis=1)
        return self.alpha * sigma / 0.25 + self.beta * volume, sigma, volume

    _STABLE, _ABSENT = -3.0, -2.0  # classes beside the told outcomes: stable, face gone at a neighbour

    def _codes(self) -> np.ndarray:
        """Each told state's class: its 0/1 label, or with outcomes "stable" or where it ends up."""
        Y = self.Y[:, 0]
        if not self._outcomes:
            return Y
        return np.where(Y > 0.5, self._STABLE, np.asarray(self._outcomes, dtype=float))

    def _spread(self, codes: np.ndarray) -> np.ndarray:
        """σ of each row of neighbour classes: the label variance, or with outcomes their unalikeability
        (eq. 3.6) times (k − 1) / 2k, half the Gini impurity: for two classes exactly the 0/1 variance."""
        if not self._outcomes:
            return neighbour_variance(codes)
        k = codes.shape[1]
        _, classes = np.unique(codes, return_inverse=True)
        return unalikeability(classes.reshape(codes.shape)) * (k - 1) / (2 * k)

    # -- Algorithm 6's selection and stopping rule --------------------------------------------
    def _propose(self, n: int, rng: np.random.Generator) -> np.ndarray:
        """Up to ``n`` queries (:meth:`Sampler.ask` validates, counts and clips); none once the resolution
        cut-offs leave no candidate, which finishes the search (:attr:`done`)."""
        if self.n_told < max(self.n_initial, self.k + 1):
            self.last_information = None
            return rng.random((self._hull_count(n) if self.whole_hulls else n, self.dim))
        if self.whole_hulls:
            return self._ask_hulls(n, rng)
        cand = self.candidates(n, rng)
        info, sigma, volume = self.information(cand)
        live = ~(((sigma == 0) & (volume < self.r_max)) | ((sigma > 0) & (volume < self.r_min)))
        cand, info, volume = cand[live], info[live], volume[live]
        if not len(cand):
            return np.empty((0, self.dim))
        m = min(int(n), len(cand))
        idx = select_batch(cand, info, m, self.separation * volume, self.embed(cand))
        self.last_information = info[idx]
        return cand[idx]

    def _hull_count(self, n: int) -> int:
        """Free states whose faces make about ``n`` labelled states (before any is told, a guess of 8 faces each)."""
        mean_faces = np.mean([len(f) for f in self._faces]) if self._faces else 8.0
        return max(int(round(n / max(mean_faces, 1.0))), 1)

    def hull_information(
        self, candidates: np.ndarray, cand_ids: np.ndarray | None = None
    ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """NNDV along the manifolds: (I, σ, V) per candidate when every face of each told θ is labelled.

        The K = 2 n_free nearest told free states θ_i are the neighbours; at each, the face
        nearest the candidate's φ stands for the candidate's manifold (the metamodel Π of
        Algorithm 7 applied to labels), so σ is the label variance *along* one manifold and
        is not raised by a parallel face nearby.  V is the distance in θ to the farthest of the K.
        """
        X, Y = self.X, self._codes()
        absent = self._ABSENT if self._outcomes else 0.0  # a face gone at a neighbour: unstable, or its own class
        f = self.n_free
        thetas, inv = np.unique(X[:, :f], axis=0, return_inverse=True)
        inv = inv.reshape(-1)
        order = np.argsort(inv, kind="stable")
        counts = np.bincount(inv, minlength=len(thetas))
        slot = np.arange(len(X)) - np.repeat(np.cumsum(counts) - counts, counts)
        body = self.embed(X)[:, 2 * f :]
        faces = np.full((len(thetas), counts.max(), body.shape[1]), np.inf)
        labels = np.zeros((len(thetas), counts.max()))
        faces[inv[order], slot] = body[order]
        labels[inv[order], slot] = Y[order]
        k = min(max(2 * f, 2), len(thetas))
        emb = self.embed(candidates)
        tree = cKDTree(angular_embedding(thetas, self.bounds[:f]))
        dist, nbr = tree.query(emb[:, : 2 * f], k=k, workers=query_workers(len(candidates)))
        dist, nbr = dist.reshape(len(candidates), k), nbr.reshape(len(candidates), k)
        if self._face_ids and cand_ids is not None:  # follow the face by name; absent counts as unstable
            first = np.unique(inv, return_index=True)[1]  # one told state per θ names every face of its hull
            hull_ids = np.concatenate([self._face_ids[i] for i in first])
            owner = np.repeat(np.arange(len(thetas)), [len(self._face_ids[i]) for i in first])
            _, rank = np.unique(np.concatenate([np.asarray(self._ids), hull_ids, cand_ids]), return_inverse=True)
            rank = rank.reshape(-1).astype(np.int64)
            n_id = rank.max() + 1
            key = inv.astype(np.int64) * n_id + rank[: len(X)]
            o = np.argsort(key)
            want = nbr.astype(np.int64) * n_id + rank[len(X) + len(hull_ids) :][:, None]
            at = np.clip(np.searchsorted(key[o], want), 0, len(key) - 1)
            found = key[o][at] == want
            lab = np.where(found, Y[o][at], absent)
            # where the face exists but was not labelled (a single-face query of another face there) it is not
            # gone: it reads as the face at the nearest joint state that labelled it (as Algorithm 8's extra states)
            unlabelled = ~found & np.isin(want, owner * n_id + rank[len(X) : len(X) + len(hull_ids)])
            if unlabelled.any():
                r, c = np.nonzero(unlabelled)
                slot = 4.0 * np.sqrt(f)  # farther than any two joint states: the nearest is of the same face
                P = separate(
                    angular_embedding(np.concatenate([X[:, :f], thetas[nbr[r, c]]]), self.bounds[:f]),
                    np.concatenate([self._ids, np.asarray(cand_ids)[r]]),
                    slot,
                )
                d, nn = cKDTree(P[: len(X)]).query(P[len(X) :], k=1)
                said = np.argmax(~unlabelled[r], axis=1)  # a face never labelled: the nearest neighbour that said
                lab[r, c] = np.where(d <= slot / 2, Y[nn], lab[r, said])
        else:
            gap = np.linalg.norm(faces[nbr] - emb[:, None, None, 2 * f :], axis=-1)  # (p, k, faces)
            gap = np.where(np.isfinite(gap), gap, np.inf)
            lab = np.take_along_axis(labels[nbr], gap.argmin(axis=2)[..., None], axis=2)[..., 0]
        sigma = self._spread(lab)
        volume = dist.max(axis=1)
        return self.alpha * sigma / 0.25 + self.beta * volume, sigma, volume

    def _hull_candidates(self, m_theta: int, rng: np.random.Generator):
        """Algorithm 7's uniform random θ, plus as many told θ jittered by their own spacing.

        Uniform candidates alone almost never land inside a sub-degree boundary interval;
        the jittered ones do, at every scale the data already has.  Returns the candidates,
        their groups (one per θ) and identities, as :meth:`_on_nearest_faces` does.
        """
        tree = self._free_tree()
        cand, groups, ids = self._candidates(m_theta, rng, tree)
        f = self.n_free
        thetas = np.unique(self.X[:, :f], axis=0)
        q = min(int(groups.max()) + 1, len(thetas))
        pick = rng.choice(len(thetas), q, replace=False)
        E = angular_embedding(thetas, self.bounds[:f])
        d, _ = cKDTree(E).query(E[pick], k=2)
        scale = d[:, 1:2] / np.ptp(self.bounds[:f], axis=1)  # chord ≈ radians → unit-cube units
        local = thetas[pick] + rng.normal(size=(q, f)) * scale
        periodic = full_turn(self.bounds[:f, 0], self.bounds[:f, 1])
        local = np.where(periodic, np.mod(local, 1.0), np.clip(local, 0.0, 1.0))
        extra, extra_groups, extra_ids = self._on_nearest_faces(local, tree)
        return (
            np.concatenate([cand, extra]),
            np.concatenate([groups, groups.max() + 1 + extra_groups]),
            None if ids is None else np.concatenate([ids, extra_ids]),
        )

    def _ask_hulls(self, n: int, rng: np.random.Generator) -> np.ndarray:
        """Whole-hull batch: distinct free states ranked by their best live face; each returned with that face."""
        m_theta = self._hull_count(n)
        cand, groups, cand_ids = self._hull_candidates(m_theta, rng)
        info, sigma, volume = self.hull_information(cand, cand_ids)
        live = ~(((sigma == 0) & (volume < self.r_max)) | ((sigma > 0) & (volume < self.r_min)))
        info = np.where(live, info, -np.inf)
        order = np.lexsort((-info, groups))  # per group, its best face first
        first = order[np.r_[True, groups[order][1:] != groups[order][:-1]]]
        first = first[np.isfinite(info[first])]
        if not len(first):  # nothing live: the search is finished
            return np.empty((0, self.dim))
        rep = cand[first]
        m = min(m_theta, len(rep))
        free = self.embed(rep)[:, : 2 * self.n_free] if self.n_free else self.embed(rep)
        idx = select_batch(rep, info[first], m, self.separation * volume[first], free)
        self.last_information = info[first][idx]
        return rep[idx]


#: A labelled batch as :meth:`ManifoldSampler.tell` takes it (``tell(*answer)``):
#: ``(states, labels, faces[, ids, face_ids[, outcomes]])``.
Answer = (
    tuple[np.ndarray, np.ndarray, Sequence[np.ndarray]]
    | tuple[np.ndarray, np.ndarray, Sequence[np.ndarray], np.ndarray | None, Sequence[np.ndarray] | None]
    | tuple[
        np.ndarray, np.ndarray, Sequence[np.ndarray], np.ndarray | None, Sequence[np.ndarray] | None, np.ndarray | None
    ]
)


def manifold_search(
    fn: Callable[[np.ndarray], Answer],
    sampler: ManifoldSampler,
    budget: int,
    batch_size: int = 50,
    progress: Callable[[int, int], None] | None = None,
) -> ManifoldSampler:
    """Algorithm 6's loop: ask, evaluate, tell, until ``budget`` evaluations or the cut-offs end it.

    ``fn(queries) -> (used_states, labels, faces[, ids, face_ids[, outcomes]])`` evaluates
    unit-cube queries and returns the states actually used (after projection), their 0/1
    labels, valid constrained values and, optionally, manifold identities and where each
    unstable state ends up (see :meth:`ManifoldSampler.tell`).
    """
    if budget < 1 or batch_size < 1:
        raise InputError(f"budget, batch_size: expected positive integers, got {budget}, {batch_size}")
    while sampler.n_told < budget and not sampler.done:
        q = sampler.ask(min(batch_size, budget - sampler.n_told))
        if not len(q):
            break
        out = fn(q)
        sampler.tell(*out)
        if progress is not None:
            progress(sampler.n_told, budget)
    return sampler
