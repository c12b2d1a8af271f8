"""One exception root for every error a user can cause.

Every leaf also inherits the matching built-in type, so callers may catch either.
The CLI turns any :class:`TrafficsimError` into one line on stderr, with exit code 2 for an
:class:`InputError` and 1 for a :class:`SimulationError`.
"""

from __future__ import annotations


class TrafficsimError(Exception):
    """Root of all user-facing errors."""


class InputError(TrafficsimError, ValueError):
    """A user file or argument is wrong; the message names where and what was expected.

    Args:
        message: what is wrong and what was expected.
        path: the file (or command-line flag) at fault, if any.
        line: 1-based line in ``path``, if known.
        key: dotted key path inside the file, if known.
    """

    def __init__(self, message: str, path: str | None = None, line: int | None = None,
                 key: str | None = None) -> None:
        self.message = message
        self.path = path
        self.line = line
        self.key = key
        #: every error found in the file (``trafficsim validate`` prints them all)
        self.errors: list[InputError] = [self]
        super().__init__(self.render())

    def render(self) -> str:
        where = ""
        if self.path is not None:
            where = f"{self.path}:{self.line}: " if self.line is not None else f"{self.path}: "
        key = f"{self.key}: " if self.key else ""
        return f"{where}{key}{self.message}"


class ScenarioError(InputError):
    """A scenario, ship, campaign or rules file is invalid."""


class ShipLibraryError(InputError):
    """A ship name is unknown or a ship file is invalid."""


class DataError(InputError):
    """A trial-data file cannot be read."""


class SimulationError(TrafficsimError, RuntimeError):
    """The simulation diverged (non-finite state); the message names the ships and the step."""
