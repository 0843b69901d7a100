"""The errors NeoSLAM raises for a user's mistake; the CLI turns each into one line and exit code 2."""

from __future__ import annotations

from pathlib import Path

__all__ = ["NeoSLAMError", "InputError", "ConfigError", "OutputError", "GoalError", "NoRouteError"]


class NeoSLAMError(Exception):
    """Base class: a problem the user can fix, reported as one line without a traceback."""


class InputError(NeoSLAMError):
    """A malformed, missing or inconsistent input file or folder."""

    def __init__(self, path: str | Path, problem: str, line: int | None = None) -> None:
        self.path = Path(path)
        self.problem = problem
        self.line = line
        where = f"{self.path}:{line}" if line is not None else f"{self.path}"
        super().__init__(f"{where}: {problem}")


class ConfigError(NeoSLAMError):
    """An invalid configuration value or file."""


class OutputError(NeoSLAMError):
    """The results folder cannot be written (for example it exists and is not empty)."""


class GoalError(NeoSLAMError):
    """A navigation goal that cannot be read, names nothing in the map, or names more than one place."""


class NoRouteError(GoalError):
    """No route on the map's links joins the start to the goal (they lie in parts of the map never linked)."""
