"""OpenCV's YAML files (`cv2.FileStorage`: a `%YAML:1.0` header, `!!opencv-matrix` values), read safely: a value by
its key, checked for its type, length and finiteness, every problem one `InputError` naming the file and the key.

The calibration files of OpenCV's samples, ORB-SLAM3's settings and EuRoC's `sensor.yaml` are in this dialect, which
PyYAML does not read (the header, the tags, `data:[...]` without a space). OpenCV parses the text from memory (the
file is read once, bounded, by `neoslam.text.read_text`); a matrix's size is checked before any of it is read, so
that a file claiming a huge matrix costs an error, not memory.
"""

from __future__ import annotations

from collections.abc import Callable
from pathlib import Path
from typing import Any, TypeVar

import cv2
import numpy as np

from neoslam.errors import InputError
from neoslam.inputs import MAX_CONFIG_BYTES
from neoslam.text import read_text

__all__ = ["OpenCVYaml", "is_opencv_yaml", "read_opencv_yaml"]

HEADER = "%YAML"  # OpenCV writes "%YAML:1.0" (before OpenCV 5) or "%YAML 1.2"
MATRIX_TAG = "!!opencv-matrix"
MAX_VALUES = 64  # the largest value NeoSLAM reads from such a file is a 4x4 matrix
_Value = TypeVar("_Value")


def is_opencv_yaml(text: str) -> bool:
    """Text in OpenCV's dialect: its header line, or a matrix tag (which PyYAML refuses)."""
    return text.lstrip().startswith(HEADER) or MATRIX_TAG in text


def read_opencv_yaml(path: Path, missing: str = "file not found") -> OpenCVYaml:
    return OpenCVYaml(path, read_text(path, missing, MAX_CONFIG_BYTES))


class OpenCVYaml:
    """The top-level values of an OpenCV YAML file, by key."""

    def __init__(self, path: Path, text: str) -> None:
        self.path = path
        try:
            self._storage = cv2.FileStorage(text, cv2.FILE_STORAGE_READ | cv2.FILE_STORAGE_MEMORY)
            root = self._storage.root()
            keys = tuple(root.keys()) if root.isMap() else ()
        except (cv2.error, SystemError) as error:  # OpenCV's parser raises both
            raise InputError(path, f"not a valid OpenCV YAML file ({_reason(error)})") from None
        if not keys:
            raise InputError(path, "not a valid OpenCV YAML file (no key: value entries)")
        repeated = next((key for index, key in enumerate(keys) if key in keys[:index]), None)
        if repeated is not None:
            raise InputError(path, f"{repeated}: given twice")
        self.keys = keys

    def __contains__(self, key: str) -> bool:
        return key in self.keys

    def number(self, key: str) -> float:
        """A finite number (an integer is a number too)."""
        return self._read(key, _number)

    def integer(self, key: str) -> int:
        def read(node: Any) -> int:
            value = _number(node)
            if not node.isInt():
                raise ValueError(f"must be a whole number, not {value:g}")
            return int(value)

        return self._read(key, read)

    def string(self, key: str) -> str:
        def read(node: Any) -> str:
            if not node.isString():
                raise ValueError("must be a string")
            return str(node.string())

        return self._read(key, read)

    def vector(self, key: str, lengths: tuple[int, ...]) -> np.ndarray:
        """Numbers given as a sequence or as an `opencv-matrix` of one row or column, as many as one of
        `lengths`."""

        def read(node: Any) -> np.ndarray:
            values = _values(node)
            if len(values) not in lengths:
                counts = " or ".join(str(n) for n in lengths)
                raise ValueError(f"has {len(values)} numbers, {counts} expected")
            return values

        return self._read(key, read)

    def matrix(self, key: str, shape: tuple[int, int]) -> np.ndarray:
        """A matrix of `shape`: an `opencv-matrix` (rows, cols, data) or a sequence of rows x cols numbers."""

        def read(node: Any) -> np.ndarray:
            values = _values(node)
            if node.isMap():
                rows, cols = (_number(node.getNode(name)) for name in ("rows", "cols"))
                if (rows, cols) != shape:
                    raise ValueError(f"is {rows:g}x{cols:g}, {shape[0]}x{shape[1]} expected")
            if len(values) != shape[0] * shape[1]:
                raise ValueError(f"has {len(values)} numbers, {shape[0] * shape[1]} expected ({shape[0]}x{shape[1]})")
            return values.reshape(shape)

        return self._read(key, read)

    def _read(self, key: str, read: Callable[[Any], _Value]) -> _Value:
        if key not in self.keys:
            raise InputError(self.path, f"{key}: missing")
        try:
            return read(self._storage.getNode(key))
        except ValueError as error:
            raise InputError(self.path, f"{key}: {error}") from None
        except (cv2.error, SystemError) as error:
            raise InputError(self.path, f"{key}: cannot be read ({_reason(error)})") from None


def _number(node: Any) -> float:
    if node.empty() or not (node.isInt() or node.isReal()):
        raise ValueError("must be a number")
    value = float(node.real())
    if not np.isfinite(value):
        raise ValueError(f"must be finite, not {value}")
    return value


def _values(node: Any) -> np.ndarray:
    """The numbers of a sequence, or of an `opencv-matrix` map's `data`, bounded before they are read."""
    if node.isMap():
        node = node.getNode("data")
    if node.empty() or not node.isSeq():
        raise ValueError("must be a list of numbers or an opencv-matrix")
    count = int(node.size())
    if count > MAX_VALUES:
        raise ValueError(f"has {count} numbers, far more than expected")
    values = np.empty(count, dtype=np.float64)
    for index in range(count):
        item = node.at(index)
        if item.empty() or not (item.isInt() or item.isReal()):
            raise ValueError(f"holds a value that is not a number (item {index + 1})")
        values[index] = item.real()
    if not np.isfinite(values).all():
        raise ValueError("holds a value that is not finite")
    return values


def _reason(error: BaseException) -> str:
    """OpenCV's own words, shortened to their last clause: "(-212:Parsing error) ... Missing , between ..."."""
    text = str(error.__cause__ or error).strip()
    last = text.splitlines()[-1] if text else type(error).__name__
    return last.rpartition("error: ")[2].strip()[:160]
