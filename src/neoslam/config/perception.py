"""Configuration of the perception front end (paper 3.1); part of `NeoSLAMConfig` as its `perception` section."""

from __future__ import annotations

import os
from pathlib import Path
from typing import Literal

from pydantic import Field, model_validator

from neoslam.config.base import Section
from neoslam.config.stereo_inputs import EurocConfig, RectificationConfig

__all__ = [
    "DetectionPass",
    "DetectorConfig",
    "StereoObjectConfig",
    "StereoOdometryConfig",
    "BagConfig",
    "PerceptionConfig",
]


DATA_ENV = "NEOSLAM_DATA"  # where the shared data (models among it) lives
DEFAULT_DATA = Path("../shared/data")  # without NEOSLAM_DATA, relative to the working directory
DEFAULT_MODELS = {
    "yolox": Path("models/yolox_nano_coco/yolox_nano.onnx"),
    "yolo11": Path("models/yolo11n_coco/yolo11n_coco.onnx"),
}


class DetectionPass(Section):
    """A window of the image that the network sees, enlarged by `scale` (the network input is the window's size
    times the scale, rounded up to a multiple of 32 px)."""

    rows: tuple[float, float] = Field((0.0, 1.0), description="top and bottom of the window, shares of the height")
    columns: tuple[float, float] = Field((0.0, 1.0), description="left and right of the window, shares of the width")
    scale: float = Field(1.0, gt=0, le=4, description="enlargement of the window for the network")

    @model_validator(mode="after")
    def _ordered(self) -> DetectionPass:
        for name, (low, high) in (("rows", self.rows), ("columns", self.columns)):
            if not 0.0 <= low < high <= 1.0:
                raise ValueError(f"{name} must be two shares 0 <= start < end <= 1, got {[low, high]}")
        return self


class DetectorConfig(Section):
    """Object detection: a YOLO network through onnxruntime, or detections read from a file (paper: YOLO)."""

    source: Literal["yolox", "yolo11", "file"] = Field(
        "yolox",
        description="yolox: YOLOX-Nano (Apache-2.0, default); yolo11: YOLO11n, which you select and obtain yourself "
        "(AGPL-3.0 weights); file: detections read with --detections",
    )
    model: Path | None = Field(
        None,
        description="the ONNX model; none: $NEOSLAM_DATA (default ../shared/data)/models/yolox_nano_coco/"
        "yolox_nano.onnx for yolox, .../yolo11n_coco/yolo11n_coco.onnx for yolo11 (docs/formats.md says how to get "
        "them)",
    )
    labels_file: Path | None = Field(
        None,
        description="class names of the model's outputs, one a line; none: coco_classes.txt beside the model, "
        "else COCO's 80 names",
    )
    classes: list[str] = Field(
        default_factory=lambda: ["car", "truck", "bicycle", "person"],
        description="classes NeoSLAM keeps (paper: car, truck, bicycle, person)",
    )
    passes: list[DetectionPass] = Field(
        default_factory=lambda: [
            DetectionPass(scale=0.5),
            DetectionPass(rows=(0.32, 0.78), scale=1.25),
        ],
        min_length=1,
        description="windows the network looks at: by default the whole frame at half size (near objects) and the "
        "band of rows that holds KITTI's road and parked cars enlarged 1.25x (distant ones, which a whole frame "
        "shrunk to YOLOX-Nano's 416 px input loses): of the sets measured, the cheapest that keeps the recall on the "
        "labelled frames and the objects mapped on kitti_06_51 (docs/benchmarks/frontend_speed.md)",
    )
    score_threshold: float = Field(
        0.45, ge=0, le=1, description="score (objectness x class) to keep a box (chosen on the labelled frames)"
    )
    nms_iou: float = Field(0.45, gt=0, le=1, description="class-wise non-maximum suppression IoU")
    duplicate_iou: float = Field(
        0.65,
        gt=0,
        le=1,
        description="boxes of different classes overlapping more than this are one object seen "
        "as two (car and truck): the lower score goes; 1 keeps both (a cyclist's person and bicycle overlap ~0.55)",
    )
    min_box_height: float = Field(
        12.0, ge=0, le=1e4, description="smaller boxes are dropped, px (KITTI's object benchmark ignores them too)"
    )
    cut_margin: float = Field(
        4.0,
        ge=0,
        le=1e4,
        description="a box this close to an edge of its window that lies inside the image holds an object the "
        "window cuts, px: left to the windows that see it whole",
    )
    contrast_clip: float = Field(
        3.0,
        ge=0,
        le=1000,
        description="contrast-limited histogram equalisation (CLAHE) of the image before detection: its clip "
        "limit; 0 switches it off (KITTI's grey frames are dark where cars stand in shade)",
    )
    contrast_tiles: int = Field(8, gt=0, le=64, description="CLAHE tiles across each side of the image")
    threads: int = Field(2, gt=0, le=64, description="onnxruntime intra-op threads")
    device: Literal["cpu", "cuda"] = Field(
        "cpu",
        description="where the network runs: cpu, or cuda (onnxruntime's CUDA execution provider, from the "
        'optional gpu extra: pip install "neoslam[gpu]"; refused in one line when it is not available)',
    )

    def model_path(self) -> Path:
        """The configured model, else the source's default under $NEOSLAM_DATA."""
        if self.model is not None:
            return self.model
        return Path(os.environ.get(DATA_ENV, DEFAULT_DATA)) / DEFAULT_MODELS.get(self.source, DEFAULT_MODELS["yolox"])


