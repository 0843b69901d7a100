"""The EuRoC MAV / ASL layout, read as a stereo sequence: raw images of two calibrated cameras, rectified as read.

```
ROOT/mav0/                                  (ROOT may be mav0 itself)
  cam0/data.csv                             "#timestamp [ns],filename", one image a line (left camera)
  cam0/data/<timestamp>.png                 raw (distorted) grey images
  cam0/sensor.yaml                          T_BS (camera -> body), resolution, intrinsics [fu, fv, cu, cv],
                                            distortion_model (radial-tangential or equidistant),
                                            distortion_coefficients
  cam1/...                                  the same for the right camera
  state_groundtruth_estimate0/data.csv      optional ground truth: timestamp, p_RS_R xyz, q_RS wxyz, ...
```

The stereo extrinsics are `inv(T_BS_cam1) @ T_BS_cam0` (a point from cam0's frame into cam1's); the pair is
rectified with `perception.rectification`. Frames are the cam0 and cam1 images whose stamps are each other's
nearest within `perception.euroc.pair_tolerance_s` (EuRoC's cameras are triggered together: the stamps are equal);
images before the other camera's first or after its last are left out, and an unpaired image in between stops the
run unless `perception.euroc.skip_unpaired`. A frame's time is its cam0 stamp.

Ground truth (evaluation only) is the body pose interpolated at each frame's stamp, moved to the rectified left
camera and expressed as NeoSLAM's robot poses (REP-103 axes, the world being the first frame's robot pose); it is
used when it covers every frame, and a sequence whose ground truth starts after its first image or ends before its
last has none.
"""

from __future__ import annotations

import re
from pathlib import Path

import numpy as np
from scipy.spatial.transform import Rotation, Slerp

from neoslam.config.perception import PerceptionConfig
from neoslam.datasets.bag import pair_by_stamp
from neoslam.datasets.kitti import read_grey_image
from neoslam.datasets.opencv_yaml import OpenCVYaml, read_opencv_yaml
from neoslam.datasets.rectified_sequence import RectifiedSequence, check_image_size
from neoslam.datasets.stereo_calibration import MODEL_NAMES, intrinsic_matrix, raw_camera
from neoslam.errors import InputError
from neoslam.geometry import camera_poses_to_robot, invert_pose, is_rotation_matrix, make_pose
from neoslam.perception.rectification import (
    EQUIDISTANT_LENGTH,
    MAX_IMAGE_SIDE,
    PLUMB_BOB_LENGTHS,
    ROTATION_TOLERANCE,
    RawCamera,
    StereoRectifier,
)
from neoslam.text import read_text
from neoslam.types import Trajectory

__all__ = ["is_euroc", "read_euroc", "euroc_folder"]

NS_PER_S = 1_000_000_000
CAMERAS = ("cam0", "cam1")
GROUND_TRUTH = "state_groundtruth_estimate0"
GROUND_TRUTH_COLUMNS = 8  # timestamp, p_RS_R x y z, q_RS w x y z (velocities and biases follow, unread)
UNIT_QUATERNION_TOLERANCE = 1e-3  # further from unit length: not a rotation written with float round-off
PINHOLE = "pinhole"
STAMP = re.compile(r"^\d{1,19}$")  # nanoseconds: digits only, within int64


def euroc_folder(path: Path) -> Path | None:
    """The `mav0` folder of an EuRoC recording given as the folder holding it or as itself; None otherwise."""
    if (path / "mav0" / "cam0").is_dir():
        return path / "mav0"
    if all((path / camera / "data.csv").is_file() for camera in CAMERAS):
        return path
    return None


def is_euroc(path: Path) -> bool:
    return path.is_dir() and euroc_folder(path) is not None


def read_euroc(path: Path, config: PerceptionConfig) -> RectifiedSequence:
    """The stereo sequence of an EuRoC recording (the folder holding mav0/, or mav0/ itself)."""
    mav0 = euroc_folder(path)
    if mav0 is None:
        raise InputError(path, "not an EuRoC recording (mav0/cam0 and mav0/cam1 with data.csv)")
    (left, left_pose), (right, right_pose) = (_sensor(mav0 / camera / "sensor.yaml") for camera in CAMERAS)
    try:
        rectifier = StereoRectifier.from_extrinsics(
            left, right, invert_pose(right_pose) @ left_pose, config.rectification.alpha
        )
    except ValueError as error:
        raise InputError(mav0 / "cam1" / "sensor.yaml", f"T_BS (with cam0's): {error}") from None
    stamps, left_paths, right_paths = _frames(mav0, config)
    check_image_size(left_paths[0], read_grey_image(left_paths[0]), rectifier.size)
    truth_file = mav0 / GROUND_TRUTH / "data.csv"
    truth = None
    if truth_file.is_file():
        body_to_left = left_pose @ make_pose(rectifier.left_rotation.T, np.zeros(3))  # rectified left camera
        truth = _ground_truth(truth_file, stamps, body_to_left, config.euroc.ground_truth_gap_s)
    folder = path.resolve()
    recording = folder.parent.name if folder == mav0.resolve() else folder.name
    timestamps = stamps / NS_PER_S
    return RectifiedSequence(f"euroc-{recording}", rectifier, timestamps, left_paths, right_paths, truth)


