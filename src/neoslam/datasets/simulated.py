"""The simulated dataset folder: one writer and one reader.

```
DATASET/
  dataset.yaml           format, version, name, source, frame count, camera calibration, simulator settings
  frames.csv             frame,timestamp,vx,vy,vz,wx,wy,wz   odometry: body-frame velocities of step i-1 -> i
  detections.csv         frame,label,score,left_x1..left_y2,right_x1..right_y2,x,y,z   (centre in the optical frame)
  patches.npy            (detections, s, s) uint8 grey patch of each detections.csv row, in row order
  truth/                 read by evaluation only; deleting it does not change a run's map
    poses_tum.txt        true robot poses (REP-103, TUM format)
    objects.csv          id,label,x,y,z,length,width,height,yaw,vx,vy,vz
    detections.csv       detection,object_id   (row of detections.csv -> object; -1 = false positive)
```
"""

from __future__ import annotations

from collections.abc import Collection, Iterable
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import yaml
from pydantic import ValidationError

from neoslam.config import CameraConfig, MotionLimitsConfig, describe_validation_error
from neoslam.errors import InputError
from neoslam.geometry import integrate_body_velocities
from neoslam.inputs import check_input_file
from neoslam.io.detection_checks import box_problem, centre_problem, label_problem, score_problem
from neoslam.io.motion_limits import check_time_steps, check_velocities
from neoslam.io.tables import numeric_column, read_table, write_table
from neoslam.io.trajectory_files import read_tum, write_tum
from neoslam.sim.detections import SimulatedDetection
from neoslam.sim.simulator import SimulatedRecording
from neoslam.text import read_yaml, utf8_text
from neoslam.types import Frame, ObjectObservation, Trajectory

__all__ = [
    "FORMAT",
    "VERSION",
    "SimulatedDataset",
    "write_dataset",
    "read_dataset",
    "is_simulated_dataset",
    "simulated_observations",
]

FORMAT = "neoslam-sim"
VERSION = 1
FRAME_COLUMNS = ("frame", "timestamp", "vx", "vy", "vz", "wx", "wy", "wz")
BOX_COLUMNS = tuple(f"{side}_{c}" for side in ("left", "right") for c in ("x1", "y1", "x2", "y2"))
DETECTION_COLUMNS = ("frame", "label", "score", *BOX_COLUMNS, "x", "y", "z")
# A dataset's name is copied into every output; longer is no name but a corrupt or hostile file.
MAX_NAME_CHARS = 256
NPY_MAGIC = b"\x93NUMPY"
ZIP_MAGIC = b"PK\x03\x04"
OBJECT_COLUMNS = ("id", "label", "x", "y", "z", "length", "width", "height", "yaw", "vx", "vy", "vz")


def write_dataset(folder: Path, recording: SimulatedRecording) -> None:
    """Write a recording into a new or empty folder (the caller makes it atomic)."""
    folder.mkdir(parents=True, exist_ok=True)
    n = len(recording.truth)
    meta = {
        "format": FORMAT,
        "version": VERSION,
        "name": utf8_text(recording.name),  # a file name that is not UTF-8 is written so that it reads back
        "source": utf8_text(recording.source),
        "frames": n,
        "camera": recording.config.camera.model_dump(mode="json"),
        "simulator": recording.config.model_dump(mode="json"),
    }
    (folder / "dataset.yaml").write_text(yaml.safe_dump(meta, sort_keys=False))
    velocities = np.column_stack([recording.linear_velocity, recording.angular_velocity])
    frame_rows = [[i, f"{recording.truth.timestamps[i]:.6f}", *(f"{v:.9f}" for v in velocities[i])] for i in range(n)]
    write_table(folder / "frames.csv", FRAME_COLUMNS, frame_rows)
    detection_rows, truth_rows, patches = [], [], []
    for frame, detections in enumerate(recording.detections):
        for d in detections:
            truth_rows.append([len(detection_rows), d.object_id])
            detection_rows.append([frame, *_detection_values(d)])
            patches.append(d.patch)
    size = recording.config.detection.patch_size
    write_table(folder / "detections.csv", DETECTION_COLUMNS, detection_rows)
    np.save(folder / "patches.npy", np.asarray(patches, dtype=np.uint8).reshape(-1, size, size))
    _write_truth(folder / "truth", recording, truth_rows)


