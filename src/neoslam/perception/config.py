"""Configuration of the perception front end (paper 3.1); part of `NeoSLAMConfig` as its `perception` section."""

from __future__ import annotations

from pathlib import Path
from typing import Literal

from pydantic import BaseModel, ConfigDict, Field

__all__ = ["DetectorConfig", "StereoObjectConfig", "StereoOdometryConfig", "PerceptionConfig"]


class _Section(BaseModel):
    model_config = ConfigDict(extra="forbid", frozen=True)


class DetectorConfig(_Section):
    """Object detection: YOLOX-Nano (COCO) through onnxruntime, or detections read from a file (paper: YOLO)."""

    source: Literal["yolox", "file"] = Field("yolox", description="yolox: run the ONNX model; file: --detections")
    model: Path = Field(
        Path("../shared/data/models/yolox_nano_coco/yolox_nano.onnx"),
        description="YOLOX ONNX model (input [1,3,S,S] BGR 0-255, output [1,N,85]); see README for how to get it",
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
    input_size: int = Field(416, gt=0, description="side of the square network input, px (YOLOX-Nano: 416)")
    score_threshold: float = Field(0.35, ge=0, le=1, description="objectness x class score to keep a box")
    nms_iou: float = Field(0.45, gt=0, le=1, description="class-wise non-maximum suppression IoU")
    duplicate_iou: float = Field(
        0.65,
        gt=0,
        le=1,
        description="boxes of different classes overlapping more than this are one object seen "
        "as two (car and truck): the lower score goes; 1 keeps both (a cyclist's person and bicycle overlap ~0.55)",
    )
    tiling: bool = Field(
        True,
        description="also run square tiles (side = image height) over the frame: finds small distant objects (on "
        "kitti_mini 1.5x the cars, at 3x the detection time)",
    )
    tile_overlap: float = Field(0.2, ge=0, lt=1, description="least share of a tile that overlaps its neighbour")
    tile_span: float = Field(
        0.5,
        gt=0,
        le=1,
        description="share of the image width, centred, that the tiles cover: distant objects gather about the "
        "vanishing point (KITTI: 2 tiles for 88 % of the cars that 4 tiles across the whole width find, at 60 % "
        "of the time)",
    )
    min_box_height: float = Field(10.0, ge=0, description="smaller boxes are dropped, px")
    threads: int = Field(2, gt=0, description="onnxruntime intra-op threads")


class StereoObjectConfig(_Section):
    """ORB keypoints in each left box matched along the rectified epipolar line, then triangulated (paper 3.1)."""

    orb_features: int = Field(300, gt=0, description="most ORB keypoints detected in one box")
    orb_scale_factor: float = Field(1.2, gt=1, description="ORB pyramid scale between levels")
    orb_fast_threshold: int = Field(12, gt=0, description="FAST threshold of the ORB detector")
    max_hamming: int = Field(60, gt=0, description="largest ORB descriptor distance of a stereo match, bits")
    ratio: float = Field(0.9, gt=0, le=1, description="best / second-best descriptor distance, at most")
    row_tolerance: float = Field(
        2.0,
        ge=0,
        description="rectified rows of a match differ by at most this, px, times the keypoint's pyramid scale",
    )
    min_disparity: float = Field(1.0, gt=0, description="smaller disparities (far points) are not used, px")
    max_disparity: float = Field(160.0, gt=0, description="largest disparity searched, px")
    refine_window: int = Field(5, ge=0, description="half size of the SAD window of the sub-pixel refinement, px")
    border_margin: float = Field(
        3.0, ge=0, description="boxes this close to the image border hold a cut-off object and are not placed, px"
    )
    min_points: int = Field(5, gt=0, description="an object needs this many triangulated keypoints")
    inlier_sigmas: float = Field(2.5, gt=0, description="keypoints this many robust std from the median depth go")
    min_depth_spread: float = Field(
        0.3, gt=0, description="least robust depth std of an object's keypoints, m (a car is deeper than a plane)"
    )
    min_depth: float = Field(1.0, gt=0, description="objects closer than this are dropped, m")
    max_depth: float = Field(40.0, gt=0, description="objects farther than this are dropped, m")
    patch_size: int = Field(16, gt=1, description="side of the grey appearance patch, px (as the simulator's)")


class StereoOdometryConfig(_Section):
    """Stereo visual odometry: corners tracked frame to frame, stereo depth, PnP with RANSAC (paper: viso2)."""

    source: Literal["stereo", "poses"] = Field("stereo", description="stereo: from the images; poses: --odometry")
    max_corners: int = Field(1500, gt=0, description="Shi-Tomasi corners tracked per frame")
    corner_quality: float = Field(0.005, gt=0, description="Shi-Tomasi quality level")
    corner_spacing: float = Field(8.0, gt=0, description="least distance between corners, px")
    corner_block: int = Field(3, gt=0, description="Shi-Tomasi gradient window side, px")
    klt_window: int = Field(
        13, gt=2, description="Lucas-Kanade window side, px (cost grows with its square; 21 is ~2x slower, no better)"
    )
    klt_levels: int = Field(3, ge=0, description="Lucas-Kanade pyramid levels of the frame-to-frame tracking")
    stereo_levels: int = Field(
        4, ge=0, description="Lucas-Kanade pyramid levels of the left-to-right match (reach large disparities)"
    )
    forward_backward_px: float = Field(1.0, gt=0, description="a track must return within this many px")
    row_tolerance: float = Field(1.0, ge=0, description="stereo rows differ by at most this, px")
    min_disparity: float = Field(1.0, gt=0, description="points with less disparity are not triangulated, px")
    max_depth: float = Field(60.0, gt=0, description="points farther than this are not used, m")
    ransac_reprojection_px: float = Field(1.0, gt=0, description="PnP RANSAC inlier threshold, px")
    ransac_iterations: int = Field(200, gt=0, description="PnP RANSAC iterations")
    min_inliers: int = Field(20, gt=3, description="fewer PnP inliers: the step keeps the previous velocity")
    mask_objects: bool = Field(True, description="ignore corners inside detected boxes (objects may move)")


class PerceptionConfig(_Section):
    """The front end that turns stereo images into frames and object observations."""

    detector: DetectorConfig = DetectorConfig()
    stereo: StereoObjectConfig = StereoObjectConfig()
    odometry: StereoOdometryConfig = StereoOdometryConfig()
