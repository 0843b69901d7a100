"""The Python API checks what it is given: a wrong record is refused where it is made, a frame out of order or
beyond `motion_limits` where `NeoSLAM.step` is given it, each with a ValueError naming the field and the value (a
TypeError for what is no Frame at all), and nothing of a refused frame is taken."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest

from neoslam import NeoSLAM
from neoslam.config import NeoSLAMConfig
from neoslam.types import Frame, ObjectObservation

BOX = np.array([100.0, 100.0, 140.0, 130.0])
PATCH = np.zeros((16, 16), np.uint8)


def _observation(**change) -> ObjectObservation:
    fields = {
        "label": "car",
        "score": 0.9,
        "box_left": BOX,
        "box_right": BOX - [20.0, 0.0, 20.0, 0.0],
        "center_camera": np.array([1.0, 0.5, 12.0]),
        "patch": PATCH,
    }
    return ObjectObservation(**{**fields, **change})


def _pose(x: float = 0.0) -> np.ndarray:
    pose = np.eye(4)
    pose[0, 3] = x
    return pose


def _frame(index: int = 0, **change) -> Frame:
    fields = {
        "index": index,
        "timestamp": 0.1 * index,
        "odometry_pose": _pose(1.0 * index),
        "linear_velocity": np.array([10.0, 0.0, 0.0]),
        "angular_velocity": np.zeros(3),
        "observations": (_observation(),),
    }
    return Frame(**{**fields, **change})


NAN_POSE = _pose()
NAN_POSE[1, 3] = np.nan
SHEARED = _pose()
SHEARED[0, 1] = 0.3

RECORDS = {
    "a 3x3 pose": (lambda: _frame(odometry_pose=np.eye(3)), "Frame.odometry_pose: expected shape (4, 4), got (3, 3)"),
    "a NaN pose": (lambda: _frame(odometry_pose=NAN_POSE), "Frame.odometry_pose: not finite"),
    "a rotation that is not one": (lambda: _frame(odometry_pose=SHEARED), "Frame.odometry_pose: its rotation is not"),
    "a 2-element velocity": (
        lambda: _frame(linear_velocity=np.array([1.0, 0.0])),
        "Frame.linear_velocity: expected shape (3,), got (2,)",
    ),
    "an infinite velocity": (
        lambda: _frame(angular_velocity=np.array([0.0, 0.0, np.inf])),
        "Frame.angular_velocity: not finite",
    ),
    "a NaN timestamp": (lambda: _frame(timestamp=float("nan")), "Frame.timestamp: not finite: nan"),
    "a negative index": (lambda: _frame(index=-1), "Frame.index: expected an integer >= 0, got -1"),
    "observations as a list": (lambda: _frame(observations=[_observation()]), "Frame.observations: expected a tuple"),
    "a dict among the observations": (lambda: _frame(observations=({"label": "car"},)), "Frame.observations[0]"),
    "a NaN centre": (lambda: _observation(center_camera=np.array([0.0, np.nan, 5.0])), "center_camera: not finite"),
    "a score of 2.0": (lambda: _observation(score=2.0), "ObjectObservation.score: 2 is not in [0, 1]"),
    "an empty label": (lambda: _observation(label=""), "ObjectObservation.label: expected a non-empty class name"),
    "a float patch": (lambda: _observation(patch=np.zeros((4, 4))), "ObjectObservation.patch: expected a 2-D uint8"),
    "a box of 3 numbers": (lambda: _observation(box_left=BOX[:3]), "ObjectObservation.box_left: expected shape (4,)"),
    "a negative depth sigma": (lambda: _observation(depth_sigma=-1.0), "ObjectObservation.depth_sigma: -1 m is"),
}


@pytest.mark.parametrize("case", list(RECORDS))
def test_a_wrong_record_is_refused_where_it_is_made(case: str) -> None:
    make, message = RECORDS[case]
    with pytest.raises(ValueError) as caught:
        make()
    assert message in str(caught.value) and "\n" not in str(caught.value), str(caught.value)


SEQUENCES = {
    "a repeated frame index": ([_frame(0), _frame(1), _frame(1)], "Frame.index: 1 after frame 1"),
    "time going back": (
        [_frame(0), _frame(1), dataclasses.replace(_frame(2), timestamp=0.05)],
        "Frame.timestamp: 0.05 s is before the previous frame's 0.1 s",
    ),
    "a 1e9 m jump": (
        [_frame(0), _frame(1, odometry_pose=_pose(1e9))],
        "Frame.odometry_pose: 1e+09 m from the previous",
    ),
    "a speed beyond the limits": (
        [_frame(0, linear_velocity=np.array([1e6, 0.0, 0.0]))],
        "Frame.linear_velocity: speed 1e+06 m/s exceeds motion_limits.max_speed",
    ),
    "an object behind the camera": (
        [_frame(0, observations=(_observation(center_camera=np.array([0.0, 0.0, -4.0])),))],
        "Frame.observations[0].center_camera: depth (z, optical frame) -4 m is not in front of the camera",
    ),
}


@pytest.mark.parametrize("case", list(SEQUENCES))
def test_a_frame_out_of_order_or_beyond_the_limits_is_refused_and_nothing_of_it_taken(case: str) -> None:
    frames, message = SEQUENCES[case]
    slam = NeoSLAM(NeoSLAMConfig())
    for frame in frames[:-1]:
        slam.step(frame)
    with pytest.raises(ValueError) as caught:
        slam.step(frames[-1])
    assert message in str(caught.value), str(caught.value)
    assert slam.frames_processed == len(frames) - 1
    slam.step(_frame(len(frames) + 5))  # the run goes on with a good frame


def test_what_is_no_frame_and_a_wrong_count_of_step_times_are_refused() -> None:
    slam = NeoSLAM(NeoSLAMConfig())
    with pytest.raises(TypeError, match="step: expected a Frame, got dict"):
        slam.step({"index": 0})
    slam.step(_frame(0))
    with pytest.raises(
        ValueError, match=r"frame_times_s: expected one time per frame processed \(1\) or none, got shape"
    ):
        slam.result(np.zeros(3))
    assert slam.result(np.zeros(1)).estimate is not None