def _detection_values(detection: SimulatedDetection) -> list[str]:
    """A detection as detections.csv holds it, after the frame: label, score, left and right boxes, centre."""
    boxes = (f"{v:.2f}" for v in np.concatenate([detection.box_left, detection.box_right]))
    centre = (f"{v:.4f}" for v in detection.center_camera)
    return [detection.label, f"{detection.score:.4f}", *boxes, *centre]


def _observation(
    label: str, score: float, boxes: np.ndarray, centre: np.ndarray, patch: np.ndarray
) -> ObjectObservation:
    """An observation from a detections.csv row's values (boxes: left then right) and its patch."""
    return ObjectObservation(label, score, boxes[:4], boxes[4:], centre, patch)


def simulated_observations(
    detections: Iterable[SimulatedDetection], classes: Collection[str] | None = None
) -> tuple[ObjectObservation, ...]:
    """A frame's simulated detections as the reader gives them from a dataset folder they were written to: the values
    rounded as detections.csv holds them, detections of other labels than `classes` (when given) left out. For a
    simulation run in memory, frame by frame (a robot driven in closed loop)."""
    observations = []
    for detection in detections:
        label, score, *numbers = _detection_values(detection)
        if classes is not None and label not in classes:
            continue
        values = np.array(numbers, dtype=float)
        observations.append(_observation(label, float(score), values[:8], values[8:], detection.patch))
    return tuple(observations)


def _write_truth(folder: Path, recording: SimulatedRecording, detection_objects: list[list[int]]) -> None:
    folder.mkdir()
    write_tum(folder / "poses_tum.txt", recording.truth)
    w = recording.world
    rows = [
        [i, w.labels[i], *(f"{v:.4f}" for v in (*w.positions[i], *w.sizes[i], w.yaws[i], *w.velocities[i]))]
        for i in range(len(w))
    ]
    write_table(folder / "objects.csv", OBJECT_COLUMNS, rows)
    write_table(folder / "detections.csv", ("detection", "object_id"), detection_objects)


@dataclass(frozen=True)
class SimulatedDataset:
    """A simulated dataset folder, read. `frames()` is all the SLAM path sees."""

    folder: Path
    name: str
    camera: CameraConfig
    timestamps: np.ndarray
    linear_velocity: np.ndarray
    angular_velocity: np.ndarray
    observations: tuple[tuple[ObjectObservation, ...], ...]
    ground_truth: Trajectory | None  # evaluation only
    rows: tuple[tuple[int, ...], ...] = ()  # per frame, the detections.csv row of each observation

    def __len__(self) -> int:
        return len(self.timestamps)

    def odometry(self) -> Trajectory:
        poses = integrate_body_velocities(self.linear_velocity, self.angular_velocity, self.timestamps)
        return Trajectory(self.timestamps, poses)

    def detection_rows(self) -> list[np.ndarray]:
        """Per frame, the detections.csv row of each of its observations, in order: what ties an observation to
        truth/detections.csv, for evaluation only (the SLAM path reads frames())."""
        return [np.asarray(rows, dtype=int) for rows in self.rows]

    def frames(self):
        """Frames in order, with the odometry integrated from the start pose (identity)."""
        poses = self.odometry().poses
        for i in range(len(self)):
            yield Frame(
                index=i,
                timestamp=float(self.timestamps[i]),
                odometry_pose=poses[i],
                linear_velocity=self.linear_velocity[i],
                angular_velocity=self.angular_velocity[i],
                observations=self.observations[i],
            )


