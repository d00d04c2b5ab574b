"""The errors RAPT raises on purpose, so a caller can catch what it means.

Every message is one line that names the field (or file) at fault and how to fix it; the
command line prints it as it is and exits non-zero.  Each class also derives from the
built-in exception of its kind (``ValueError`` for bad input, ``RuntimeError`` for a run
that cannot go on, ``TimeoutError``, ``ConnectionError``, ``FileNotFoundError`` for a
missing file, ``PermissionError`` for a refusal), so a generic handler such as
``except ValueError`` keeps catching what it means.

The packages built on :mod:`rapt` subclass these for their own inputs (mission files,
robot files, flight logs, the vehicle link).
"""

from __future__ import annotations

__all__ = [
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


class RaptError(Exception):
    """Base of every error RAPT raises on purpose; its message is one line naming the field and the fix."""


class InputError(RaptError, ValueError):
    """An argument, setting or parameter that cannot be used as given."""


class FileFormatError(InputError):
    """A file (mission, robot, plan, log, key) that cannot be read; the message names the file and the field."""


class MissingFileError(FileFormatError, FileNotFoundError):
    """A file given by its path that does not exist; also a ``FileNotFoundError``, as it was raised before."""


class StudyMismatchError(RaptError, ValueError):
    """A stored study that does not belong to the run asked for (another space, system or mission)."""


class RunError(RaptError, RuntimeError):
    """A study, simulation or flight that cannot go on (a sampler broke its contract, a process did not start)."""


class LinkError(RaptError, ConnectionError):
    """The vehicle or the bus cannot be reached, or stopped answering."""


class LinkTimeoutError(RaptError, TimeoutError):
    """Something awaited from the vehicle or the bus did not come in time."""


class RefusedError(RaptError, PermissionError):
    """An action the configuration does not allow (a command to a vehicle while commands are off)."""
