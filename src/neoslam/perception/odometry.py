"""Stereo visual odometry of the perception front end (paper 3.1, where viso2 served).

One step per stereo frame, each a function below:

1. `detect_corners`: Shi-Tomasi corners in the left image, none inside the detected boxes (cars may move).
2. `stereo_points`: their depth, by tracking them into the right image with pyramidal Lucas-Kanade held to the
   rectified row; too small a disparity or too great a depth is dropped.
3. `track_points`: the previous frame's corners tracked into the current left image, forward and back.
4. `estimate_motion`: `cv2.solvePnPRansac` (previous 3-D points, current 2-D points), then Levenberg-Marquardt on
   the inliers. With too few inliers the step repeats the previous motion (constant velocity) and counts a failure.

The current frame's corners and depths become the next step's previous ones, so each image is searched for
corners and matched in stereo once; the tracking starts from the constant-velocity prediction of each corner
(`predict_pixels`), which keeps near, fast-moving points. (OpenCV's Python binding takes no prebuilt pyramids,
so those are built per LK call.) Poses are in the camera optical frame (x right, y down,
z forward); `neoslam.geometry.camera_poses_to_robot` turns them into robot poses.
"""

from __future__ import annotations

from dataclasses import dataclass

import cv2
import numpy as np

from neoslam.config import CameraConfig
from neoslam.config.perception import StereoOdometryConfig
from neoslam.geometry import invert_pose, make_pose
from neoslam.perception.stereo import triangulate

__all__ = [
    "StereoFeatures",
    "StereoOdometry",
    "box_mask",
    "detect_corners",
    "stereo_points",
    "track_points",
    "predict_pixels",
    "estimate_motion",
]

# OpenCV's own Lucas-Kanade termination (30 iterations or a 0.01 px update): tighter buys no accuracy here.
LK_CRITERIA = (cv2.TERM_CRITERIA_COUNT | cv2.TERM_CRITERIA_EPS, 30, 0.01)
# Levenberg-Marquardt refinement of the PnP pose: it converges in a handful of iterations from the RANSAC pose.
REFINE_CRITERIA = (cv2.TERM_CRITERIA_COUNT | cv2.TERM_CRITERIA_EPS, 20, 1e-9)
# RANSAC stops early once it is this sure of having drawn an all-inlier sample.
RANSAC_CONFIDENCE = 0.999
# Constant-velocity predictions closer than this to the camera plane (m) are not trusted as LK starting points.
MIN_PREDICTION_DEPTH = 0.5
# Fixed seed of OpenCV's random generator before each RANSAC: the same images give the same motion.
RANSAC_SEED = 0


@dataclass(frozen=True)
class StereoFeatures:
    """One frame's left image and its corners with stereo depth: (n, 2) px and (n, 3) m, camera frame."""

    image: np.ndarray
    pixels: np.ndarray
    points: np.ndarray


def box_mask(shape: tuple[int, int], boxes: np.ndarray | None) -> np.ndarray | None:
    """uint8 mask of an image, 0 inside the boxes (x1, y1, x2, y2 px) and 255 elsewhere; None without boxes."""
    if boxes is None or len(boxes) == 0:
        return None
    mask = np.full(shape, 255, dtype=np.uint8)
    height, width = shape
    for x1, y1, x2, y2 in np.asarray(boxes, dtype=np.float64).reshape(-1, 4):
        left, top = max(int(np.floor(x1)), 0), max(int(np.floor(y1)), 0)
        right, bottom = min(int(np.ceil(x2)) + 1, width), min(int(np.ceil(y2)) + 1, height)
        mask[top:bottom, left:right] = 0
    return mask


def detect_corners(image: np.ndarray, config: StereoOdometryConfig, boxes: np.ndarray | None = None) -> np.ndarray:
    """(n, 2) float32 Shi-Tomasi corners of a grey image, outside `boxes` when config.mask_objects."""
    mask = box_mask(image.shape[:2], boxes) if config.mask_objects else None
    corners = cv2.goodFeaturesToTrack(
        image,
        maxCorners=config.max_corners,
        qualityLevel=config.corner_quality,
        minDistance=config.corner_spacing,
        mask=mask,
        blockSize=config.corner_block,
    )
    return np.empty((0, 2), np.float32) if corners is None else corners.reshape(-1, 2).astype(np.float32)