def is_simulated_dataset(folder: Path) -> bool:
    return (folder / "dataset.yaml").is_file()


def _read_meta(path: Path) -> dict:
    if not path.is_file():
        raise InputError(path, "not found: not a simulated dataset folder (made by `neoslam simulate`)")
    meta = read_yaml(path)
    if not isinstance(meta, dict) or meta.get("format") != FORMAT:
        raise InputError(path, f"format is not {FORMAT!r}")
    if meta.get("version") != VERSION:
        raise InputError(path, f"version {meta.get('version')!r} is not supported (this NeoSLAM reads {VERSION})")
    if "frames" not in meta:
        raise InputError(path, "no 'frames' entry (the number of frames in frames.csv)")
    frames = meta["frames"]
    if not isinstance(frames, int) or isinstance(frames, bool) or frames < 1:
        raise InputError(path, f"frames must be the number of frames in frames.csv (an integer >= 1), got {frames!r}")
    name = meta.get("name", path.parent.name)
    if isinstance(name, int | float):  # `name: 05` is YAML's number 5: a name all the same
        name = str(name)
    if not isinstance(name, str) or len(name) > MAX_NAME_CHARS:
        # A name is copied into every output (metrics.json, maps): a YAML alias chain here once made 2.8 GB of it.
        raise InputError(path, f"name must be a string of at most {MAX_NAME_CHARS} characters")
    meta["name"] = name
    try:
        meta["camera"] = CameraConfig.model_validate(meta.get("camera", {}))
    except ValidationError as error:
        raise InputError(path, f"camera.{describe_validation_error(error)}") from None
    return meta


def _read_frames(path: Path, limits: MotionLimitsConfig) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    rows = read_table(path, FRAME_COLUMNS)
    if not rows:
        raise InputError(path, "no frames")
    values = {name: numeric_column(path, rows, FRAME_COLUMNS, name) for name in FRAME_COLUMNS}
    if not np.array_equal(values["frame"], np.arange(len(rows))):
        bad = int(np.flatnonzero(values["frame"] != np.arange(len(rows)))[0])
        problem = f"frame {values['frame'][bad]:g} out of order, expected {bad}"
        raise InputError(path, problem, line=int(rows.lines[bad]))
    stamps = values["timestamp"]
    back = np.flatnonzero(np.diff(stamps) <= 0)
    if len(back):
        raise InputError(path, f"timestamp {stamps[back[0] + 1]} does not increase", line=int(rows.lines[back[0] + 1]))
    linear = np.column_stack([values[c] for c in ("vx", "vy", "vz")])
    angular = np.column_stack([values[c] for c in ("wx", "wy", "wz")])
    check_time_steps(path, stamps, limits, rows.lines)
    check_velocities(path, linear, angular, limits, rows.lines)
    return stamps, linear, angular


def _read_detections(
    folder: Path, frames: int, classes: frozenset[str] | None
) -> tuple[tuple[tuple[ObjectObservation, ...], ...], tuple[tuple[int, ...], ...]]:
    """Per frame, its observations (of `classes` only, when given) and the detections.csv row of each."""
    path = folder / "detections.csv"
    rows = read_table(path, DETECTION_COLUMNS)
    numeric = [c for c in DETECTION_COLUMNS if c != "label"]
    values = {name: numeric_column(path, rows, DETECTION_COLUMNS, name) for name in numeric}
    patches = _read_patches(folder / "patches.npy", len(rows))
    per_frame: list[list[ObjectObservation]] = [[] for _ in range(frames)]
    rows_of: list[list[int]] = [[] for _ in range(frames)]
    for k, row in enumerate(rows.rows):
        line = int(rows.lines[k])
        frame = values["frame"][k]
        if frame != int(frame) or not 0 <= frame < frames:
            raise InputError(path, f"frame {frame:g} is not one of the {frames} frames", line=line)
        box = np.array([values[c][k] for c in BOX_COLUMNS])
        centre = np.array([values[c][k] for c in ("x", "y", "z")])
        problem = (
            label_problem(row[1])
            or score_problem(float(values["score"][k]))
            or box_problem(box[:4].tolist(), "left box")
            or box_problem(box[4:].tolist(), "right box")
            or centre_problem(centre.tolist())
        )
        if problem is not None:
            raise InputError(path, problem, line=line)
        if classes is not None and row[1] not in classes:
            continue
        per_frame[int(frame)].append(_observation(row[1], float(values["score"][k]), box, centre, patches[k]))
        rows_of[int(frame)].append(k)
    return tuple(tuple(observations) for observations in per_frame), tuple(tuple(rows) for rows in rows_of)


