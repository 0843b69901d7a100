"""A folder of a stereo camera's own images with its calibration file, read as a stereo sequence.

```
FOLDER/left/NAME.png|jpg ...    left camera images (raw or rectified, grey or colour)
FOLDER/right/NAME.png|jpg ...   right camera images, paired with the left by identical file name
FOLDER/calibration.yaml         the stereo calibration (or --calibration FILE): see datasets/stereo_calibration.py
FOLDER/times.txt                optional: each frame's time, s, one line per pair
```

Frames follow the order of the file names (by their numeric value when every name is a number, else
alphabetically). A frame's time, in seconds, comes from the first of:

1. `times.txt`, one line per image pair in that order (as KITTI's);
2. the file names, when every name is a time: whole numbers of at least 18 digits are nanoseconds (a Unix time in
   ns), names with a decimal point are seconds; other whole numbers (000000, 000001, ...) number the frames only;
3. the frame rate in the calibration file (NeoSLAM's `frame_rate`, ORB-SLAM3's `Camera.fps`): frame i at i / rate.

Without any of these the folder is refused, as is a left image without a right image of the same name (or the
other way round).
"""

from __future__ import annotations

import re
from decimal import Decimal
from pathlib import Path

import numpy as np

from neoslam.config.perception import PerceptionConfig
from neoslam.datasets.kitti import read_grey_image
from neoslam.datasets.rectified_sequence import RectifiedSequence
from neoslam.datasets.stereo_calibration import read_stereo_calibration
from neoslam.errors import InputError
from neoslam.io.trajectory_files import read_times

__all__ = ["is_stereo_folder", "read_stereo_folder", "CALIBRATION_FILE", "TIMES_FILE"]

SIDES = ("left", "right")
IMAGE_SUFFIXES = (".png", ".jpg", ".jpeg")
CALIBRATION_FILE = "calibration.yaml"
TIMES_FILE = "times.txt"
NS_PER_S = 1_000_000_000
MIN_NS_STAMP = 10**17  # 18 digits: a Unix time in ns from 1973 on (in us or ms it has at most 16 digits)
NUMBER = re.compile(r"^\d+(\.\d+)?$")


def is_stereo_folder(path: Path) -> bool:
    """A folder holding left/ and right/ image folders."""
    return path.is_dir() and all((path / side).is_dir() for side in SIDES)


def read_stereo_folder(folder: Path, config: PerceptionConfig, calibration: Path | None = None) -> RectifiedSequence:
    """The stereo sequence of a folder of left/ and right/ images, calibrated by `calibration` (default:
    FOLDER/calibration.yaml)."""
    names = _pair_names(folder)
    left = tuple(folder / "left" / name for name in names)
    right = tuple(folder / "right" / name for name in names)
    first = read_grey_image(left[0])
    calibration_path = calibration if calibration is not None else folder / CALIBRATION_FILE
    found = read_stereo_calibration(calibration_path, (first.shape[1], first.shape[0]))
    rectifier = found.rectifier(config.rectification.alpha)
    timestamps = _timestamps(folder, names, found.frame_rate, calibration_path)
    return RectifiedSequence(f"stereo-{folder.resolve().name}", rectifier, timestamps, left, right)


def _images(folder: Path) -> set[str]:
    return {p.name for p in folder.iterdir() if p.suffix.lower() in IMAGE_SUFFIXES and not p.name.startswith(".")}


def _pair_names(folder: Path) -> list[str]:
    """The file names the two cameras share, in frame order; a name of one camera alone is refused."""
    left, right = (_images(folder / side) for side in SIDES)
    for side, own, other in (("left", left, right), ("right", right, left)):
        alone = sorted(own - other)
        if alone:
            missing = "right" if side == "left" else "left"
            problem = f"no {missing} image of the same name ({len(alone)} {side} images have none)"
            raise InputError(folder / side / alone[0], problem)
    if not left:
        raise InputError(folder / "left", f"no images ({', '.join(IMAGE_SUFFIXES)})")
    stems = [Path(name).stem for name in left]
    if all(NUMBER.match(stem) for stem in stems):
        return sorted(left, key=lambda name: (Decimal(Path(name).stem), name))
    return sorted(left)


def _timestamps(folder: Path, names: list[str], frame_rate: float | None, calibration: Path) -> np.ndarray:
    """Each frame's time, s: from times.txt, the file names, or the calibration's frame rate (module docstring)."""
    times_path = folder / TIMES_FILE
    if times_path.exists():
        times = read_times(times_path)
        if len(times) != len(names):
            raise InputError(times_path, f"{len(times)} times for the {len(names)} image pairs")
        return times
    stems = [Path(name).stem for name in names]
    if all(NUMBER.match(stem) for stem in stems):
        values = [Decimal(stem) for stem in stems]
        if all("." not in stem and value >= MIN_NS_STAMP for stem, value in zip(stems, values, strict=True)):
            return _increasing(folder, names, np.array([int(v) for v in values], dtype=np.int64) / NS_PER_S)
        if any("." in stem for stem in stems):
            return _increasing(folder, names, np.array([float(v) for v in values]))
    if frame_rate is None:
        raise InputError(
            folder,
            f"frame times unknown: add {TIMES_FILE}, name the images by their time (ns, or seconds with a decimal "
            f"point), or give the frame rate in {calibration.name}",
        )
    return np.arange(len(names)) / frame_rate


def _increasing(folder: Path, names: list[str], times: np.ndarray) -> np.ndarray:
    """Times from file names: two names of one time (1.5 and 1.50) are refused."""
    repeated = np.flatnonzero(np.diff(times) <= 0)
    if len(repeated):
        first, second = names[repeated[0]], names[repeated[0] + 1]
        raise InputError(folder / "left" / second, f"the same time as {first}")
    return times
