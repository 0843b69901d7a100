"""Shared fixtures. Tests that need ../shared/data find it through NEOSLAM_DATA (default ../shared/data from the
repository root) and skip when it is absent, unless NEOSLAM_REQUIRE_DATA=1 (CI), where they fail instead. `cli` runs
the `neoslam` command in-process. The simulated drives that several system tests read (a whole drive and its run take
seconds) are made once per session: see "Shared drives" below."""

from __future__ import annotations

import importlib
import os
import pickle
from dataclasses import dataclass
from pathlib import Path
from types import ModuleType
from typing import TYPE_CHECKING, Generic, TypeVar

import pytest

if TYPE_CHECKING:
    from typer.testing import Result

    from neoslam.pipeline import RunResult
    from neoslam.sim.session_drives import SessionRecording
    from neoslam.types import MapState

T = TypeVar("T")

REPO_ROOT = Path(__file__).resolve().parents[1]


def pytest_configure(config: pytest.Config) -> None:
    # The networks the tests train are tiny (the object-vector cells: one hidden layer of 32 units, batches of 32),
    # where torch's worker threads only add synchronisation; on a 2-core machine that is busy with other work they
    # spin against each other instead (the 400-epoch fit of tests/cells/test_object_vector.py, measured under load:
    # 4.5 s on one thread, 60-120 s on two). The results are the same either way.
    import torch

    torch.set_num_threads(1)


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


# ------------------------------------------------------------------------------------------------- Shared drives
# A drive made once per session and read by several tests. A run's result is kept pickled and every test gets its own
# copy (`Kept.copy`, a few milliseconds against seconds for the run), so a test that changed what it read could not
# change what the next test reads, whatever the order the tests run in.


class Kept(Generic[T]):
    """A value kept as its pickle: each `copy()` is a new, equal value."""

    def __init__(self, value: T) -> None:
        self._pickled = pickle.dumps(value)

    def copy(self) -> T:
        return pickle.loads(self._pickled)


@pytest.fixture(scope="session")
def keep() -> type[Kept]:
    """`keep(value)`: a Kept, for a module's own fixture whose value several tests read (`.copy()` for each)."""
    return Kept


@pytest.fixture(scope="session")
def block_seed5(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """The route "block" simulated with the default simulator and seed 5, as a dataset folder (read-only: a test
    that changes a dataset copies it first)."""
    from neoslam.config import SimulatorConfig
    from neoslam.datasets.simulated import write_dataset
    from neoslam.sim.simulator import simulate_route

    folder = tmp_path_factory.mktemp("block_seed5") / "data"
    write_dataset(folder, simulate_route("block", SimulatorConfig(seed=5)))
    return folder


@pytest.fixture(scope="session")
def _block_seed5_run(block_seed5: Path) -> Kept[RunResult]:
    from neoslam.config import NeoSLAMConfig
    from neoslam.datasets.simulated import read_dataset
    from neoslam.pipeline import run

    dataset = read_dataset(block_seed5)
    return Kept(run(dataset.frames(), NeoSLAMConfig(), total=len(dataset), progress=False))


@pytest.fixture
def block_seed5_run(_block_seed5_run: Kept[RunResult]) -> RunResult:
    """`pipeline.run` over block_seed5 with the default NeoSLAMConfig (a copy of its result for this test)."""
    return _block_seed5_run.copy()


@dataclass(frozen=True)
class TownSessions:
    """The route "town" driven as two sessions in one world: A, frames 0-1800 (noise seed 3), and B, from frame 1300
    to the end (noise seed 4), each in its own frame with vo odometry; `folders` holds each written as a dataset."""

    sessions: tuple[SessionRecording, SessionRecording]
    folders: tuple[Path, Path]


@pytest.fixture(scope="session")
def _town_sessions(tmp_path_factory: pytest.TempPathFactory) -> Kept[TownSessions]:
    from neoslam.config import NeoSLAMConfig
    from neoslam.config.profiles import simulation_config
    from neoslam.datasets.simulated import write_dataset
    from neoslam.sim.routes import ROUTES, drive_route
    from neoslam.sim.session_drives import session_recordings

    sim = simulation_config(NeoSLAMConfig(), "vo", 3).simulator
    truth = drive_route(ROUTES["town"], sim.frame_period, sim.camera.height_above_ground)
    a, b = session_recordings(truth, [(0, 1800), (1300, len(truth))], sim, [3, 4], "town")
    root = tmp_path_factory.mktemp("town_sessions")
    for session, name in ((a, "a"), (b, "b")):
        write_dataset(root / name, session.recording)
    return Kept(TownSessions((a, b), (root / "a", root / "b")))


@pytest.fixture
def town_sessions(_town_sessions: Kept[TownSessions]) -> TownSessions:
    """The two town sessions (a copy for this test; the dataset folders are shared and read-only)."""
    return _town_sessions.copy()


def drive_session(folder: Path, config, stored: MapState | None, name: str) -> tuple[MapState, RunResult]:
    """A session's dataset folder driven with NeoSLAM, after the `stored` map if given: the map (as it is once the
    result is made: the result finishes the map) and the result."""
    import numpy as np

    from neoslam.datasets.simulated import read_dataset
    from neoslam.pipeline import NeoSLAM

    slam = NeoSLAM(config, stored, name)
    for frame in read_dataset(folder).frames():
        slam.step(frame)
    result = slam.result(np.zeros(0))
    return slam.map_state(), result


@pytest.fixture(scope="session")
def _town_session_a(_town_sessions: Kept[TownSessions]) -> Kept[tuple[MapState, RunResult]]:
    from neoslam.config import NeoSLAMConfig

    sessions = _town_sessions.copy()
    return Kept(drive_session(sessions.folders[0], NeoSLAMConfig(), None, sessions.sessions[0].recording.name))


@pytest.fixture
def town_session_a(_town_session_a: Kept[tuple[MapState, RunResult]]) -> tuple[MapState, RunResult]:
    """Town session A driven alone with the default NeoSLAMConfig: its map and its result (copies for this test)."""
    return _town_session_a.copy()


@pytest.fixture(scope="session")
def session_driver():
    """`session_driver(folder, config, stored, name)`: a session driven over a stored map (see `drive_session`)."""
    return drive_session
