"""Objects placed in 3-D by ORB stereo matching (paper 3.1).

ORB keypoints inside each left box are matched in the right image along the rectified epipolar line (same row,
positive disparity), refined to sub-pixel disparity by a SAD search along the row, and triangulated with the
baseline. An object's centre is the median of its keypoints that agree in depth; its depth uncertainty is the
robust spread of those keypoints over the square root of their number.
"""

from __future__ import annotations

from dataclasses import dataclass

import cv2
import numpy as np

from neoslam.boxes import covered_share
from neoslam.config import CameraConfig
from neoslam.config.perception import StereoObjectConfig
from neoslam.perception.detection import Detection
from neoslam.types import ObjectObservation

__all__ = ["StereoMatches", "match_stereo_keypoints", "triangulate", "unhidden_shares", "ObjectTriangulator"]

MAD_TO_SIGMA = 1.4826  # median absolute deviation of a normal distribution, in standard deviations
ORB_PATCH_SIZE = 31  # OpenCV's default ORB patch (and edge threshold), px
OCCLUSION_SAMPLES = 20  # per side of a box, for the share of it that nearer boxes hide


@dataclass(frozen=True)
class StereoMatches:
    """Matched keypoints: left pixel positions and their sub-pixel disparities."""

    left: np.ndarray  # (n, 2) u, v
    disparity: np.ndarray  # (n,)


def triangulate(left: np.ndarray, disparity: np.ndarray, camera: CameraConfig) -> np.ndarray:
    """(n, 3) points in the left camera's optical frame from rectified pixels and disparities."""
    depth = camera.fx * camera.baseline / disparity
    x = (left[:, 0] - camera.cx) * depth / camera.fx
    y = (left[:, 1] - camera.cy) * depth / camera.fy
    return np.column_stack([x, y, depth])


def _orb(
    image: np.ndarray, box: np.ndarray, config: StereoObjectConfig, widen_left: float = 0.0
) -> tuple[np.ndarray, np.ndarray | None]:
    """ORB keypoints inside a box (widened to the left by `widen_left` px), as rows (u, v, scale of their pyramid
    level), and their descriptors. ORB runs on the box with a margin only (its image pyramid is most of its cost),
    and with a budget of its own, so that a small distant car is not outvoted by the texture of a near one."""
    height, width = image.shape[:2]
    x1, x2 = (int(np.clip(v, 0, width)) for v in (np.floor(box[0] - widen_left), np.ceil(box[2]) + 1))
    y1, y2 = (int(np.clip(v, 0, height)) for v in (np.floor(box[1]), np.ceil(box[3]) + 1))
    margin = ORB_PATCH_SIZE  # the descriptor of a keypoint on the box edge reads this far outside it
    left, top = max(x1 - margin, 0), max(y1 - margin, 0)
    right, bottom = min(x2 + margin, width), min(y2 + margin, height)
    mask = np.zeros((bottom - top, right - left), np.uint8)
    mask[y1 - top : y2 - top, x1 - left : x2 - left] = 255
    orb = cv2.ORB_create(
        nfeatures=config.orb_features, scaleFactor=config.orb_scale_factor, fastThreshold=config.orb_fast_threshold
    )
    keypoints, descriptors = orb.detectAndCompute(image[top:bottom, left:right], mask)
    rows = [(k.pt[0] + left, k.pt[1] + top, config.orb_scale_factor**k.octave) for k in keypoints]
    return np.array(rows, dtype=np.float64).reshape(-1, 3), descriptors


def _refine_disparity(
    left: np.ndarray, right: np.ndarray, points: np.ndarray, disparity: np.ndarray, half: int
) -> np.ndarray:
    """Sub-pixel disparity: SAD of a (2h+1)^2 window slid +-h px along the row, then a parabola through the
    minimum (as ORB-SLAM's stereo matching). Points too near the border keep their keypoint disparity."""
    if half == 0 or len(points) == 0:
        return disparity
    height, width = left.shape
    u = np.round(points[:, 0]).astype(int)
    v = np.round(points[:, 1]).astype(int)
    ur = np.round(points[:, 0] - disparity).astype(int)
    inside = (v >= half) & (v < height - half) & (u >= half) & (u < width - half)
    inside &= (ur >= 2 * half) & (ur < width - 2 * half)
    refined = disparity.copy()
    if not inside.any():
        return refined
    offsets = np.arange(-half, half + 1)
    rows = v[inside, None, None] + offsets[None, :, None]
    left_windows = left[rows, u[inside, None, None] + offsets[None, None, :]].astype(np.float32)
    shifts = np.arange(-half, half + 1)
    sad = np.empty((inside.sum(), len(shifts)), np.float32)
    for k, shift in enumerate(shifts):
        cols = ur[inside, None, None] + shift + offsets[None, None, :]
        sad[:, k] = np.abs(left_windows - right[rows, cols].astype(np.float32)).sum(axis=(1, 2))
    best = sad.argmin(axis=1)
    interior = (best > 0) & (best < len(shifts) - 1)
    delta = np.zeros(len(best))
    i = np.flatnonzero(interior)
    s0, s1, s2 = sad[i, best[i] - 1], sad[i, best[i]], sad[i, best[i] + 1]
    curvature = s0 - 2 * s1 + s2
    delta[i] = np.where(curvature > 0, 0.5 * (s0 - s2) / np.where(curvature > 0, curvature, 1), 0.0)
    # A minimum on the search edge is not a minimum: keep the keypoint disparity there.
    # The windows sit on the rounded left pixel; its disparity serves the keypoint a fraction of a pixel away.
    right_u = ur[inside] + shifts[best] + delta
    refined[inside] = np.where(interior, u[inside] - right_u, disparity[inside])
    return refined