class StereoObjectConfig(Section):
    """ORB keypoints in each left box matched along the rectified epipolar line, then triangulated (paper 3.1)."""

    orb_features: int = Field(300, gt=0, le=100_000, description="most ORB keypoints detected in one box")
    orb_scale_factor: float = Field(
        1.4,
        gt=1,
        le=4,
        description="ORB pyramid scale between levels (1.4: smaller levels than 1.2 to build and search, the same "
        "keyframes and mapped objects on KITTI)",
    )
    orb_fast_threshold: int = Field(12, gt=0, le=255, description="FAST threshold of the ORB detector")
    max_hamming: int = Field(60, gt=0, le=256, description="largest ORB descriptor distance of a stereo match, bits")
    ratio: float = Field(0.9, gt=0, le=1, description="best / second-best descriptor distance, at most")
    row_tolerance: float = Field(
        2.0,
        ge=0,
        le=1000,
        description="rectified rows of a match differ by at most this, px, times the keypoint's pyramid scale",
    )
    min_disparity: float = Field(1.0, gt=0, le=1e4, description="smaller disparities (far points) are not used, px")
    max_disparity: float = Field(160.0, gt=0, le=1e4, description="largest disparity searched, px")
    refine_window: int = Field(
        5, ge=0, le=100, description="half size of the SAD window of the sub-pixel refinement, px"
    )
    border_margin: float = Field(
        3.0,
        ge=0,
        le=1e4,
        description="boxes this close to the image border hold a cut-off object and are not placed, px",
    )
    min_points: int = Field(5, gt=0, le=10_000, description="an object needs this many triangulated keypoints")
    min_visible_share: float = Field(
        0.35,
        ge=0,
        le=1,
        description="a box less unhidden than this by boxes reaching lower in the image (nearer objects on the road) "
        "is not placed: most of its keypoints are the nearer object's",
    )
    inlier_sigmas: float = Field(
        2.5, gt=0, le=100, description="keypoints this many robust std from the median depth go"
    )
    min_depth_spread: float = Field(
        0.3,
        gt=0,
        le=1000,
        description="least robust depth std of an object's keypoints, m (a car is deeper than a plane)",
    )
    min_depth: float = Field(1.0, gt=0, le=1e4, description="objects closer than this are dropped, m")
    max_depth: float = Field(
        60.0,
        gt=0,
        le=1e4,
        description="objects farther than this are dropped, m (the keyframe fusion weighs far, noisy views little, "
        "and on real streets many parked cars are seen only at 40-60 m)",
    )
    patch_size: int = Field(16, gt=1, le=256, description="side of the grey appearance patch, px (as the simulator's)")
    max_boxes: int = Field(
        100,
        gt=0,
        le=100_000,
        description="most boxes of one frame placed in 3-D, the highest scores first (a detector's non-maximum "
        "suppression keeps a few dozen; a detections file may hold any number, and each box costs a few ms)",
    )


