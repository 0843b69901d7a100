"""Shared fixtures. Tests that need ../shared/data find it through NEOSLAM_DATA (default ../shared/data from the
repository root) and skip when it is absent, unless NEOSLAM_REQUIRE_DATA=1 (CI), where they fail instead."""

from __future__ import annotations

import importlib
import os
from pathlib import Path
from types import ModuleType

import pytest

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