def _row_candidates(left: np.ndarray, right: np.ndarray, config: StereoObjectConfig) -> tuple[np.ndarray, np.ndarray]:
    """Index pairs (left, right) of keypoints on the same rectified row with a disparity in range, grouped by left
    keypoint. Right keypoints are sorted by row, so each left keypoint looks only at the band around its row."""
    order = np.argsort(right[:, 1], kind="stable")
    rows = right[order, 1]
    # A keypoint found on a coarser pyramid level is located less precisely: its band is wider (as in ORB-SLAM).
    band = config.row_tolerance * left[:, 2]
    low = np.searchsorted(rows, left[:, 1] - band, side="left")
    high = np.searchsorted(rows, left[:, 1] + band, side="right")
    counts = high - low
    query = np.repeat(np.arange(len(left)), counts)
    offsets = np.arange(counts.sum()) - np.repeat(np.cumsum(counts) - counts, counts)
    train = order[np.repeat(low, counts) + offsets]
    disparity = left[query, 0] - right[train, 0]
    keep = (disparity >= config.min_disparity) & (disparity <= config.max_disparity)
    return query[keep], train[keep]


def _best_unambiguous(
    query: np.ndarray, distance: np.ndarray, train: np.ndarray, config: StereoObjectConfig
) -> tuple[np.ndarray, np.ndarray]:
    """Per left keypoint (`query` comes grouped) its nearest right descriptor, kept when close enough and clearly
    better than the next."""
    count = len(query)
    starts = np.flatnonzero(np.r_[True, query[1:] != query[:-1]])
    key = distance.astype(np.int64) * count + np.arange(count)  # nearest first, ties to the earlier candidate
    best_key = np.minimum.reduceat(key, starts)
    best_at, best = best_key % count, best_key // count
    key[best_at] = np.iinfo(np.int64).max  # a keypoint with one candidate has no second: the ratio test passes
    second = np.minimum.reduceat(key, starts) // count
    # Two places on the row that look alike are ambiguous: the ratio test drops them.
    keep = (best <= config.max_hamming) & (best <= config.ratio * second)
    return query[best_at[keep]], train[best_at[keep]]


def match_stereo_keypoints(
    left: np.ndarray, right: np.ndarray, box: np.ndarray, config: StereoObjectConfig
) -> StereoMatches:
    """ORB keypoints in a left box matched to ORB keypoints of the right image on the same rectified row."""
    empty = StereoMatches(np.empty((0, 2)), np.empty(0))
    left_points, left_descriptors = _orb(left, box, config)
    right_points, right_descriptors = _orb(right, box, config, widen_left=config.max_disparity)
    if left_descriptors is None or right_descriptors is None:
        return empty
    query, train = _row_candidates(left_points, right_points, config)
    if len(query) == 0:
        return empty
    distance = np.bitwise_count(left_descriptors[query] ^ right_descriptors[train]).sum(axis=1, dtype=np.int32)
    query, train = _best_unambiguous(query, distance, train, config)
    points = left_points[query, :2]
    coarse = points[:, 0] - right_points[train, 0]
    refined = _refine_disparity(left, right, points, coarse, config.refine_window)
    keep = refined >= config.min_disparity
    return StereoMatches(points[keep], refined[keep])


def _in_boxes(points: np.ndarray, boxes: np.ndarray) -> np.ndarray:
    """(m, n): which rows of (x, y, z, u, v) points have their pixel inside which of the boxes (n, 4)."""
    u, v = points[:, 3, None], points[:, 4, None]
    return (u >= boxes[:, 0]) & (u <= boxes[:, 2]) & (v >= boxes[:, 1]) & (v <= boxes[:, 3])


def _agreeing_points(inside: np.ndarray, config: StereoObjectConfig) -> np.ndarray | None:
    """The keypoints of a box that agree with its median depth, or None when too few."""
    if len(inside) < config.min_points:
        return None
    depth = inside[:, 2]
    median = np.median(depth)
    # Keypoints on the road or on what stands behind the object lie in its box too; they disagree in depth.
    spread = max(MAD_TO_SIGMA * np.median(np.abs(depth - median)), config.min_depth_spread)
    agreeing = inside[np.abs(depth - median) <= config.inlier_sigmas * spread]
    return agreeing if len(agreeing) >= config.min_points else None


