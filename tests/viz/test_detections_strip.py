"""The detections strip of a run on real images: some keyframe frames, evenly spread, each left image with its
detections' boxes in their class colour and a label of class, score and depth, two images a row; and the video of
every frame so drawn."""

from __future__ import annotations

from pathlib import Path

import cv2
import numpy as np

from neoslam.types import Frame, ObjectObservation
from neoslam.viz.detections_strip import (
    BOX_COLOURS,
    STRIP_COLUMNS,
    STRIP_FRAMES,
    TILE_WIDTH,
    SeenObjects,
    strip_frames,
    write_detections_strip,
    write_detections_video,
)


def _frame(index: int, boxes: list[tuple[str, tuple[float, float, float, float], float]]) -> Frame:
    observations = tuple(
        ObjectObservation(
            label, 0.9, np.array(box), np.array(box), np.array([0.0, 0.0, depth]), np.zeros((4, 4), np.uint8)
        )
        for label, box, depth in boxes
    )
    return Frame(index, 0.1 * index, np.eye(4), np.zeros(3), np.zeros(3), observations)


def test_the_frames_drawn_are_spread_over_the_keyframes() -> None:
    assert strip_frames(np.array([5, 3, 3, 9])) == [3, 5, 9]
    chosen = strip_frames(np.arange(0, 1000, 7))
    assert len(chosen) == STRIP_FRAMES and chosen[0] == 0 and chosen[-1] == 994 and chosen == sorted(set(chosen))
    assert strip_frames(np.zeros(0, dtype=int)) == []


def test_boxes_are_drawn_in_their_class_colour_on_the_frames_images(tmp_path: Path) -> None:
    seen = SeenObjects()
    seen(None, _frame(0, [("car", (100.0, 100.0, 300.0, 250.0), 12.5)]), np.eye(4))
    seen(None, _frame(1, []), np.eye(4))
    seen(None, _frame(2, [("person", (600.0, 150.0, 700.0, 350.0), 8.0)]), np.eye(4))
    image = np.full((376, 1240), 128, dtype=np.uint8)  # KITTI's size, halved in the strip
    path = tmp_path / "detections.png"
    assert write_detections_strip(path, lambda frame: image, np.array([0, 2]), seen)
    strip = cv2.imread(str(path))
    assert strip.shape == (188, STRIP_COLUMNS * TILE_WIDTH, 3)
    left, right = strip[:, :TILE_WIDTH], strip[:, TILE_WIDTH:]
    assert np.all(left[125, 50] == BOX_COLOURS["car"])  # the car's left edge, x 100 / 2, halfway down
    assert np.all(right[150, 300] == BOX_COLOURS["person"])
    assert np.all(right[150, 50] == 128)  # no box where the car was: each image its own frame's
    assert not write_detections_strip(tmp_path / "none.png", lambda frame: image, np.zeros(0, dtype=int), seen)
    assert not (tmp_path / "none.png").exists()


def test_the_video_has_every_frame_drawn_at_the_cameras_rate_and_the_same_frames_give_the_same_bytes(tmp_path):
    seen = SeenObjects()
    for index in range(5):
        seen(None, _frame(index, [("car", (100.0 + 40 * index, 100.0, 300.0 + 40 * index, 250.0), 12.5)]), np.eye(4))
    image = np.full((376, 1240), 128, dtype=np.uint8)
    first, second = tmp_path / "a.avi", tmp_path / "b.avi"
    for path in (first, second):
        assert write_detections_video(path, lambda frame: image, sorted(seen.frames), seen, 10.0) == 5
    assert first.read_bytes() == second.read_bytes()
    video = cv2.VideoCapture(str(first))
    assert int(video.get(cv2.CAP_PROP_FRAME_COUNT)) == 5 and video.get(cv2.CAP_PROP_FPS) == 10.0
    for index in range(5):
        ok, picture = video.read()
        assert ok and picture.shape == (188, TILE_WIDTH, 3)
        edge = (100 + 40 * index) // 2 + 1  # the car's left edge, halved, inside the 2-pixel line
        blue = picture[125, edge].astype(int) - picture[125, edge - 12].astype(int)  # against the grey beside it
        assert blue[0] > 40, index  # the box moves with the car from frame to frame (JPEG: near its colour)
    assert write_detections_video(tmp_path / "none.avi", lambda frame: image, [], seen, 10.0) == 0
    assert not (tmp_path / "none.avi").exists()
