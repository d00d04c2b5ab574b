"""The errors RAPT raises on purpose: what a caller can catch, and what the message says."""

import numpy as np
import pytest

import rapt
import rapt.errors
from rapt.errors import FileFormatError, InputError, RaptError, RunError, StudyMismatchError
from rapt.store import StudyStore
from sim.robots.model import RobotFileError
from sim.robots.robotfile import load_robot

# (the class, the built-in exception that code written before the hierarchy caught)
BUILT_IN_BASES = [
    (InputError, ValueError),
    (FileFormatError, ValueError),
    (StudyMismatchError, ValueError),
    (RunError, RuntimeError),
    (rapt.errors.LinkError, ConnectionError),
    (rapt.errors.LinkTimeoutError, TimeoutError),
    (rapt.errors.MissingFileError, FileNotFoundError),
    (rapt.errors.MissingFileError, ValueError),  # also a FileFormatError
    (rapt.errors.RefusedError, PermissionError),
]


@pytest.mark.parametrize("cls, builtin", BUILT_IN_BASES, ids=lambda c: c.__name__)
def test_every_error_is_a_rapt_error_and_keeps_its_built_in_base(cls, builtin):
    assert issubclass(cls, RaptError) and issubclass(cls, builtin)
    assert getattr(rapt, cls.__name__) is cls  # exported from the package, as the public API is


def _one_line(exc: BaseException) -> str:
    text = str(exc)
    assert text and "\n" not in text
    return text


@pytest.mark.parametrize(
    "call, field",
    [
        (lambda: rapt.StateSpace.from_bounds([(0, 1), (2, 1)]), "bounds"),
        (lambda: rapt.Continuous("depth", 5.0, 1.0), "parameter 'depth'"),
        (
            lambda: rapt.boundary_pairs(
                np.random.default_rng(0).random((20, 2)), np.arange(20.0)[:, None] % 2, d_eps=0.0
            ),
            "d_eps",
        ),
        (lambda: rapt.performance_modes(np.zeros((4, 1)), bandwidth=-1.0), "bandwidth"),
    ],
    ids=["from_bounds", "Continuous", "boundary_pairs", "performance_modes"],
)
def test_a_bad_argument_is_an_input_error_naming_the_field(call, field):
    with pytest.raises(InputError) as info:
        call()
    assert isinstance(info.value, ValueError)  # `except ValueError` callers still catch it
    assert _one_line(info.value).startswith(field)


def test_a_bad_robot_file_is_a_robot_file_error_and_a_rapt_error(tmp_path):
    path = tmp_path / "bad.toml"
    path.write_text('name = "bad"\n[[link]]\nname = "body"\nmass = -1.0\nboxes = [{ size = [0.6, 0.4, 0.2] }]\n')
    with pytest.raises(RobotFileError) as info:
        load_robot(path)
    assert isinstance(info.value, FileFormatError) and isinstance(info.value, RaptError)
    assert isinstance(info.value, ValueError)
    assert _one_line(info.value).startswith("link[0].mass: expected a number >= 0")


def test_a_file_that_is_not_a_study_database_is_a_file_format_error(tmp_path):
    path = tmp_path / "notes.db"
    path.write_text("these are not the droids you are looking for\n" * 100)
    with pytest.raises(FileFormatError, match=r"^store: .*notes\.db is not a RAPT study database"):
        StudyStore(path)
    with pytest.raises(InputError, match="is a directory; give a file path"):
        StudyStore(tmp_path)


def test_a_closed_store_refuses_to_be_used():
    store = StudyStore(":memory:")
    store.set_meta({"dim": 2})
    store.close()
    store.close()  # closing twice is harmless
    with pytest.raises(RunError, match="is closed"):
        store.get_meta()


def test_a_store_of_another_space_is_a_study_mismatch(tmp_path):
    def fn(X):
        return (X[:, :1] > 0.5).astype(float)

    db = tmp_path / "study.db"
    rapt.search(fn, [(0, 1), (0, 1)], budget=20, method="random", batch_size=10, seed=1, store=db)
    with pytest.raises(StudyMismatchError, match=r"^store: .* holds a study with .*use a new store path$"):
        rapt.search(fn, [(0, 2), (0, 1)], budget=20, method="random", batch_size=10, seed=1, store=db)