def unhidden_shares(boxes: np.ndarray) -> np.ndarray:
    """The share of each box (x1, y1, x2, y2) not covered by a box whose bottom edge is lower in the image: on a
    road, the object standing nearer."""
    return np.array([1.0 - covered_share(box, boxes[boxes[:, 3] > box[3]], OCCLUSION_SAMPLES) for box in boxes])


def _patch(image: np.ndarray, box: np.ndarray, size: int) -> np.ndarray:
    x1, y1, x2, y2 = np.round(box).astype(int)
    crop = image[max(y1, 0) : max(y2, y1 + 1), max(x1, 0) : max(x2, x1 + 1)]
    return cv2.resize(crop, (size, size), interpolation=cv2.INTER_AREA)


class ObjectTriangulator:
    """Detections of one stereo frame -> object observations with a 3-D centre in the camera frame."""

    def __init__(self, camera: CameraConfig, config: StereoObjectConfig) -> None:
        self.camera = camera
        self.config = config

    def _truncated(self, box: np.ndarray) -> bool:
        """A box on the image border holds part of an object: its keypoints do not give the object's centre."""
        margin = self.config.border_margin
        x1, y1, x2, y2 = box
        return x1 < margin or y1 < margin or x2 > self.camera.width - margin or y2 > self.camera.height - margin

    def _box_points(self, left: np.ndarray, right: np.ndarray, box: np.ndarray) -> np.ndarray:
        """(n, 5) rows x, y, z (camera frame) and u, v (left pixel) of the box's triangulated keypoints."""
        matches = match_stereo_keypoints(left, right, box, self.config)
        return np.column_stack([triangulate(matches.left, matches.disparity, self.camera), matches.left])

    def _visible_points(self, points: list[np.ndarray], boxes: np.ndarray) -> list[np.ndarray | None]:
        """Each box's agreeing keypoints, leaving out those that lie in another object's box at that object's
        depth: where parked cars overlap in the image, the keypoints belong to the one in front, and a car mostly
        hidden by a nearer one would otherwise take the nearer one's depth."""
        first = [_agreeing_points(box_points, self.config) for box_points in points]
        placed = np.array([other is not None for other in first], bool)
        depth = np.array([np.median(other[:, 2]) if other is not None else np.nan for other in first])
        band = np.array([np.ptp(other[:, 2]) / 2 if other is not None else np.nan for other in first])
        visible: list[np.ndarray | None] = []
        for k, box_points in enumerate(points):
            # (m points, n boxes) at once: inside box j and at its object's depth, for every other placed box j
            others = placed.copy()
            others[k] = False
            hidden = _in_boxes(box_points, boxes[others]) & (
                np.abs(box_points[:, 2, None] - depth[None, others]) <= band[None, others]
            )
            visible.append(_agreeing_points(box_points[~hidden.any(axis=1)], self.config))
        return visible

    def _placed_boxes(self, detections: list[Detection]) -> list[Detection]:
        """At most `max_boxes` detections, the highest scores first, kept in their order."""
        if len(detections) <= self.config.max_boxes:
            return detections
        scores = np.array([d.score for d in detections])
        kept = np.sort(np.argsort(-scores, kind="stable")[: self.config.max_boxes])
        return [detections[i] for i in kept]

    def observe(self, left: np.ndarray, right: np.ndarray, detections: list[Detection]) -> list[ObjectObservation]:
        """Objects whose keypoints triangulate consistently, within the configured depth range."""
        detections = self._placed_boxes(detections)
        boxes = np.array([d.box for d in detections], dtype=np.float64).reshape(-1, 4)
        points = [self._box_points(left, right, box) for box in boxes]
        visible = unhidden_shares(boxes) >= self.config.min_visible_share
        observations = []
        for k, (detection, box, agreeing) in enumerate(
            zip(detections, boxes, self._visible_points(points, boxes), strict=True)
        ):
            if agreeing is None or self._truncated(box) or not visible[k]:
                continue
            centre = np.median(agreeing[:, :3], axis=0)
            if not self.config.min_depth <= centre[2] <= self.config.max_depth:
                continue
            disparity = self.camera.fx * self.camera.baseline / centre[2]
            depth_sigma = MAD_TO_SIGMA * np.median(np.abs(agreeing[:, 2] - centre[2])) / np.sqrt(len(agreeing))
            observations.append(
                ObjectObservation(
                    label=detection.label,
                    score=detection.score,
                    box_left=box.copy(),
                    box_right=box - np.array([disparity, 0.0, disparity, 0.0]),
                    center_camera=centre,
                    patch=_patch(left, box, self.config.patch_size),
                    depth_sigma=float(depth_sigma),
                )
            )
        return observations
