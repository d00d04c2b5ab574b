"""RAPT's algorithm library: adaptive search for performance boundaries.

Knows nothing of vehicles or MAVLink: a system under test is any function from an
(n, d) array of scenario states to an (n, m) array of scores.

>>> import numpy as np, rapt
>>> study = rapt.search(lambda X: (X[:, :1] > 0.5).astype(float), [(0, 1), (0, 1)], budget=200, seed=1)
>>> study.X.shape, study.Y.shape
((200, 2), (200, 1))
"""

from rapt.boundaries import BoundaryPairs, boundary_pairs
from rapt.errors import (
    FileFormatError,
    InputError,
    LinkError,
    LinkTimeoutError,
    MissingFileError,
    RaptError,
    RefusedError,
    RunError,
    StudyMismatchError,
)
from rapt.modes import performance_modes
from rapt.samplers import METHODS, make_sampler
from rapt.scoretree import ScoreTree
from rapt.search import Study, search
from rapt.space import Categorical, Continuous, Integer, Permutation, StateSpace
from rapt.subboundaries import SubBoundaryTree, subboundary_tree

__all__ = [
    "search",
    "Study",
    "StateSpace",
    "Continuous",
    "Integer",
    "Categorical",
    "Permutation",
    "METHODS",
    "make_sampler",
    "performance_modes",
    "boundary_pairs",
    "BoundaryPairs",
    "ScoreTree",
    "subboundary_tree",
    "SubBoundaryTree",
    "RaptError",
    "InputError",
    "FileFormatError",
    "MissingFileError",
    "StudyMismatchError",
    "RunError",
    "LinkError",
    "LinkTimeoutError",
    "RefusedError",
]

__version__ = "0.1.0"
