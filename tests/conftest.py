"""Shared fixtures. Tests that need ../shared/data find it through NEOSLAM_DATA (default ../shared/data from the
repository root) and skip when it is absent, unless NEOSLAM_REQUIRE_DATA=1 (CI), where they fail instead. `cli` runs
the `neoslam` command in-process."""

from __future__ import annotations

import importlib
import os
from pathlib import Path
from types import ModuleType
from typing import TYPE_CHECKING

import pytest

if TYPE_CHECKING:
    from typer.testing import Result

REPO_ROOT = Path(__file__).resolve().parents[1]


def _data_root() -> Path:
    return Path(os.environ.get("NEOSLAM_DATA", REPO_ROOT.parent / "shared" / "data")).resolve()


@pytest.fixture(scope="session")
def shared_data() -> Path:
    """The shared data folder (KITTI poses, kitti_mini, models)."""
    root = _data_root()
    if not (root / "kitti" / "poses").is_dir():
        reason = f"shared data not found at {root} (set NEOSLAM_DATA)"
        if os.environ.get("NEOSLAM_REQUIRE_DATA") == "1":
            pytest.fail(reason)
        pytest.skip(reason)
    return root


@pytest.fixture(scope="session")
def kitti_poses(shared_data: Path):
    """Path of a ground-truth pose file: kitti_poses('05')."""

    def _path(sequence: str) -> Path:
        return shared_data / "kitti" / "poses" / f"{sequence}.txt"

    return _path


def require_extra(module: str, extra: str) -> ModuleType:
    """Import an optional extra's module, or skip with the command that installs it; under NEOSLAM_REQUIRE_EXTRAS=1
    (CI, which installs the extras) a missing extra fails instead."""
    try:
        return importlib.import_module(module)
    except ImportError:
        reason = f'{module} is not installed: it is the optional extra pip install "neoslam[{extra}]"'
        if os.environ.get("NEOSLAM_REQUIRE_EXTRAS") == "1":
            pytest.fail(reason)
        pytest.skip(reason)


@pytest.fixture(scope="session")
def extra():
    """`extra("rerun", "viewer")`: the module of an optional extra (see `require_extra`)."""
    return require_extra


class Cli:
    """The CLI run in-process: `invoke` gives typer's result, `ok` asserts a clean exit, `one_line_error` asserts the
    one-line refusal every bad input gets (exit 2, no traceback)."""

    def __init__(self) -> None:
        # imported here, not at the top: collecting a test that never runs the CLI need not import it
        from typer.testing import CliRunner

        from neoslam.cli import app

        self._runner, self._app = CliRunner(), app

    def invoke(self, *args: object, env: dict[str, str] | None = None) -> Result:
        return self._runner.invoke(self._app, [str(a) for a in args], env=env)

    def ok(self, *args: object, env: dict[str, str] | None = None) -> Result:
        result = self.invoke(*args, env=env)
        assert result.exit_code == 0, (result.output, result.exception)
        return result

    @staticmethod
    def one_line_error(result: Result, *parts: str) -> str:
        """The error line, after checking it is the only line on stderr, names every part and came with exit code 2."""
        assert "Traceback" not in result.output, result.output
        assert result.exit_code == 2, (result.exit_code, result.output, result.exception)
        assert isinstance(result.exception, SystemExit), result.exception
        lines = result.stderr.splitlines()
        assert len(lines) == 1 and lines[0].startswith("neoslam: error: "), result.stderr
        for part in parts:
            assert part in lines[0], (part, lines[0])
        return lines[0]


@pytest.fixture(scope="session")
def cli() -> Cli:
    """The `neoslam` command run in-process (session-wide, so module-scoped fixtures can run it too)."""
    return Cli()
