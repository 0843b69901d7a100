"""The front end's stages overlapped in threads: the same frames in the same order as one at a time, an error at
the frame where it happened, and the stages stopped when the consumer stops."""

from __future__ import annotations

import threading
import time

import numpy as np
import pytest

from neoslam.config import NeoSLAMConfig
from neoslam.perception.detection import Detection
from neoslam.perception.frontend import ImageDataset, StereoFrontEnd, StereoMotion
from neoslam.perception.odometry import StereoOdometry
from neoslam.perception.pipelined import staged
from neoslam.perception.stereo import ObjectTriangulator


def test_stages_keep_the_order_and_every_item() -> None:
    def slow_square(x: int) -> int:
        time.sleep(0.001 * (x % 3))  # stages finish at uneven times
        return x * x

    assert list(staged(range(50), [slow_square, lambda x: x + 1], depth=2)) == [x * x + 1 for x in range(50)]


def test_an_error_reaches_the_consumer_at_its_item() -> None:
    def fails_at_7(x: int) -> int:
        if x == 7:
            raise ValueError("item 7")
        return x

    seen = []
    with pytest.raises(ValueError, match="item 7"):
        for x in staged(range(20), [fails_at_7], depth=3):
            seen.append(x)
    assert seen == list(range(7))


def test_an_error_of_the_source_reaches_the_consumer_after_the_items_before_it() -> None:
    def source():
        yield from range(4)
        raise OSError("image 4 unreadable")

    seen = []
    with pytest.raises(OSError, match="image 4"):
        seen.extend(staged(source(), [lambda x: x], depth=2))
    assert seen == [0, 1, 2, 3]


def test_closing_the_consumer_stops_the_stages() -> None:
    before = threading.active_count()
    frames = staged(iter(range(10**9)), [lambda x: x], depth=2)
    assert next(frames) == 0
    frames.close()
    deadline = time.monotonic() + 5
    while threading.active_count() > before and time.monotonic() < deadline:
        time.sleep(0.05)
    assert threading.active_count() == before


class _Sequence:
    """A textured stereo pair moving forward: every point 20 px of disparity, shifted a little each frame."""

    def __init__(self, frames: int) -> None:
        config = NeoSLAMConfig()
        self.camera = config.simulator.camera
        self.timestamps = np.arange(frames) * 0.1
        rng = np.random.default_rng(3)
        self._texture = rng.integers(0, 256, (self.camera.height, self.camera.width + 64), dtype=np.uint8)
        self.name, self.ground_truth = "textured", None

    def __len__(self) -> int:
        return len(self.timestamps)

    def stereo_pair(self, index: int) -> tuple[np.ndarray, np.ndarray]:
        left = np.ascontiguousarray(self._texture[:, index : index + self.camera.width])
        return left, np.roll(left, -20, axis=1)


class _Boxes:
    def detect(self, frame_index: int, image: np.ndarray) -> list[Detection]:
        return [Detection("car", 0.9, np.array([300.0 + frame_index, 120, 420 + frame_index, 200]))]


def _frames(depth: int):
    sequence = _Sequence(12)
    perception = NeoSLAMConfig().perception
    front_end = StereoFrontEnd(
        ObjectTriangulator(sequence.camera, perception.stereo),
        _Boxes(),
        StereoMotion(StereoOdometry(sequence.camera, perception.odometry)),
    )
    return list(ImageDataset(sequence, front_end, depth).frames())


def test_the_pipelined_front_end_gives_the_frames_of_the_sequential_one() -> None:
    one_at_a_time, overlapped = _frames(0), _frames(2)
    assert len(one_at_a_time) == len(overlapped) == 12
    for a, b in zip(one_at_a_time, overlapped, strict=True):
        assert a.index == b.index and a.timestamp == b.timestamp
        assert np.array_equal(a.odometry_pose, b.odometry_pose)
        assert [o.center_camera.tolist() for o in a.observations] == [o.center_camera.tolist() for o in b.observations]
    assert any(frame.observations for frame in one_at_a_time)