class StereoOdometryConfig(Section):
    """Stereo visual odometry: corners tracked frame to frame, stereo depth, PnP with RANSAC (paper: viso2)."""

    source: Literal["stereo", "poses"] = Field("stereo", description="stereo: from the images; poses: --odometry")
    max_corners: int = Field(1500, gt=0, le=100_000, description="Shi-Tomasi corners tracked per frame")
    corner_quality: float = Field(0.005, gt=0, lt=1, description="Shi-Tomasi quality level")
    corner_spacing: float = Field(8.0, gt=0, le=1e4, description="least distance between corners, px")
    corner_block: int = Field(3, gt=0, le=99, description="Shi-Tomasi gradient window side, px")
    klt_window: int = Field(
        9,
        gt=2,
        le=101,
        description="Lucas-Kanade window side, px (cost grows with its square; 9 tracks KITTI's frames as well as 13)",
    )
    klt_levels: int = Field(3, ge=0, le=10, description="Lucas-Kanade pyramid levels of the frame-to-frame tracking")
    stereo_levels: int = Field(
        4, ge=0, le=10, description="Lucas-Kanade pyramid levels of the left-to-right match (reach large disparities)"
    )
    forward_backward_px: float = Field(1.0, gt=0, le=1000, description="a track must return within this many px")
    row_tolerance: float = Field(1.0, ge=0, le=1000, description="stereo rows differ by at most this, px")
    min_disparity: float = Field(1.0, gt=0, le=1e4, description="points with less disparity are not triangulated, px")
    max_depth: float = Field(60.0, gt=0, le=1e4, description="points farther than this are not used, m")
    ransac_reprojection_px: float = Field(1.0, gt=0, le=1000, description="PnP RANSAC inlier threshold, px")
    ransac_iterations: int = Field(200, gt=0, le=100_000, description="PnP RANSAC iterations")
    min_inliers: int = Field(
        20, gt=3, le=100_000, description="fewer PnP inliers: the step keeps the previous velocity"
    )
    mask_objects: bool = Field(True, description="ignore corners inside detected boxes (objects may move)")


class BagConfig(Section):
    """Reading a ROS 1 or ROS 2 bag: how left and right images pair into stereo frames and how the optional
    odometry topic is sampled at the images' stamps."""

    pair_tolerance_s: float = Field(
        0.005,
        gt=0,
        description="a left and a right image pair when their stamps differ by at most this, s (stereo needs both "
        "taken at once: at 10 m/s, 5 ms is 5 cm of travel; hardware-synchronised cameras give equal stamps)",
    )
    skip_unpaired: bool = Field(
        False, description="drop images without a partner on the other camera instead of stopping with an error"
    )
    odometry_tolerance_s: float = Field(
        0.1,
        gt=0,
        description="an image's odometry pose is interpolated between the odometry messages around its stamp, "
        "which must both be this close to it, s (0.1: odometry at 10 Hz or faster)",
    )


class PerceptionConfig(Section):
    """The front end that turns stereo images into frames and object observations."""

    detector: DetectorConfig = DetectorConfig()
    stereo: StereoObjectConfig = StereoObjectConfig()
    odometry: StereoOdometryConfig = StereoOdometryConfig()
    bag: BagConfig = BagConfig()
    rectification: RectificationConfig = RectificationConfig()
    euroc: EurocConfig = EurocConfig()
    pipeline_depth: int = Field(
        2,
        ge=0,
        le=64,
        description="frames waiting between two stages of the front end (read, detect, place in 3-D; the odometry "
        "tracks in the caller's thread), each stage in a thread of its own (onnxruntime and OpenCV release the "
        "GIL); the frames and their order are the same as one at a time; 0: one frame at a time",
    )