def _sensor(path: Path) -> tuple[RawCamera, np.ndarray]:
    """A camera's sensor.yaml: its calibration and T_BS (its pose in the body frame)."""
    storage = read_opencv_yaml(path, "camera calibration (sensor.yaml) not found")
    if "camera_model" in storage and storage.string("camera_model") != PINHOLE:
        raise InputError(path, f"camera_model: only {PINHOLE} cameras are read, not {storage.string('camera_model')}")
    pose = _body_pose(storage)
    width, height = storage.vector("resolution", (2,))
    fu, fv, cu, cv = storage.vector("intrinsics", (4,))
    model_name = storage.string("distortion_model")
    if model_name not in MODEL_NAMES:
        raise InputError(path, f"distortion_model: must be one of {', '.join(MODEL_NAMES)}, not {model_name!r}")
    model = MODEL_NAMES[model_name]
    lengths = {"plumb_bob": PLUMB_BOB_LENGTHS[1:], "equidistant": (EQUIDISTANT_LENGTH,)}.get(model)
    distortion = storage.vector("distortion_coefficients", lengths) if lengths else np.zeros(0)
    size = (int(width), int(height))
    if size != (width, height) or not all(0 < side <= MAX_IMAGE_SIDE for side in size):
        raise InputError(path, f"resolution: must be two whole numbers of px in 1..{MAX_IMAGE_SIDE}")
    return raw_camera(path, "intrinsics", intrinsic_matrix(fu, fv, cu, cv), distortion, model, size), pose


def _image_list(path: Path) -> tuple[np.ndarray, list[str], np.ndarray]:
    """A camera's data.csv: stamps (ns), image file names and the line of each."""
    stamps, names, lines = [], [], []
    for number, line in enumerate(read_text(path, "image list (data.csv) not found").splitlines(), start=1):
        if not line.strip() or line.lstrip().startswith("#"):
            continue
        stamp, _, name = (part.strip() for part in line.partition(","))
        if not STAMP.match(stamp) or int(stamp) >= 2**63:
            raise InputError(path, f"{stamp[:30]!r} is not a timestamp in ns", number)
        if not name or "/" in name or "\\" in name or name in (".", ".."):
            raise InputError(path, f"{name[:60]!r} is not an image file name", number)
        if stamps and int(stamp) <= stamps[-1]:
            raise InputError(path, "timestamps must increase from line to line", number)
        stamps.append(int(stamp))
        names.append(name)
        lines.append(number)
    if not stamps:
        raise InputError(path, "lists no images")
    return np.array(stamps, dtype=np.int64), names, np.array(lines)


def _frames(mav0: Path, config: PerceptionConfig) -> tuple[np.ndarray, tuple[Path, ...], tuple[Path, ...]]:
    """The stereo frames: cam0 stamps (ns) and the two image files of each."""
    lists = {camera: _image_list(mav0 / camera / "data.csv") for camera in CAMERAS}
    (left, left_names, _), (right, right_names, _) = lists["cam0"], lists["cam1"]
    tolerance = round(config.euroc.pair_tolerance_s * NS_PER_S)
    pairs_left, pairs_right = pair_by_stamp(left, right, tolerance)
    if len(pairs_left) == 0:
        raise InputError(mav0, f"no stereo pairs: no cam0 and cam1 images within {tolerance / 1e6:g} ms of each other")
    if not config.euroc.skip_unpaired:
        for camera, other, paired in (("cam0", "cam1", pairs_left), ("cam1", "cam0", pairs_right)):
            _check_unpaired(mav0, camera, other, lists, paired, config.euroc.pair_tolerance_s)
    paths = []
    for camera, names, paired in (("cam0", left_names, pairs_left), ("cam1", right_names, pairs_right)):
        files = tuple(mav0 / camera / "data" / names[i] for i in paired)
        missing = next((file for file in files if not file.is_file()), None)
        if missing is not None:
            raise InputError(missing, f"image listed in {camera}/data.csv not found")
        paths.append(files)
    return left[pairs_left], paths[0], paths[1]


