"""Shared fixtures. Tests that need ../shared/data find it through NEOSLAM_DATA (default ../shared/data from the
repository root) and skip when it is absent, unless NEOSLAM_REQUIRE_DATA=1 (CI), where they fail instead."""

from __future__ import annotations

import os
from pathlib import Path

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