def _lucas_kanade(
    previous: np.ndarray,
    current: np.ndarray,
    pixels: np.ndarray,
    config: StereoOdometryConfig,
    levels: int,
    guess: np.ndarray | None = None,
) -> tuple[np.ndarray, np.ndarray]:
    flags = 0 if guess is None else cv2.OPTFLOW_USE_INITIAL_FLOW
    moved, status, _ = cv2.calcOpticalFlowPyrLK(
        previous,
        current,
        pixels.reshape(-1, 1, 2),
        None if guess is None else guess.reshape(-1, 1, 2).copy(),
        winSize=(config.klt_window, config.klt_window),
        maxLevel=levels,
        criteria=LK_CRITERIA,
        flags=flags,
    )
    return moved.reshape(-1, 2), status.reshape(-1).astype(bool)


def stereo_points(
    left: np.ndarray,
    right: np.ndarray,
    pixels: np.ndarray,
    camera: CameraConfig,
    config: StereoOdometryConfig,
) -> tuple[np.ndarray, np.ndarray]:
    """Left-image corners with a stereo match: their (m, 2) pixels and (m, 3) camera-frame points, m <= n.

    Each corner is tracked into the right image from the same pixel (LK, `stereo_levels` pyramid levels reach large
    disparities); a match must stay on its rectified row and give a disparity and depth within the config's limits.
    """
    if len(pixels) == 0:
        return np.empty((0, 2), np.float32), np.empty((0, 3))
    matched, ok = _lucas_kanade(left, right, pixels, config, config.stereo_levels)
    disparity = pixels[:, 0] - matched[:, 0]
    ok &= np.abs(matched[:, 1] - pixels[:, 1]) <= config.row_tolerance
    ok &= disparity >= config.min_disparity
    depth = camera.fx * camera.baseline / np.where(ok, disparity, 1.0)
    ok &= depth <= config.max_depth
    return pixels[ok], triangulate(pixels[ok], disparity[ok], camera)


def track_points(
    previous: np.ndarray,
    current: np.ndarray,
    pixels: np.ndarray,
    config: StereoOdometryConfig,
    guess: np.ndarray | None = None,
) -> tuple[np.ndarray, np.ndarray]:
    """Pixels tracked from the previous into the current image: (n, 2) positions and an (n,) validity mask.

    `guess` (n, 2) predicts the current positions (e.g. by constant velocity); a track is valid when LK succeeds
    both ways and the backward track returns within `forward_backward_px`.
    """
    ok = np.zeros(len(pixels), bool)
    forward = np.array(pixels, dtype=np.float32).reshape(-1, 2)
    if len(pixels) == 0:
        return forward, ok
    forward, ok = _lucas_kanade(previous, current, pixels, config, config.klt_levels, guess)
    back_pixels = pixels[ok]
    backward, back_ok = _lucas_kanade(current, previous, forward[ok], config, config.klt_levels, back_pixels)
    ok[ok] = back_ok & (np.linalg.norm(backward - back_pixels, axis=1) <= config.forward_backward_px)
    return forward, ok


def predict_pixels(points: np.ndarray, motion: np.ndarray, camera: CameraConfig) -> np.ndarray:
    """(n, 2) pixels of previous-frame points (n, 3) seen after `motion` (T_previous_current); points that
    would fall behind the camera keep the pixel they had."""
    current = points @ motion[:3, :3] - motion[:3, 3] @ motion[:3, :3]  # R^T (X - t)
    seen_before = points[:, :2] / points[:, 2:3]
    ahead = current[:, 2:3] > MIN_PREDICTION_DEPTH
    normalised = np.where(ahead, current[:, :2] / np.where(ahead, current[:, 2:3], 1.0), seen_before)
    return (normalised * [camera.fx, camera.fy] + [camera.cx, camera.cy]).astype(np.float32)


