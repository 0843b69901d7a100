"""Moving objects through the whole pipeline: a street of parked cars with traffic in both lanes; the traffic
joins no keyframe and no map object, and objects.csv lists it with moving = 1."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from neoslam.config import NeoSLAMConfig
from neoslam.geometry import invert_pose, robot_points_to_camera, transform_points
from neoslam.io.results import OBJECT_COLUMNS, write_objects
from neoslam.io.tables import read_table
from neoslam.pipeline import RunResult, run
from neoslam.types import Frame, ObjectObservation

pytestmark = pytest.mark.slow  # every test here runs whole drives, real images or real bags

PERIOD, SPEED, FRAMES = 0.1, 10.0, 400
FX, BASELINE, DISPARITY_SIGMA = 707.0912, 0.5372, 0.3
PARKED = [(x, side * 5.0) for x in np.arange(0.0, 480.0, 8.0) for side in (-1, 1)]
# Traffic in the two lanes (1.8 m either side of the robot's): oncoming cars and cars driving ahead, slower.
TRAFFIC = [((60.0 + 70.0 * k, -1.8), (-8.0, 0.0)) for k in range(6)] + [
    ((15.0 + 90.0 * k, 1.8), (6.0, 0.0)) for k in range(4)
]
LANES = 3.0  # |y| below this is the road, where only traffic drives


def _view(pose: np.ndarray, point: np.ndarray, rng: np.random.Generator) -> ObjectObservation | None:
    """The stereo camera's observation of a car at a world point: within 3-45 m and 35 degrees of the axis."""
    centre = robot_points_to_camera(transform_points(invert_pose(pose), point[None]))[0]
    if not 3.0 < centre[2] < 45.0 or abs(centre[0]) > 0.7 * centre[2]:
        return None
    depth = FX * BASELINE / (FX * BASELINE / centre[2] + rng.normal(0.0, DISPARITY_SIGMA))
    noisy = centre * depth / centre[2]
    box = np.array([10.0, 10.0, 40.0, 40.0])
    patch = np.full((16, 16), int(point[0] * 7) % 256, np.uint8)  # parked cars look apart
    return ObjectObservation("car", 0.9, box, box, noisy, patch)


def _street() -> list[Frame]:
    rng = np.random.default_rng(5)
    frames = []
    for i in range(FRAMES):
        t = i * PERIOD
        pose = np.eye(4)
        pose[0, 3] = SPEED * t
        points = [np.array([x, y, 0.0]) for x, y in PARKED]
        points += [np.array([x + vx * t, y + vy * t, 0.0]) for (x, y), (vx, vy) in TRAFFIC]
        views = tuple(v for v in (_view(pose, p, rng) for p in points) if v is not None)
        frames.append(Frame(i, t, pose, np.array([SPEED, 0.0, 0.0]), np.zeros(3), views))
    return frames


def _run(enabled: bool) -> RunResult:
    config = NeoSLAMConfig.model_validate({"moving_objects": {"enabled": enabled}})
    return run(_street(), config, progress=False)


@pytest.fixture(scope="module")
def _runs(keep):
    return keep({enabled: _run(enabled) for enabled in (True, False)})


@pytest.fixture
def runs(_runs) -> dict[bool, RunResult]:
    """The street run with the motion detector on (True) and off (False); copies for this test."""
    return _runs.copy()


def test_keyframes_and_the_map_leave_the_traffic_out(runs: dict[bool, RunResult]) -> None:
    on, off = runs[True], runs[False]
    assert len(on.keyframes) > 20
    on_road = [np.abs(k.centers[:, 1]) < LANES for k in on.keyframes]
    assert not np.concatenate(on_road).any()
    # Without the detector the traffic gets into keyframes and the map: the test has something to catch.
    assert np.concatenate([np.abs(k.centers[:, 1]) < LANES for k in off.keyframes]).any()
    # The map keeps the few views of a car let through before it was found moving (the keyframe window gives them
    # back; the object map does not yet): far fewer objects on the road than without the detector.
    on_road, off_road = (sum(abs(o.position[1]) < LANES for o in run.objects) for run in (on, off))
    assert on_road < off_road / 2


def test_the_traffic_is_reported_moving(runs: dict[bool, RunResult]) -> None:
    on = runs[True]
    assert len(on.moving_objects) >= len(TRAFFIC) // 2
    assert all(abs(o.position[1]) < LANES for o in on.moving_objects)
    assert on.moving_observations > 0 and runs[False].moving_objects == []
    assert runs[False].moving_observations == 0


def test_objects_csv_has_the_moving_column(runs: dict[bool, RunResult], tmp_path: Path) -> None:
    on = runs[True]
    write_objects(tmp_path / "objects.csv", on.objects, on.moving_objects)
    rows = read_table(tmp_path / "objects.csv", OBJECT_COLUMNS)
    assert OBJECT_COLUMNS[-1] == "moving"
    assert [row[-1] for row in rows.rows] == ["0"] * len(on.objects) + ["1"] * len(on.moving_objects)
    ids = [row[0] for row in rows.rows]
    assert len(set(ids)) == len(ids)  # an id names one row, static or moving


def test_same_street_same_result(runs: dict[bool, RunResult]) -> None:
    first, second = runs[True], _run(True)  # the first run was made for the other tests
    assert [o.position.tolist() for o in first.moving_objects] == [o.position.tolist() for o in second.moving_objects]
    assert [k.centers.tolist() for k in first.keyframes] == [k.centers.tolist() for k in second.keyframes]


def test_parked_cars_are_known_static_in_keyframes(runs: dict[bool, RunResult]) -> None:
    """With `unjudged: wait`, the parked cars' objects are known static by the time keyframes hold them, but for
    the far ones just come into view; without the detector nothing is provisional (nothing tells)."""
    provisional = np.concatenate([k.provisional for k in runs[True].keyframes])
    assert 0 < provisional.mean() < 0.2  # 0.08 on this street
    assert not np.concatenate([k.provisional for k in runs[False].keyframes]).any()
