"""What the detector saw, on the camera's images (plots/detections.png of a run on real images): the left images of
some of the run's keyframe frames, each object's box with its class, score and stereo depth; and, when asked
(`neoslam run --detections-video`), every frame so drawn as a video, plots/detections.avi (Motion JPEG, written by
OpenCV's own encoder: no codec library needed, and the same frames give the same bytes).

`SeenObjects` is a step observer that keeps every frame's detections (class, score, left box, depth; not the
patches) while the run goes, a few dozen bytes an object; after the run, `write_detections_strip` reads the chosen
frames' left images again from the dataset and draws them in a grid."""

from __future__ import annotations

from collections.abc import Callable, Iterable
from dataclasses import dataclass
from pathlib import Path

import cv2
import numpy as np

from neoslam.types import Frame

__all__ = [
    "STRIP_FRAMES",
    "SeenObjects",
    "detections_strip",
    "strip_frames",
    "write_detections_strip",
    "write_detections_video",
]

STRIP_FRAMES = 8  # keyframe frames drawn: evenly spread over the run
STRIP_COLUMNS = 2
TILE_WIDTH = 620  # pixels of each image in the strip (KITTI's 1241 halved)
BOX_COLOURS = {"car": (200, 120, 30), "truck": (160, 60, 150), "bicycle": (50, 160, 40), "person": (30, 130, 230)}
OTHER_COLOUR = (120, 120, 120)  # BGR: a class beyond the four
FONT = cv2.FONT_HERSHEY_SIMPLEX
VIDEO_CODEC = "MJPG"


@dataclass(frozen=True, slots=True)
class Seen:
    """One detection as the strip draws it."""

    label: str
    score: float
    box: np.ndarray  # (4,) x1, y1, x2, y2, left image pixels
    depth_m: float  # the triangulated centre's depth (camera z)


class SeenObjects:
    """A step observer keeping every frame's detections, by frame index."""

    def __init__(self) -> None:
        self.frames: dict[int, tuple[Seen, ...]] = {}

    def __call__(self, slam: object, frame: Frame, pose: np.ndarray) -> None:
        self.frames[frame.index] = tuple(
            Seen(o.label, float(o.score), np.asarray(o.box_left, dtype=float), float(o.center_camera[2]))
            for o in frame.observations
        )


def strip_frames(keyframe_frames: np.ndarray, count: int = STRIP_FRAMES) -> list[int]:
    """Up to `count` distinct keyframe frames, evenly spread from the first to the last."""
    frames = np.unique(np.asarray(keyframe_frames, dtype=int))
    if len(frames) <= count:
        return frames.tolist()
    return frames[np.round(np.linspace(0, len(frames) - 1, count)).astype(int)].tolist()


def _tile(image: np.ndarray, frame: int, seen: tuple[Seen, ...]) -> np.ndarray:
    """The image (grey or colour) in colour with its detections drawn and its frame written, TILE_WIDTH wide."""
    tile = cv2.cvtColor(image, cv2.COLOR_GRAY2BGR) if image.ndim == 2 else image.copy()
    scale = TILE_WIDTH / tile.shape[1]
    tile = cv2.resize(tile, (TILE_WIDTH, max(1, round(tile.shape[0] * scale))), interpolation=cv2.INTER_AREA)
    for s in seen:
        x1, y1, x2, y2 = (int(round(v * scale)) for v in s.box)
        colour = BOX_COLOURS.get(s.label, OTHER_COLOUR)
        cv2.rectangle(tile, (x1, y1), (x2, y2), colour, 2)
        text = f"{s.label} {s.score:.2f} {s.depth_m:.1f} m"
        (width, height), _ = cv2.getTextSize(text, FONT, 0.4, 1)
        top = max(y1 - height - 4, 0)
        cv2.rectangle(tile, (x1, top), (x1 + width + 4, top + height + 4), colour, -1)
        cv2.putText(tile, text, (x1 + 2, top + height + 1), FONT, 0.4, (255, 255, 255), 1, cv2.LINE_AA)
    banner = f"frame {frame}: {len(seen)} object{'s' if len(seen) != 1 else ''}"
    (width, height), _ = cv2.getTextSize(banner, FONT, 0.55, 1)
    cv2.rectangle(tile, (0, 0), (width + 12, height + 12), (0, 0, 0), -1)
    cv2.putText(tile, banner, (6, height + 6), FONT, 0.55, (255, 255, 255), 1, cv2.LINE_AA)
    return tile


def detections_strip(images: dict[int, np.ndarray], seen: dict[int, tuple[Seen, ...]]) -> np.ndarray:
    """The tiles of `images` (frame -> left image), in frame order, STRIP_COLUMNS a row (BGR)."""
    tiles = [_tile(images[frame], frame, seen.get(frame, ())) for frame in sorted(images)]
    height = max(t.shape[0] for t in tiles)
    tiles = [cv2.copyMakeBorder(t, 0, height - t.shape[0], 0, 0, cv2.BORDER_CONSTANT, value=(255, 255, 255))
             for t in tiles]  # fmt: skip
    blank = np.full_like(tiles[0], 255)
    tiles += [blank] * (-len(tiles) % STRIP_COLUMNS)
    rows = [np.hstack(tiles[k : k + STRIP_COLUMNS]) for k in range(0, len(tiles), STRIP_COLUMNS)]
    return np.vstack(rows)


def write_detections_strip(path: Path, left_image, keyframe_frames: np.ndarray, seen: SeenObjects) -> bool:
    """plots/detections.png from `left_image(frame)` (the dataset's rectified left image) at the strip's keyframe
    frames; False when the run made no keyframe (nothing written)."""
    frames = strip_frames(keyframe_frames)
    if not frames:
        return False
    strip = detections_strip({frame: left_image(frame) for frame in frames}, seen.frames)
    if not cv2.imwrite(str(path), strip):
        raise OSError(f"{path}: could not write the image")
    return True


def write_detections_video(
    path: Path, left_image: Callable[[int], np.ndarray], frames: Iterable[int], seen: SeenObjects, fps: float
) -> int:
    """plots/detections.avi: each of `frames` (in order) drawn as the strip draws a tile, at `fps` frames a second;
    the number of frames written (0: no file)."""
    writer, size, written = None, (0, 0), 0
    try:
        for frame in frames:
            tile = _tile(left_image(frame), frame, seen.frames.get(frame, ()))
            if writer is None:
                size = (tile.shape[1], tile.shape[0])
                fourcc = cv2.VideoWriter_fourcc(*VIDEO_CODEC)
                writer = cv2.VideoWriter(str(path), cv2.CAP_OPENCV_MJPEG, fourcc, fps, size)
                if not writer.isOpened():
                    raise OSError(f"{path}: could not write the video")
            if (tile.shape[1], tile.shape[0]) != size:  # a frame of another size: scaled to the first's
                tile = cv2.resize(tile, size, interpolation=cv2.INTER_AREA)
            writer.write(tile)
            written += 1
    finally:
        if writer is not None:
            writer.release()
    return written
