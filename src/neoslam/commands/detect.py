"""`neoslam detect`: the configured detector over the left images of a KITTI sequence, a ROS bag, an EuRoC recording
or a folder of stereo images, written as JSON lines (the format `--detections` reads)."""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import replace
from pathlib import Path

from tqdm import tqdm

from neoslam.config import NeoSLAMConfig
from neoslam.datasets.bag import BagSequence, is_bag
from neoslam.datasets.kitti import KittiSequence, is_kitti_root
from neoslam.datasets.opening import ImageInputs, bag_sequence, kitti_sequence, own_camera_sequence
from neoslam.datasets.rectified_sequence import RectifiedSequence
from neoslam.errors import InputError
from neoslam.io.atomic import atomic_file, check_target_file
from neoslam.perception.detections_file import write_detections_file
from neoslam.perception.detector import make_detector

__all__ = ["detect_sequence"]


def detect_sequence(
    root: Path,
    sequence_name: str | None,
    out: Path,
    config: NeoSLAMConfig,
    overwrite: bool = False,
    progress: bool = True,
    read: Sequence[Path | None] = (),
    topics: ImageInputs = ImageInputs(),
) -> dict[str, int]:
    """Run the configured detector over the left images of a KITTI sequence, a ROS bag, an EuRoC recording or a
    folder of stereo images (rectified, as a run sees them) and write its detections as JSON lines (the format
    `--detections` reads), so that a detector runs once and its output can be inspected and reused. `topics` names
    a bag's camera topics (frames are the bag's stereo pairs, as a run numbers them) or a folder's calibration."""
    inputs = [root, *read, *topics.files()]
    check_target_file(out, overwrite, inputs)
    given = replace(topics, sequence=sequence_name)
    sequence: KittiSequence | BagSequence | RectifiedSequence | None = own_camera_sequence(root, config, given)
    if sequence is None and is_bag(root):
        sequence = bag_sequence(root, config, given, motion=False)
    elif sequence is None and not is_kitti_root(root):
        raise InputError(
            root,
            "not a KITTI odometry root (sequences/NN/image_0, image_1, calib.txt, times.txt), a ROS bag, an EuRoC "
            "recording (mav0/cam0, mav0/cam1) or a folder of stereo images (left/, right/ and a calibration)",
        )
    elif sequence is None:
        sequence = kitti_sequence(root, sequence_name)
    with atomic_file(out, overwrite, inputs) as staging:
        detector = make_detector(config.perception.detector)
        indices = tqdm(range(len(sequence)), desc="detect", unit="frame", disable=not progress, leave=False)
        per_frame = {i: detector.detect(i, sequence.left_image(i)) for i in indices}
        write_detections_file(staging, per_frame)
    return {"frames": len(per_frame), "detections": sum(len(d) for d in per_frame.values())}
