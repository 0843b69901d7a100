"""The Hebbian recall at a loop closure (local-view calibration, paper 3.5-3.6 and NeuroSLAM): it re-anchors the grid
and head-direction cells where the closure puts the robot, in the cells' own frame; each closure is checked against
the cells as the recalls before it left them; keyframes made before the OVCN learnt are associated once it has."""

from __future__ import annotations

import math

import numpy as np
import pytest

from neoslam.cells import circular_difference
from neoslam.config import NeoSLAMConfig
from neoslam.geometry import make_pose
from neoslam.pipeline import NeoSLAM
from neoslam.types import Keyframe, LoopClosure

# NeuroSLAM's order: every closure the detector accepts recalls its place (the default recalls only on accepted ones;
# the tests of that order name it).
CONFIG = NeoSLAMConfig.model_validate({"hebbian": {"recall_on": "detected"}})
CELL_M = CONFIG.grid_cells.metres_per_cell
STORED_CELL = np.array([10.0, 20.0, 18.0])  # the grid cells when the place was stored
STORED_HEADING_CELL = 9.0  # 90 degrees, in the cells' frame
DRIFTED_CELL = np.array([25.0, 5.0, 18.0])  # where path integration has them when the place is seen again
DRIFTED_HEADING_CELL = 27.0  # 270 degrees
# The closure's fit: the robot 12 m ahead of the stored keyframe and 6 m to its left, turned 25 degrees left.
TURN_DEG = 25.0
RELATIVE = make_pose(
    np.array(
        [
            [math.cos(math.radians(TURN_DEG)), -math.sin(math.radians(TURN_DEG)), 0.0],
            [math.sin(math.radians(TURN_DEG)), math.cos(math.radians(TURN_DEG)), 0.0],
            [0.0, 0.0, 1.0],
        ]
    ),
    np.array([12.0, 6.0, 0.0]),
)
# In the cells' frame the stored keyframe faces 90 degrees: ahead is +y, left is -x.
EXPECTED_CELL = STORED_CELL + np.array([-6.0, 12.0, 0.0]) / CELL_M  # (9.25, 21.5, 18)
EXPECTED_HEADING_CELL = STORED_HEADING_CELL + TURN_DEG / 10.0  # 11.5 cells = 115 degrees


def _yaw_pose(yaw_deg: float, translation) -> np.ndarray:
    c, s = math.cos(math.radians(yaw_deg)), math.sin(math.radians(yaw_deg))
    return make_pose(np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]]), np.asarray(translation, float))


def _keyframe(keyframe_id: int, pose: np.ndarray) -> Keyframe:
    """Four cars 8-12 m ahead of the robot (where the OVCN's field fires)."""
    ahead = np.array([[10.0, 2.0, 0.5], [9.0, -2.0, 0.5], [12.0, 1.0, 0.5], [8.0, 3.0, 0.5]])
    centres = ahead @ pose[:3, :3].T + pose[:3, 3]
    return Keyframe(keyframe_id, 10 * keyframe_id, pose, centres, ("car",) * 4, np.zeros((4, 16, 16), np.uint8))


def _settle_at(slam: NeoSLAM, grid_cell: np.ndarray, heading_cell: float) -> None:
    slam.grid_cells.reset(grid_cell)
    slam.head_direction.reset(heading_cell)
    for _ in range(10):
        slam.grid_cells.step(0.0, 0.0, 0.0)
        slam.head_direction.step(0.0)


def _settle(slam: NeoSLAM, frames: int = 10) -> None:
    for _ in range(frames):
        slam.grid_cells.step(0.0, slam.head_direction.heading, 0.0)
        slam.head_direction.step(0.0)


def _slam_that_stored_a_place(config: NeoSLAMConfig = CONFIG) -> NeoSLAM:
    """Keyframe 0 stored with the cells at STORED_*, its odometry facing 60 degrees (the cells' frame and the
    odometry's differ, as after a drift and a recall); the cells have since drifted to DRIFTED_*."""
    slam = NeoSLAM(config)
    _settle_at(slam, STORED_CELL, STORED_HEADING_CELL)
    slam.hebbian.associate(0, 1.0, slam.grid_cells.activity, slam.head_direction.activity)
    slam.loop_detector.index.add(_keyframe(0, _yaw_pose(60.0, [100.0, 50.0, 0.0])), 0.0)
    _settle_at(slam, DRIFTED_CELL, DRIFTED_HEADING_CELL)
    return slam


def _closure(query: Keyframe, relative: np.ndarray = RELATIVE) -> LoopClosure:
    return LoopClosure(query.frame_index, 0, query.id, 0, 10.0, 4, relative)


def _assert_at(slam: NeoSLAM, grid_cell: np.ndarray, heading_cell: float, tolerance: float = 0.25) -> None:
    cells = slam.grid_cells.dims
    assert np.abs(circular_difference(slam.grid_cells.centre, grid_cell, cells)).max() < tolerance
    assert abs(float(circular_difference(slam.head_direction.centre, heading_cell, 36))) < tolerance


def _check_records(slam: NeoSLAM, monkeypatch, accept: bool) -> list[np.ndarray]:
    """Replace the experience map's check by one that accepts or rejects every closure and records the grid-cell
    state each closure was checked against; the current keyframe is not stored (not needed here)."""
    seen: list[np.ndarray] = []

    def check(closure, cells) -> bool:
        seen.append(cells.grid.copy())
        return accept

    monkeypatch.setattr(slam.experience_map, "close_loop", check)
    monkeypatch.setattr(slam.loop_detector, "add", lambda keyframe, odometer: None)
    return seen


