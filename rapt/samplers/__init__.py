"""Ask/tell samplers: space-filling baselines and adaptive boundary searches.

``make_sampler(method, dim, ...)`` builds one by the name :func:`rapt.search` takes.
"""

from __future__ import annotations

from rapt.errors import InputError
from rapt.samplers.adaptive import GPRSampler, InformationSampler, NNDVSampler, ScaledNDVSampler
from rapt.samplers.base import Sampler
from rapt.samplers.lola_voronoi import LolaVoronoiSampler
from rapt.samplers.space_filling import LatinHypercubeSampler, RandomSampler, SobolSampler

__all__ = [
    "Sampler",
    "RandomSampler",
    "SobolSampler",
    "LatinHypercubeSampler",
    "InformationSampler",
    "NNDVSampler",
    "ScaledNDVSampler",
    "GPRSampler",
    "LolaVoronoiSampler",
    "METHODS",
    "make_sampler",
]

#: ``method=`` names accepted by :func:`rapt.search`, in the order the paper introduces them.
METHODS: dict[str, type[Sampler]] = {
    "random": RandomSampler,
    "sobol": SobolSampler,
    "lhs": LatinHypercubeSampler,
    "gpr": GPRSampler,
    "nndv": NNDVSampler,
    "s-ndv": ScaledNDVSampler,
    "lola-voronoi": LolaVoronoiSampler,  # the dissertation's peer (Table 3.1)
}


def make_sampler(method: str, dim: int, *, seed: int = 0, **options) -> Sampler:
    """Build the sampler registered under ``method`` (one of :data:`METHODS`)."""
    if method not in METHODS:
        raise InputError(f"method: unknown method {method!r}; allowed: {', '.join(METHODS)}")
    cls = METHODS[method]
    try:
        return cls(dim, seed=seed, **options)
    except TypeError as exc:
        raise InputError(f"method {method!r}: {exc}") from None
