"""Built-in routes: length, height, revisits (same and opposite direction) and a drivable speed profile."""

from __future__ import annotations

import numpy as np
import pytest
from scipy.spatial import cKDTree

from neoslam.config import SimulatorConfig
from neoslam.geometry import is_rotation_matrix, yaw_of
from neoslam.sim.routes import CRUISE_SPEED, ROUTES, Route, drive_route, route_names
from neoslam.types import Trajectory

PERIOD = SimulatorConfig().frame_period
HEIGHT = SimulatorConfig().camera.height_above_ground
REVISIT_RADIUS_M = 3.0
MIN_FRAME_GAP = 100


@pytest.fixture(scope="module")
def town() -> Trajectory:
    return drive_route(ROUTES["town"], PERIOD, HEIGHT)


@pytest.fixture(scope="module")
def block() -> Trajectory:
    return drive_route(ROUTES["block"], PERIOD, HEIGHT)


def _revisit_heading_differences(truth: Trajectory) -> list[float]:
    """Per frame that comes back within REVISIT_RADIUS_M of a place passed >= MIN_FRAME_GAP frames earlier:
    the smallest heading difference (degrees) to those earlier frames, and the largest, as (min, max)."""
    xy = truth.positions[:, :2]
    yaw = yaw_of(truth.poses)
    tree = cKDTree(xy)
    result = []
    for i in range(len(xy)):
        earlier = [j for j in tree.query_ball_point(xy[i], REVISIT_RADIUS_M) if j <= i - MIN_FRAME_GAP]
        if earlier:
            difference = np.degrees(np.abs(np.angle(np.exp(1j * (yaw[i] - yaw[earlier])))))
            result.append((difference.min(), difference.max()))
    return result


def test_route_names() -> None:
    assert route_names() == sorted(ROUTES) and {"town", "block"} <= set(ROUTES)


def test_town_is_two_to_three_km_with_a_hill(town: Trajectory) -> None:
    assert 2000.0 <= town.path_length() <= 3000.0
    assert np.ptp(town.positions[:, 2]) > 5.0


def test_town_revisits_in_both_directions(town: Trajectory) -> None:
    revisits = _revisit_heading_differences(town)
    opposite = sum(1 for _, largest in revisits if largest > 150.0)
    same = sum(1 for smallest, _ in revisits if smallest < 30.0)
    assert opposite >= 50, "no street driven again in the opposite direction"
    assert same >= 50, "no street driven again in the same direction"


def test_block_is_short(block: Trajectory) -> None:
    assert len(block) == 816
    assert 500.0 <= block.path_length() <= 700.0
    assert len(_revisit_heading_differences(block)) > 0  # driven once and a half: it comes back


@pytest.mark.parametrize("name", sorted(ROUTES))
def test_route_is_a_valid_drive(name: str) -> None:
    route = ROUTES[name]
    truth = drive_route(route, PERIOD, HEIGHT)
    np.testing.assert_allclose(np.diff(truth.timestamps), PERIOD, atol=1e-9)
    assert truth.timestamps[0] == 0.0
    assert all(is_rotation_matrix(pose[:3, :3], 1e-9) for pose in truth.poses)
    np.testing.assert_allclose(truth.positions[0, :2], route.corners[0], atol=1e-9)
    speed = np.linalg.norm(np.diff(truth.positions, axis=0), axis=1) / PERIOD
    assert speed.max() <= CRUISE_SPEED * 1.01
    assert speed.min() > 0.5
    # the camera rides at its height above the road surface on every pass
    ground = route.ground_height(truth.positions[:, :2])
    np.testing.assert_allclose(truth.positions[:, 2] - ground, HEIGHT, atol=1e-6)
    # the robot looks where it drives (x forward) and has no roll
    motion = np.diff(truth.positions[:, :2], axis=0)
    heading = np.arctan2(motion[:, 1], motion[:, 0])
    difference = np.degrees(np.abs(np.angle(np.exp(1j * (heading - yaw_of(truth.poses[:-1]))))))
    assert np.median(difference) < 2.0
    assert np.abs(truth.poses[:, 2, 1]).max() < 1e-9  # z row has no y component: zero roll


def test_climbing_is_a_nose_up_pitch(town: Trajectory) -> None:
    climbing = np.diff(town.positions[:, 2]) > 0.05
    forward_up = town.poses[:-1, 2, 0]  # world z component of the robot's x axis
    assert np.all(forward_up[climbing] > 0)


def test_deterministic() -> None:
    a = drive_route(ROUTES["block"], PERIOD, HEIGHT)
    b = drive_route(ROUTES["block"], PERIOD, HEIGHT)
    np.testing.assert_array_equal(a.poses, b.poses)


def test_u_turn_is_refused() -> None:
    route = Route(name="u", description="", corners=((0, 0), (50, 0), (0, 1)))
    with pytest.raises(ValueError, match="U-turn"):
        drive_route(route, PERIOD, HEIGHT)