def estimate_motion(
    points: np.ndarray,
    pixels: np.ndarray,
    camera: CameraConfig,
    config: StereoOdometryConfig,
) -> tuple[np.ndarray | None, int]:
    """T_previous_current (4x4) from previous-frame 3-D points and their current pixels, and the inlier count.

    RANSAC PnP (EPnP samples, seeded), then Levenberg-Marquardt on the inliers' reprojection error; None when
    fewer than `min_inliers` agree.
    """
    if len(points) < config.min_inliers:
        return None, 0
    intrinsics = np.array([[camera.fx, 0.0, camera.cx], [0.0, camera.fy, camera.cy], [0.0, 0.0, 1.0]])
    object_points = np.ascontiguousarray(points, dtype=np.float64)
    image_points = np.ascontiguousarray(pixels, dtype=np.float64)
    cv2.setRNGSeed(RANSAC_SEED)
    found, rvec, tvec, inliers = cv2.solvePnPRansac(
        object_points,
        image_points,
        intrinsics,
        None,
        iterationsCount=config.ransac_iterations,
        reprojectionError=config.ransac_reprojection_px,
        confidence=RANSAC_CONFIDENCE,
        flags=cv2.SOLVEPNP_EPNP,
    )
    if not found or inliers is None or len(inliers) < config.min_inliers:
        return None, 0 if inliers is None else len(inliers)
    inliers = inliers.reshape(-1)
    rvec, tvec = cv2.solvePnPRefineLM(
        object_points[inliers], image_points[inliers], intrinsics, None, rvec, tvec, criteria=REFINE_CRITERIA
    )
    current_from_previous = make_pose(cv2.Rodrigues(rvec)[0], tvec.reshape(3))
    return invert_pose(current_from_previous), len(inliers)


class StereoOdometry:
    """Frame-to-frame stereo visual odometry; `step` gives each frame's motion, `pose` their product."""

    def __init__(self, camera: CameraConfig, config: StereoOdometryConfig) -> None:
        self.camera = camera
        self.config = config
        self.failures = 0  # steps that fell back on the previous motion
        self.last_inliers = 0  # PnP inliers of the last step (0 before the second frame)
        self.last_tracked = 0  # previous corners with stereo depth tracked into the last frame
        self._pose = np.eye(4)
        self._motion = np.eye(4)
        self._previous: StereoFeatures | None = None

    @property
    def pose(self) -> np.ndarray:
        """T_first_current, camera optical frame (a copy)."""
        return self._pose.copy()

    @property
    def motion(self) -> np.ndarray:
        """The last step's T_previous_current, camera optical frame (a copy)."""
        return self._motion.copy()

    def lose_track(self) -> None:
        """Track afresh from the next frame, which starts at the current pose with no motion: a camera that stopped
        and came back moved by an unknown amount meanwhile, and its first frame has nothing to be tracked from."""
        self._previous = None
        self._motion = np.eye(4)

    def _features(self, left: np.ndarray, right: np.ndarray, boxes: np.ndarray | None) -> StereoFeatures:
        corners = detect_corners(left, self.config, boxes)
        pixels, points = stereo_points(left, right, corners, self.camera, self.config)
        return StereoFeatures(left.copy(), pixels, points)  # a copy: callers may reuse their buffers

    def step(self, left: np.ndarray, right: np.ndarray, boxes: np.ndarray | None = None) -> np.ndarray:
        """The motion T_previous_current (4x4, camera frame) since the last frame; identity on the first.

        `left` and `right` are the rectified grey (uint8) images; `boxes` (n, 4) x1, y1, x2, y2 px are detected
        objects of the left image, whose corners are not used when config.mask_objects.
        """
        if left.ndim != 2 or left.shape != right.shape:
            raise ValueError(f"need two grey images of one size, got {left.shape} and {right.shape}")
        current = self._features(left, right, boxes)
        previous, self._previous = self._previous, current
        if previous is None:
            return self.motion
        guess = predict_pixels(previous.points, self._motion, self.camera)
        tracked, ok = track_points(previous.image, current.image, previous.pixels, self.config, guess)
        self.last_tracked = int(ok.sum())
        motion, self.last_inliers = estimate_motion(previous.points[ok], tracked[ok], self.camera, self.config)
        if motion is None:
            self.failures += 1
            motion = self._motion  # constant velocity
        self._motion = motion
        self._pose = self._pose @ motion
        return self.motion
