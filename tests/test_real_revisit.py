"""The whole system on real KITTI images: the 51 frames of KITTI 06 (60 m of a residential street) make keyframes
along the street, and a revisit of the same street's images closes true loops only.

The revisit plays the frames forward, back to the start, and forward again through a photometric change (gain,
offset, noise, blur, a shift under 2 px). It is a revisit of the same images, not an independent second drive."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from neoslam.config import NeoSLAMConfig
from neoslam.datasets.kitti import read_kitti_sequence
from neoslam.datasets.replay import PhotometricChange, forward_back_forward
from neoslam.geometry import invert_pose
from neoslam.perception.frontend import open_front_end
from neoslam.pipeline import RunResult, run

pytestmark = pytest.mark.slow  # every test here runs whole drives, real images or real bags

FRAMES = 51
THIRD_PASS = PhotometricChange(gain=0.8, offset=15.0, noise_sigma=3.0, blur_sigma=0.7, shift_x=1.3, shift_y=-0.8)
TRUE_CLOSURE_M = 5.0  # the evaluation's criterion: the two frames' true positions this close
RELATIVE_POSE_M = 1.0


@pytest.fixture(scope="module")
def street(shared_data: Path):
    return read_kitti_sequence(shared_data / "kitti_06_51", "06")


@pytest.fixture(scope="module")
def revisit(street) -> tuple[RunResult, np.ndarray]:
    config = NeoSLAMConfig()
    replay = forward_back_forward(street, THIRD_PASS)
    frames = list(open_front_end(replay, config.perception).frames())
    return run(iter(frames), config, total=len(frames), progress=False), replay.ground_truth.poses


def test_keyframes_along_the_real_street(revisit) -> None:
    result, _ = revisit
    first_pass = [k for k in result.keyframes if k.frame_index < FRAMES]
    assert len(first_pass) >= 6
    assert all(len(k.labels) >= 4 for k in first_pass)


def test_the_third_pass_closes_true_loops_to_the_first(revisit) -> None:
    result, truth = revisit
    third_to_first = [c for c in result.loop_closures if c.query_frame >= 2 * FRAMES - 1 and c.match_frame < FRAMES]
    assert third_to_first, "no closure from the third pass to the first"
    for closure in result.loop_closures:  # every accepted closure is true
        gap = np.linalg.norm(truth[closure.query_frame, :3, 3] - truth[closure.match_frame, :3, 3])
        assert gap <= TRUE_CLOSURE_M, (closure.query_frame, closure.match_frame, gap)
    for closure in third_to_first:  # and its fit is the true relative pose within a metre
        true_relative = invert_pose(truth[closure.match_frame]) @ truth[closure.query_frame]
        assert np.linalg.norm(closure.relative_pose[:2, 3] - true_relative[:2, 3]) < RELATIVE_POSE_M
