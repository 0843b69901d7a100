"""The public Python API: `neoslam` exposes NeoSLAM, Frame, ObjectObservation and the configuration; the API page's
example (docs/api_example.py, shown in docs/api.md and run here so that it cannot rot) drives NeoSLAM frame by frame;
`run` calls an observer after every step."""

from __future__ import annotations

import re
import runpy
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

import neoslam
from neoslam.config import NeoSLAMConfig
from neoslam.pipeline import run
from neoslam.types import Frame

REPO = Path(__file__).resolve().parents[1]
EXAMPLE = REPO / "docs" / "api_example.py"
API_PAGE = REPO / "docs" / "api.md"


def test_the_public_names() -> None:
    from neoslam import Frame, NeoSLAM, NeoSLAMConfig, ObjectObservation, load_config  # noqa: F401

    for name in neoslam.__all__:
        assert getattr(neoslam, name) is not None, name
    assert isinstance(load_config(environ={}), NeoSLAMConfig)
    with pytest.raises(AttributeError):
        neoslam.not_a_name  # noqa: B018


def test_importing_neoslam_stays_light() -> None:
    """The names load on first use: `import neoslam` (and with it the CLI's start) does not load torch or GTSAM."""
    code = "import sys, neoslam; print(sorted(m for m in ('torch', 'gtsam') if m in sys.modules))"
    done = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=120, check=True)
    assert done.stdout.strip() == "[]"


@pytest.mark.slow
def test_the_api_example_runs(capsys: pytest.CaptureFixture[str]) -> None:
    runpy.run_path(str(EXAMPLE), run_name="__main__")
    printed = capsys.readouterr().out
    found = re.search(r"(\d+) keyframes, (\d+) objects, (\d+) closures", printed)
    assert found, printed
    keyframes, objects, _ = (int(v) for v in found.groups())
    assert keyframes > 0 and objects > 0
    assert "last corrected position (m): [149.   0.   0.]" in printed  # 150 frames at 1 m, no drift to correct


def test_the_api_page_shows_the_example() -> None:
    code = EXAMPLE.read_text().split('"""', 2)[2].strip()  # the example without its docstring
    assert code in API_PAGE.read_text(), "docs/api.md's example differs from docs/api_example.py"


def test_run_calls_the_observer_after_each_step() -> None:
    seen: list[tuple[int, np.ndarray]] = []
    frames = []
    for index in range(5):
        pose = np.eye(4)
        pose[0, 3] = float(index)
        frames.append(Frame(index, 0.1 * index, pose, np.array([10.0, 0, 0]), np.zeros(3)))
    result = run(iter(frames), NeoSLAMConfig(), progress=False, on_step=lambda slam, f, p: seen.append((f.index, p)))
    assert [index for index, _ in seen] == list(range(5))
    np.testing.assert_array_equal(np.array([p for _, p in seen]), result.online_estimate.poses)
