"""Opening a run's input: a simulated dataset folder, a KITTI sequence, a ROS bag, an EuRoC recording or a folder of
a stereo camera's own images with its calibration, recognised by what it holds.

A simulated dataset is read as frames; images go through the perception front end (or detections and odometry
from files). A new source adds a reader in this package and a branch to `open_dataset`.
"""

from __future__ import annotations

from collections.abc import Iterator
from dataclasses import dataclass
from pathlib import Path
from typing import Protocol

import numpy as np

from neoslam.config import MotionLimitsConfig, NeoSLAMConfig
from neoslam.datasets.bag import BagSequence, is_bag, open_bag
from neoslam.datasets.euroc import is_euroc, read_euroc
from neoslam.datasets.kitti import KittiSequence, is_kitti_root, read_kitti_sequence, sequences_in
from neoslam.datasets.rectified_sequence import RectifiedSequence
from neoslam.datasets.simulated import is_simulated_dataset, read_dataset
from neoslam.datasets.stereo_folder import is_stereo_folder, read_stereo_folder
from neoslam.errors import ConfigError, InputError
from neoslam.io.motion_limits import check_pose_steps
from neoslam.perception.frontend import StereoSequence, open_front_end
from neoslam.types import Frame, Trajectory

__all__ = [
    "Dataset",
    "ImageInputs",
    "bag_sequence",
    "kitti_sequence",
    "own_camera_sequence",
    "open_dataset",
    "open_stereo_sequence",
]


class Dataset(Protocol):
    """What a run reads: a simulated dataset folder, or image sequences seen through the perception front end."""

    name: str
    ground_truth: Trajectory | None  # evaluation only

    def __len__(self) -> int: ...

    def frames(self) -> Iterator[Frame]: ...


@dataclass(frozen=True)
class ImageInputs:
    """What a run on images needs besides their path: the KITTI sequence, the bag's topics (found in the bag when
    unambiguous) or the calibration file of a folder of stereo images, and optionally detections and odometry from
    files (or a bag's odometry topic) instead of the built-in detector and stereo odometry."""

    sequence: str | None = None
    detections: Path | None = None
    odometry: Path | None = None
    left_topic: str | None = None
    right_topic: str | None = None
    odometry_topic: str | None = None
    calibration: Path | None = None  # a folder of left/ and right/ images: its calibration file

    def files(self) -> list[Path]:
        """The files a run reads besides the dataset (an output must not replace them)."""
        return [path for path in (self.detections, self.odometry, self.calibration) if path is not None]


def kitti_sequence(root: Path, name: str | None) -> KittiSequence:
    """The named sequence of a KITTI root; without a name, one line listing the sequences there."""
    if name is None:
        found = ", ".join(sequences_in(root)) or "none"
        raise InputError(root, f"a KITTI root needs --sequence NN (sequences here: {found})")
    return read_kitti_sequence(root, name)


def bag_sequence(path: Path, config: NeoSLAMConfig, inputs: ImageInputs, motion: bool = True) -> BagSequence:
    """A bag's stereo sequence; with `motion`, its odometry topic too when one is named (or when the config asks
    for poses and no pose file is given: then the bag's only nav_msgs/Odometry topic)."""
    if inputs.sequence is not None:
        raise ConfigError("--sequence applies to KITTI roots; choose a bag's cameras with --left-topic/--right-topic")
    if inputs.odometry is not None and inputs.odometry_topic is not None:
        raise ConfigError("give either --odometry FILE or --odometry-topic, not both")
    wanted = motion and config.perception.odometry.source == "poses" and inputs.odometry is None
    odometry_topic = inputs.odometry_topic if motion else None
    bag = config.perception.bag
    return open_bag(path, bag, inputs.left_topic, inputs.right_topic, odometry_topic, odometry_wanted=wanted)