def _npy_header(path: Path) -> tuple[tuple[int, ...], np.dtype, int]:
    """Shape, dtype and data bytes present of a .npy file, read from its header before any data is loaded: a
    file that is empty, a zip (.npz) or not NumPy's gets its own message, and a header whose shape the file does
    not hold is refused before numpy allocates it."""
    with path.open("rb") as handle:
        magic = handle.read(len(NPY_MAGIC))
        if not magic:
            raise InputError(path, "empty file (0 bytes): expected a .npy array of (N, s, s) uint8 patches")
        if magic.startswith(ZIP_MAGIC):
            raise InputError(path, "is an .npz (zip) archive, not a .npy array (write the patches with numpy.save)")
        if magic != NPY_MAGIC:
            raise InputError(path, "not a .npy file (it does not start with NumPy's header)")
        handle.seek(0)
        try:
            version = np.lib.format.read_magic(handle)
            if version == (1, 0):
                shape, _, dtype = np.lib.format.read_array_header_1_0(handle)
            else:
                shape, _, dtype = np.lib.format.read_array_header_2_0(handle)
        except ValueError as error:
            raise InputError(path, f"the .npy header is not readable ({error})") from None
        return shape, dtype, path.stat().st_size - handle.tell()


def _read_patches(path: Path, count: int) -> np.ndarray:
    check_input_file(path)
    shape, dtype, present = _npy_header(path)
    if len(shape) != 3 or dtype != np.uint8 or shape[0] != count or not 0 < shape[1] == shape[2]:
        raise InputError(path, f"expected ({count}, s, s) uint8 patches with s >= 1, found {shape} {dtype}")
    if present < count * shape[1] * shape[2]:
        raise InputError(path, f"truncated: {present} bytes of data for {shape} patches")
    try:
        patches = np.load(path, allow_pickle=False)
    except (ValueError, OSError, EOFError) as error:
        raise InputError(path, f"not a readable .npy array ({error})") from None
    return patches


def read_dataset(
    folder: Path, limits: MotionLimitsConfig | None = None, classes: Collection[str] | None = None
) -> SimulatedDataset:
    """Read a simulated dataset folder, its motion checked against `limits` (default: the default limits); ground
    truth is attached when `truth/` exists. With `classes` (the detector's, perception.detector.classes), detections
    of other labels are left out, as the real front end leaves them out."""
    if not folder.is_dir():
        raise InputError(folder, "dataset folder not found")
    meta = _read_meta(folder / "dataset.yaml")
    stamps, linear, angular = _read_frames(folder / "frames.csv", limits or MotionLimitsConfig())
    if meta.get("frames") != len(stamps):
        raise InputError(folder / "frames.csv", f"{len(stamps)} frames, dataset.yaml says {meta.get('frames')}")
    observations, rows = _read_detections(folder, len(stamps), None if classes is None else frozenset(classes))
    truth_file = folder / "truth" / "poses_tum.txt"
    truth = read_tum(truth_file) if truth_file.is_file() else None
    if truth is not None and len(truth) != len(stamps):
        raise InputError(truth_file, f"{len(truth)} poses for {len(stamps)} frames")
    return SimulatedDataset(folder, meta["name"], meta["camera"], stamps, linear, angular, observations, truth, rows)
