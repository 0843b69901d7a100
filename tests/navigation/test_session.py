"""Guidance towards a goal during a run: nothing before the session relocalises in the stored map, then a route from
where the robot is, followed to the goal; an object goal is reached only once it was seen again."""

from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest

from neoslam.config import NeoSLAMConfig
from neoslam.datasets.simulated import read_dataset
from neoslam.geometry import camera_points_to_robot
from neoslam.navigation import plan_route
from neoslam.navigation.session import GUIDANCE_COLUMNS, GoalGuidance
from neoslam.pipeline import NeoSLAM

pytestmark = pytest.mark.slow  # two sessions of a simulated drive

FRAMES = 400


@pytest.fixture(scope="module")
def mapped(block_seed5):
    """The first session's map of the block drive's first frames, those frames, and the first session's pose at
    each of them."""
    frames = list(read_dataset(block_seed5).frames())[:FRAMES]
    slam = NeoSLAM(NeoSLAMConfig())
    poses = [slam.step(frame) for frame in frames]
    return slam.map_state(), frames, poses


def _goal_object(state) -> tuple[int, str]:
    """An object the drive passes in its second half (the route there from the start is long enough to follow):
    its id and class."""
    goal = plan_route(state, "nearest car", start=len(state.experiences) * 3 // 4).goal
    return goal.ids[0], goal.object.position


def _drive(state, frames, goal: str) -> GoalGuidance:
    config = NeoSLAMConfig()
    slam = NeoSLAM(config, stored=state)
    guidance = GoalGuidance(goal, config)
    for frame in frames:
        guidance(slam, frame, slam.step(frame))
    return guidance


def test_a_later_session_is_guided_to_an_object_once_it_relocalises(mapped) -> None:
    state, frames, _ = mapped
    goal, _ = _goal_object(state)
    guidance = _drive(state, frames, f"object {goal}")
    states = [r.state for r in guidance.records]
    assert states[0] == "not_localised"
    localised = guidance.events.localised
    assert localised is not None and all(s == "not_localised" for s in states[:localised])
    assert "arrived" in states and "missing" not in states and "unreachable" not in states
    summary = guidance.summary()
    assert summary["state"] == "arrived" and summary["goal_seen"] is True
    assert summary["arrived_frame"] > summary["planned_frame"] >= localised
    row = guidance.records[summary["arrived_frame"]].row()
    assert tuple(row) == GUIDANCE_COLUMNS and row["goal_distance_m"] <= NeoSLAMConfig().navigation.arrival_radius


def test_an_object_goal_never_seen_again_is_reported_missing_not_arrived(mapped) -> None:
    """The later session sees everything but the goal object (its observations within 5 m of it are taken out)."""
    state, frames, poses = mapped
    goal, position = _goal_object(state)

    def elsewhere(frame, pose):
        def kept(observation) -> bool:
            point = pose[:3, :3] @ camera_points_to_robot(observation.center_camera[None])[0] + pose[:3, 3]
            return np.hypot(*(point[:2] - position[:2])) > 5.0

        return replace(frame, observations=tuple(o for o in frame.observations if kept(o)))

    gone = [elsewhere(frame, pose) for frame, pose in zip(frames, poses, strict=True)]
    guidance = _drive(state, gone, f"object {goal}")
    states = {r.state for r in guidance.records}
    assert "missing" in states and "arrived" not in states
    assert guidance.summary()["state"] == "missing" and guidance.summary()["arrived_frame"] is None


def test_a_goal_the_map_cannot_reach_is_unreachable_with_its_reason(mapped) -> None:
    state, frames, _ = mapped
    guidance = _drive(state, frames[:120], "experience 999999")
    last = guidance.records[-1]
    if guidance.events.localised is None:
        pytest.skip("the first 120 frames did not relocalise")
    assert last.state == "unreachable" and "999999" in (last.reason or "")
