"""Detections read from a file, so that any detector can feed NeoSLAM in place of YOLOX.

Format: JSON lines, one line per frame (UTF-8, a byte-order mark allowed)::

    {"frame": 0, "detections": [{"label": "car", "score": 0.9, "box": [x1, y1, x2, y2]}, ...]}

- `frame` is the 0-based index of the frame in the sequence; each frame appears at most once, in any order.
  Frames absent from the file have no detections.
- `box` is in pixels of the left image, x1 < x2 and y1 < y2; `score` is in [0, 1] (the checks of
  `neoslam.io.detection_checks`, shared with a simulated dataset's detections.csv).
- Other keys (on a line or in a detection) are ignored, so that a detector may add its own.
- Blank lines are skipped, and an empty file is allowed: it is what a detector that found nothing writes,
  and what `write_detections_file` writes for no frames.
- Labels outside the classes NeoSLAM keeps are dropped on reading.

Any other problem is an `InputError` naming the file and the line.
"""

from __future__ import annotations

import json
from collections.abc import Iterable, Mapping
from pathlib import Path
from typing import Any

import numpy as np

from neoslam.errors import InputError
from neoslam.io.detection_checks import box_problem, label_problem, score_problem
from neoslam.perception.detection import Detection
from neoslam.text import read_text

__all__ = ["DetectionsFile", "write_detections_file", "parse_line"]


class DetectionsFile:
    """The detections of a JSON-lines file, read and checked whole when opened; `detect` looks a frame up."""

    def __init__(self, path: str | Path, classes: Iterable[str], frame_count: int | None = None) -> None:
        """`frame_count`: the frames of the sequence; a line of a frame beyond them is refused with its line (most
        likely the detections of another sequence)."""
        self.path = Path(path)
        self.classes = frozenset(classes)
        self.frame_count = frame_count
        self._frames = self._read()

    @property
    def frames(self) -> tuple[int, ...]:
        """The frames that have a line in the file, ascending (including those whose detections were dropped)."""
        return tuple(sorted(self._frames))

    def detect(self, frame_index: int, image: np.ndarray | None = None) -> list[Detection]:
        """The file's detections of `frame_index` (none when absent), clipped to the image when one is given.

        Boxes that clipping leaves empty (entirely outside the image) are dropped.
        """
        detections = self._frames.get(frame_index, [])
        if image is None:
            return list(detections)
        return [d for d in (_clip(d, image.shape[1], image.shape[0]) for d in detections) if d is not None]

    def _read(self) -> dict[int, list[Detection]]:
        lines = read_text(self.path, missing="detections file not found").splitlines()
        frames: dict[int, list[Detection]] = {}
        for number, line in enumerate(lines, start=1):
            if not line.strip():
                continue
            try:
                frame, detections = parse_line(line)
            except ValueError as error:
                raise InputError(self.path, str(error), line=number) from error
            if frame in frames:
                raise InputError(self.path, f"frame {frame} appears twice", line=number)
            if self.frame_count is not None and frame >= self.frame_count:
                problem = f"frame {frame} is beyond the {self.frame_count} frames of the sequence"
                raise InputError(self.path, problem, line=number)
            frames[frame] = [d for d in detections if d.label in self.classes]
        return frames


def parse_line(line: str) -> tuple[int, list[Detection]]:
    """The frame index and detections of one line; ValueError saying what is wrong (without file or line)."""
    try:
        record = json.loads(line)
    except json.JSONDecodeError as error:
        raise ValueError(f"not JSON ({error.msg} at column {error.colno})") from error
    except RecursionError:
        # json's parser recurses per nesting level: a line nested thousands deep is no detection record.
        raise ValueError("not a detections record (JSON nested too deeply)") from None
    if not isinstance(record, dict):
        raise ValueError('a line must be a JSON object {"frame": ..., "detections": [...]}')
    frame = _required(record, "frame", "line")
    if not _is_int(frame) or frame < 0:
        raise ValueError(f'"frame" must be a non-negative integer, got {frame!r}')
    items = _required(record, "detections", "line")
    if not isinstance(items, list):
        raise ValueError(f'"detections" must be a list, got {type(items).__name__}')
    return frame, [_parse_detection(item, index) for index, item in enumerate(items)]


def _parse_detection(item: Any, index: int) -> Detection:
    where = f"detection {index}"
    if not isinstance(item, dict):
        raise ValueError(f'{where}: must be an object {{"label": ..., "score": ..., "box": [...]}}')
    label = _required(item, "label", where)
    score = _required(item, "score", where)
    box = _required(item, "box", where)
    problem = label_problem(label) or score_problem(score) or box_problem(box)
    if problem is not None:
        raise ValueError(f"{where}: {problem}")
    return Detection(label, float(score), np.array(box, dtype=np.float64))


def _required(record: dict[str, Any], key: str, where: str) -> Any:
    if key not in record:
        raise ValueError(f'{where}: missing key "{key}"')
    return record[key]


def _is_int(value: Any) -> bool:
    return isinstance(value, int) and not isinstance(value, bool)  # JSON true is not frame 1


def _clip(detection: Detection, width: int, height: int) -> Detection | None:
    box = np.clip(detection.box, 0, [width, height, width, height])
    if box[2] <= box[0] or box[3] <= box[1]:
        return None
    return Detection(detection.label, detection.score, box)


def write_detections_file(path: str | Path, per_frame: Mapping[int, list[Detection]]) -> None:
    """Write detections in the format `DetectionsFile` reads, one line per frame of `per_frame`, ascending.

    Frames with an empty list get a line too, so that the file records that they were processed.
    Raises ValueError for a negative frame or a detection that the reader would refuse.
    """
    lines = []
    for frame in sorted(per_frame):
        if not _is_int(frame) or frame < 0:
            raise ValueError(f"frame must be a non-negative integer, got {frame!r}")
        record = {
            "frame": frame,
            "detections": [
                {"label": d.label, "score": d.score, "box": [float(v) for v in d.box]} for d in per_frame[frame]
            ],
        }
        line = json.dumps(record, allow_nan=False)
        parse_line(line)  # the writer refuses what the reader would, so that every written file reads back
        lines.append(line + "\n")
    Path(path).write_text("".join(lines), encoding="utf-8")