def own_camera_sequence(data: Path, config: NeoSLAMConfig, inputs: ImageInputs) -> RectifiedSequence | None:
    """The rectified stereo sequence of an EuRoC recording or of a folder of left/ and right/ images (with
    `inputs.calibration` or its calibration.yaml); None for other inputs."""
    if inputs.calibration is not None and not is_stereo_folder(data):
        raise ConfigError("--calibration applies to a folder of left/ and right/ images only")
    if not (is_euroc(data) or is_stereo_folder(data)):
        return None
    if inputs.sequence is not None:
        raise ConfigError("--sequence applies to KITTI roots, not to an EuRoC recording or a folder of images")
    if is_euroc(data):
        return read_euroc(data, config.perception)
    return read_stereo_folder(data, config.perception, inputs.calibration)


def _check_bag_odometry(path: Path, bag: BagSequence, limits: MotionLimitsConfig) -> None:
    """A bag's odometry topic is held to the motion limits as a pose file is, the frame named instead of a line."""
    if bag.odometry is None:
        return
    try:
        check_pose_steps(path, bag.odometry, limits, np.arange(len(bag.odometry)))
    except InputError as error:
        where = f"odometry topic {bag.topics.odometry}, frame {error.line}"
        raise InputError(path, f"{where}: {error.problem}") from None


def open_dataset(data: Path, config: NeoSLAMConfig, inputs: ImageInputs) -> Dataset:
    """The dataset at `data`: a simulated dataset folder, a KITTI root (with `inputs.sequence`), a ROS bag, an
    EuRoC recording or a folder of left/ and right/ images with a calibration."""
    if not data.exists():
        raise InputError(data, "dataset folder not found")
    if (inputs.left_topic, inputs.right_topic, inputs.odometry_topic) != (None, None, None) and not is_bag(data):
        raise ConfigError("--left-topic, --right-topic and --odometry-topic apply to ROS bags only")
    if inputs.calibration is not None and not is_stereo_folder(data):
        raise ConfigError("--calibration applies to a folder of left/ and right/ images only")
    if is_simulated_dataset(data):
        if inputs != ImageInputs():
            raise ConfigError("--sequence, --detections and --odometry apply to image inputs, not a simulated dataset")
        return read_dataset(data, config.motion_limits, config.perception.detector.classes)
    if is_kitti_root(data):
        sequence = kitti_sequence(data, inputs.sequence)
        return open_front_end(sequence, config.perception, inputs.detections, inputs.odometry, config.motion_limits)
    if is_bag(data):
        bag = bag_sequence(data, config, inputs)
        if inputs.odometry is None and bag.odometry is not None:
            _check_bag_odometry(data, bag, config.motion_limits)
        odometry = inputs.odometry if inputs.odometry is not None else bag.odometry
        return open_front_end(bag, config.perception, inputs.detections, odometry, config.motion_limits)
    own = own_camera_sequence(data, config, inputs)
    if own is not None:
        return open_front_end(own, config.perception, inputs.detections, inputs.odometry, config.motion_limits)
    raise InputError(
        data,
        "neither a simulated dataset (dataset.yaml) nor a KITTI odometry root (sequences/) nor a ROS bag (.bag, "
        ".db3, .mcap, or a folder with metadata.yaml) nor an EuRoC recording (mav0/cam0, mav0/cam1) nor a folder "
        "of stereo images (left/, right/ and a calibration)",
    )


def open_stereo_sequence(data: Path, config: NeoSLAMConfig, inputs: ImageInputs) -> StereoSequence:
    """The rectified stereo images at `data` without the front end (to play them as a camera, say): a KITTI
    sequence, a ROS bag's cameras, an EuRoC recording or a folder of left/ and right/ images."""
    if not data.exists():
        raise InputError(data, "dataset folder not found")
    if is_kitti_root(data):
        return kitti_sequence(data, inputs.sequence)
    if is_bag(data):
        return bag_sequence(data, config, inputs, motion=False)
    own = own_camera_sequence(data, config, inputs)
    if own is not None:
        return own
    raise InputError(
        data,
        "no stereo images here: neither a KITTI odometry root nor a ROS bag nor an EuRoC recording nor a folder of "
        "stereo images (a simulated dataset holds detections, not images)",
    )