def _check_unpaired(
    mav0: Path,
    camera: str,
    other: str,
    lists: dict[str, tuple[np.ndarray, list[str], np.ndarray]],
    paired: np.ndarray,
    tolerance_s: float,
) -> None:
    """An image without a partner while both cameras were recording is a dropped frame: refused, by its line."""
    stamps, _, lines = lists[camera]
    other_stamps = lists[other][0]
    unpaired = np.setdiff1d(np.arange(len(stamps)), paired)
    inside = unpaired[(stamps[unpaired] >= other_stamps[0]) & (stamps[unpaired] <= other_stamps[-1])]
    if len(inside):
        first = int(inside[0])
        problem = (
            f"{len(inside)} images have no {other} image within {tolerance_s * 1e3:g} ms (first: this one); raise "
            "perception.euroc.pair_tolerance_s or set perception.euroc.skip_unpaired"
        )
        raise InputError(mav0 / camera / "data.csv", problem, int(lines[first]))


def _ground_truth(path: Path, stamps: np.ndarray, body_to_left: np.ndarray, gap_s: float) -> Trajectory | None:
    """The robot poses at the frames' stamps (None when the ground truth does not cover every frame)."""
    times, poses = _ground_truth_samples(path)
    sensor = path.parent / "sensor.yaml"
    if sensor.is_file():  # the pose of the ground truth's own frame in the body frame (the identity in EuRoC)
        storage = read_opencv_yaml(sensor)
        if "T_BS" in storage:
            poses = poses @ invert_pose(_body_pose(storage))
    start = times[0]
    at, samples = (stamps - start) / NS_PER_S, (times - start) / NS_PER_S
    after = np.searchsorted(samples, at)
    if at[0] < samples[0] or at[-1] > samples[-1]:
        return None
    before = np.clip(after - 1, 0, len(samples) - 1)
    after = np.clip(after, 0, len(samples) - 1)
    exact = samples[after] == at
    close = (at - samples[before] <= gap_s) & (samples[after] - at <= gap_s)
    if not (exact | close).all():
        return None
    rotations = Slerp(samples, Rotation.from_matrix(poses[:, :3, :3]))(at).as_matrix()
    positions = np.stack([np.interp(at, samples, poses[:, axis, 3]) for axis in range(3)], axis=1)
    world_left = np.array([make_pose(r, p) for r, p in zip(rotations, positions, strict=True)]) @ body_to_left
    camera_poses = invert_pose(world_left[0]) @ world_left
    return Trajectory(stamps / NS_PER_S, camera_poses_to_robot(camera_poses))


def _ground_truth_samples(path: Path) -> tuple[np.ndarray, np.ndarray]:
    """EuRoC's ground-truth CSV: stamps (ns) and body poses T_R_S."""
    stamps, values = [], []
    for number, line in enumerate(read_text(path, "ground truth not found").splitlines(), start=1):
        if not line.strip() or line.lstrip().startswith("#"):
            continue
        fields = [field.strip() for field in line.split(",")]
        if len(fields) < GROUND_TRUTH_COLUMNS:
            raise InputError(path, f"{len(fields)} columns, at least {GROUND_TRUTH_COLUMNS} expected", number)
        if not STAMP.match(fields[0]) or (stamps and int(fields[0]) <= stamps[-1]):
            raise InputError(path, "the timestamp (ns) must be a whole number above the previous line's", number)
        try:
            row = np.array([float(field) for field in fields[1:GROUND_TRUTH_COLUMNS]])
        except ValueError:
            raise InputError(path, "a position or quaternion value is not a number", number) from None
        norm = np.linalg.norm(row[3:]) if np.isfinite(row).all() else np.nan
        if not abs(norm - 1.0) <= UNIT_QUATERNION_TOLERANCE:
            raise InputError(path, "the pose is not finite or its quaternion is not of unit length", number)
        stamps.append(int(fields[0]))
        values.append(row)
    if len(stamps) < 2:
        raise InputError(path, "fewer than two ground-truth poses")
    table = np.array(values)
    quaternions = table[:, [4, 5, 6, 3]]  # w x y z -> x y z w
    rotations = Rotation.from_quat(quaternions / np.linalg.norm(quaternions, axis=1, keepdims=True)).as_matrix()
    poses = np.tile(np.eye(4), (len(table), 1, 1))
    poses[:, :3, :3], poses[:, :3, 3] = rotations, table[:, :3]
    return np.array(stamps, dtype=np.int64), poses


def _body_pose(storage: OpenCVYaml) -> np.ndarray:
    """T_BS: the sensor's pose in the body frame, a rigid transform."""
    pose = storage.matrix("T_BS", (4, 4))
    if not np.array_equal(pose[3], [0.0, 0.0, 0.0, 1.0]):
        raise InputError(storage.path, "T_BS: its last row must be 0 0 0 1")
    if not is_rotation_matrix(pose[:3, :3], ROTATION_TOLERANCE):
        raise InputError(storage.path, "T_BS: its rotation is not a rotation matrix (orthonormal, determinant +1)")
    return pose