@pytest.mark.parametrize("accept", [True, False])
def test_a_closure_re_anchors_the_cells_where_it_puts_the_robot(monkeypatch, accept: bool) -> None:
    slam = _slam_that_stored_a_place()
    _check_records(slam, monkeypatch, accept)
    query = _keyframe(1, _yaw_pose(-40.0, [300.0, -20.0, 0.0]))  # odometry: anywhere, the fit says where
    slam._close_loop(query, [_closure(query)], slam._cell_state(), None)
    _settle(slam)
    # Recalled at the stored cell state moved by the fit's offset and turn, in the cells' frame: not left where
    # path integration had the cells, not at the stored state itself, not turned by the odometry's heading there.
    _assert_at(slam, EXPECTED_CELL, EXPECTED_HEADING_CELL)
    assert len(slam.loop_closures) == int(accept) and len(slam.detected_closures) == 1


def test_a_closure_of_an_earlier_keyframe_recalls_the_place_where_the_robot_is_now(monkeypatch) -> None:
    """The detector confirms keyframe 1 when keyframe 2 relocalises too: the robot has moved on 5 m since."""
    slam = _slam_that_stored_a_place()
    _check_records(slam, monkeypatch, True)
    earlier = _keyframe(1, _yaw_pose(-40.0, [300.0, -20.0, 0.0]))
    slam._close_loop(earlier, [], slam._cell_state(), None)
    now = _keyframe(2, earlier.pose @ _yaw_pose(0.0, [5.0, 0.0, 0.0]))
    slam._close_loop(now, [_closure(earlier)], slam._cell_state(), None)
    _settle(slam)
    moved_on = RELATIVE[:2, :2] @ np.array([5.0, 0.0])  # 5 m along the robot's heading, stored keyframe's frame
    expected = EXPECTED_CELL + np.array([-moved_on[1], moved_on[0], 0.0]) / CELL_M  # turned to the cells' 90 deg
    _assert_at(slam, expected, EXPECTED_HEADING_CELL)


def test_each_closure_is_checked_against_the_cells_the_recalls_before_it_left(monkeypatch) -> None:
    """Two closures in one keyframe: the first is rejected (the cells have drifted 15 cells away), yet it recalls
    the place, so the second is checked against re-anchored cells (NeuroSLAM: a re-seen view calibrates the cells
    whatever the experience map does with it)."""
    slam = _slam_that_stored_a_place()
    seen = _check_records(slam, monkeypatch, False)
    earlier = _keyframe(1, _yaw_pose(-40.0, [300.0, -20.0, 0.0]))
    slam._close_loop(earlier, [], slam._cell_state(), None)
    now = _keyframe(2, earlier.pose)
    slam._close_loop(now, [_closure(earlier), _closure(now)], slam._cell_state(), None)
    dims = slam.grid_cells.dims
    assert np.abs(circular_difference(seen[0], DRIFTED_CELL, dims)).max() < 0.25
    assert np.abs(circular_difference(seen[1], EXPECTED_CELL, dims)).max() < 0.25


def test_with_the_papers_order_a_rejected_closure_recalls_nothing(monkeypatch) -> None:
    config = CONFIG.model_copy(update={"hebbian": CONFIG.hebbian.model_copy(update={"recall_on": "accepted"})})
    slam = _slam_that_stored_a_place(config)
    seen = _check_records(slam, monkeypatch, False)
    query = _keyframe(1, _yaw_pose(-40.0, [300.0, -20.0, 0.0]))
    slam._close_loop(query, [_closure(query), _closure(query)], slam._cell_state(), None)
    _settle(slam)
    _assert_at(slam, DRIFTED_CELL, DRIFTED_HEADING_CELL)
    assert len(seen) == 2 and np.abs(circular_difference(seen[1], DRIFTED_CELL, slam.grid_cells.dims)).max() < 0.25


def test_the_recall_energy_is_the_gain_times_the_cells_injection_energy(monkeypatch) -> None:
    """At the cells' own 0.1 (NeuroSLAM's energy per frame of a re-seen view) a recall 15 cells away dies out; as
    measured, such a recall changes no closure and no metre of the map."""
    weak = CONFIG.model_copy(update={"hebbian": CONFIG.hebbian.model_copy(update={"recall_gain": 1.0})})
    slam = _slam_that_stored_a_place(weak)
    _check_records(slam, monkeypatch, True)
    query = _keyframe(1, _yaw_pose(-40.0, [300.0, -20.0, 0.0]))
    slam._close_loop(query, [_closure(query)], slam._cell_state(), None)
    _settle(slam)
    _assert_at(slam, DRIFTED_CELL, DRIFTED_HEADING_CELL)


def test_keyframes_made_before_the_ovcn_learnt_are_associated_once_it_has() -> None:
    slam = NeoSLAM(CONFIG)
    _settle_at(slam, STORED_CELL, STORED_HEADING_CELL)
    first = _keyframe(0, _yaw_pose(0.0, [0.0, 0.0, 0.0]))
    slam._associate(first)
    assert 0 not in slam.hebbian  # the untrained OVCN's activity means nothing yet
    rng = np.random.default_rng(0)
    slam.object_vector_cells.train_epoch(rng.uniform(2.0, 20.0, 400), rng.uniform(-np.pi, np.pi, 400))
    _settle_at(slam, DRIFTED_CELL, DRIFTED_HEADING_CELL)
    slam._associate(_keyframe(1, _yaw_pose(0.0, [50.0, 0.0, 0.0])))
    # Each with the cells as they were when it was made.
    assert slam.hebbian.recall(0).gc_peak == tuple(STORED_CELL.astype(int))
    assert slam.hebbian.recall(0).hd_peak == int(STORED_HEADING_CELL)
    assert slam.hebbian.recall(1).gc_peak == tuple(DRIFTED_CELL.astype(int))
