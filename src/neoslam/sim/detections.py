"""Per frame, what YOLO plus ORB stereo matching report about the objects in view: label (sometimes confused),
score, left and right boxes, a triangulated centre with disparity noise, misses (by depth and image column),
objects cut off by the image border or hidden behind nearer ones, false positives and a patch."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy.spatial import cKDTree

from neoslam.config import CameraConfig, DetectionNoiseConfig
from neoslam.geometry import robot_points_to_camera
from neoslam.sim.camera import MIN_CORNER_DEPTH, StereoCamera
from neoslam.sim.visibility import column_offset, cut_off, hidden
from neoslam.sim.world import World

__all__ = ["SimulatedDetection", "InView", "DetectionSimulator"]

FALSE_POSITIVE = -1  # object id of a detection with no object behind it
MIN_DISPARITY = 0.5  # px: stereo matching gives up below this
MIN_BOX_PX = 1.0  # a detector reports no box narrower or lower than a pixel
SCORE_NEAR, SCORE_FAR, SCORE_SIGMA = 0.9, 0.55, 0.08  # detector confidence falls with range
SCORE_RANGE = (0.3, 0.99)
FALSE_POSITIVE_SCORE = (0.3, 0.6)
FALSE_POSITIVE_BOX_PX = (15.0, 120.0)  # side of a spurious box
BOX_CORNERS = np.array([[sx, sy, sz] for sx in (-1, 1) for sy in (-1, 1) for sz in (-1, 1)], dtype=float) / 2


@dataclass(frozen=True)
class SimulatedDetection:
    label: str
    score: float
    box_left: np.ndarray
    box_right: np.ndarray
    center_camera: np.ndarray
    patch: np.ndarray  # uint8
    object_id: int  # truth only: the object behind it, or FALSE_POSITIVE


@dataclass(frozen=True)
class InView:
    """An object the detector could report at a pose: in range, its centre in the image, not cut off by the border
    (when the noise model places no cut-off objects) and not hidden behind nearer ones (when it models occlusion)."""

    index: int
    centre: np.ndarray  # (3,) world frame
    yaw: float  # heading of the object's length axis at that time, world frame
    depth: float  # m, of the centre in the camera frame
    column: float  # image column of the centre from the principal point, share of the half width


def _interpolate(table: tuple[tuple[float, float], ...], key: float) -> float:
    """Linear interpolation in a (key, value) table, held at the ends."""
    keys, values = zip(*table, strict=True)
    return float(np.interp(key, keys, values))


def _ordered(box: np.ndarray) -> np.ndarray:
    """x1 < x2 and y1 < y2, each side at least MIN_BOX_PX: corner noise larger than a small, far box would
    otherwise turn it inside out (or to nothing once written to two decimals)."""
    low, high = np.minimum(box[:2], box[2:]), np.maximum(box[:2], box[2:])
    middle, half = (low + high) / 2, np.maximum(high - low, MIN_BOX_PX) / 2
    return np.concatenate([middle - half, middle + half])


def _yaw_matrix(yaw: float) -> np.ndarray:
    c, s = np.cos(yaw), np.sin(yaw)
    return np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]])


class DetectionSimulator:
    """Detections of a world's objects from a stereo camera whose optical centre is the robot frame's origin."""

    def __init__(self, world: World, camera: CameraConfig, noise: DetectionNoiseConfig) -> None:
        self.world = world
        self.camera = StereoCamera(camera)
        self.noise = noise
        self.labels = sorted(set(world.labels.tolist()) | {"car", "truck", "bicycle", "person"})
        static = np.linalg.norm(world.velocities, axis=1) == 0
        self._static_ids = np.flatnonzero(static)
        self._moving_ids = np.flatnonzero(~static)
        self._tree = cKDTree(world.positions[static, :2]) if static.any() else None

    @property
    def max_range(self) -> float:
        """Depth beyond which nothing is reported, m."""
        return self.noise.max_range or self.camera.config.max_range

    def _nearby(self, pose: np.ndarray, positions: np.ndarray) -> np.ndarray:
        cam = self.camera.config
        # The farthest point in view: max_range deep at the image's wider edge.
        half_width = max(cam.cx, cam.width - cam.cx) / cam.fx * self.max_range
        reach = float(np.hypot(self.max_range, half_width)) + self.world.sizes.max(initial=0.0)
        ids = []
        if self._tree is not None:
            ids = self._static_ids[self._tree.query_ball_point(pose[:2, 3], reach)].tolist()
        moving = self._moving_ids[np.linalg.norm(positions[self._moving_ids, :2] - pose[:2, 3], axis=1) < reach]
        return np.array(sorted(ids + moving.tolist()), dtype=int)

    def detect(self, pose: np.ndarray, time: float, rng: np.random.Generator) -> list[SimulatedDetection]:
        """Detections at one true robot pose T_world_robot."""
        detections = [d for view in self.in_view(pose, time) if (d := self._observe(view, pose, rng))]
        detections += self._false_positives(rng)
        return detections

    def in_view(self, pose: np.ndarray, time: float) -> list[InView]:
        """The objects the detector could report at a true robot pose, in object order (no random draws)."""
        cam = self.camera.config
        positions, yaws = self.world.positions_at(time), self.world.yaws_at(time)
        nearby = self._nearby(pose, positions)
        views = []
        for i in nearby:
            centre_cam = self._to_camera(pose, positions[i][None])[0]
            depth = centre_cam[2]
            if not cam.min_range <= depth <= self.max_range:
                continue
            pixel, _ = self.camera.project(centre_cam[None])
            if not self.camera.in_image(pixel)[0]:
                continue
            if self.noise.border_margin is not None and self._cut_off(i, positions[i], yaws[i], pose):
                continue
            column = column_offset(float(pixel[0, 0]), cam)
            views.append(InView(int(i), positions[i], float(yaws[i]), float(depth), column))
        if self.noise.occlusion_cover is not None:
            views = self._unhidden(views, nearby, positions, yaws, pose)
        return views

    def _corners_in_camera(self, index: int, centre: np.ndarray, yaw: float, pose: np.ndarray) -> np.ndarray:
        corners = centre + (BOX_CORNERS * self.world.sizes[index]) @ _yaw_matrix(yaw).T
        return self._to_camera(pose, corners)

    def _cut_off(self, index: int, centre: np.ndarray, yaw: float, pose: np.ndarray) -> bool:
        corners = self._corners_in_camera(index, centre, yaw, pose)
        behind = bool((corners[:, 2] <= MIN_CORNER_DEPTH).any())
        return cut_off(self.camera.extent(corners), behind, self.camera.config, self.noise.border_margin)

    def _unhidden(
        self, views: list[InView], nearby: np.ndarray, positions: np.ndarray, yaws: np.ndarray, pose
    ) -> list[InView]:
        """The views whose box is not mostly covered by the boxes of nearer objects (seen or not)."""
        boxes, depths, rows = [], [], {}
        for i in nearby:
            corners = self._corners_in_camera(i, positions[i], yaws[i], pose)
            if not (corners[:, 2] > MIN_CORNER_DEPTH).any():
                continue
            box = self.camera.box(corners)
            if box[2] > box[0] and box[3] > box[1]:
                rows[int(i)] = len(boxes)
                boxes.append(box)
                depths.append(self._to_camera(pose, positions[i][None])[0, 2])
        if not boxes:
            return views
        covered = hidden(np.array(boxes), np.array(depths), self.noise.occlusion_cover)
        return [v for v in views if v.index not in rows or not covered[rows[v.index]]]

    def _miss_probability(self, depth: float, column: float) -> float:
        noise = self.noise
        if noise.detection_probability is None:
            rate = (
                noise.miss_rate
                + (noise.miss_rate_at_max_range - noise.miss_rate) * depth / self.camera.config.max_range
            )
        else:
            rate = 1.0 - _interpolate(noise.detection_probability, depth)
        if noise.column_factor is None:
            return rate
        return 1.0 - (1.0 - rate) * _interpolate(noise.column_factor, column)

    def _to_camera(self, pose: np.ndarray, points: np.ndarray) -> np.ndarray:
        return robot_points_to_camera((points - pose[:3, 3]) @ pose[:3, :3])

    def _measured_centre(self, index: int, centre: np.ndarray, yaw: float, pose: np.ndarray) -> np.ndarray:
        """Stereo points lie on the visible surface: move the centre towards the camera along the ray."""
        ray = centre - pose[:3, 3]
        ray /= np.linalg.norm(ray)
        in_object = _yaw_matrix(yaw).T @ ray
        radius = 1.0 / np.sqrt(((in_object / (self.world.sizes[index] / 2)) ** 2).sum())
        return centre - self.noise.surface_bias * radius * ray

    def _observe(self, view: InView, pose: np.ndarray, rng) -> SimulatedDetection | None:
        index, centre, depth = view.index, view.centre, view.depth
        if rng.random() < self._miss_probability(depth, view.column):
            return None
        surface = self._to_camera(pose, self._measured_centre(index, centre, view.yaw, pose)[None])
        pixel, disparity = self.camera.project(surface)
        pixel = pixel + rng.normal(0.0, self.noise.pixel_sigma, 2)
        disparity = disparity + rng.normal(0.0, self.noise.disparity_sigma)
        if disparity[0] < MIN_DISPARITY:
            return None
        box = _ordered(
            self.camera.box(self._corners_in_camera(index, centre, view.yaw, pose))
            + rng.normal(0.0, self.noise.box_sigma, 4)
        )
        return SimulatedDetection(
            label=self._label(str(self.world.labels[index]), rng),
            score=self._score(depth, rng),
            box_left=box,
            box_right=box - np.array([disparity[0], 0.0, disparity[0], 0.0]),
            center_camera=self.camera.back_project(pixel, disparity)[0],
            patch=self._patch(self.world.textures[index], rng),
            object_id=int(index),
        )

    def _label(self, label: str, rng: np.random.Generator) -> str:
        if rng.random() < self.noise.label_confusion:
            others = [other for other in self.labels if other != label]
            return others[int(rng.integers(len(others)))]
        return label

    def _score(self, depth: float, rng: np.random.Generator) -> float:
        mean = SCORE_NEAR + (SCORE_FAR - SCORE_NEAR) * depth / self.camera.config.max_range
        return float(np.clip(mean + rng.normal(0.0, SCORE_SIGMA), *SCORE_RANGE))

    def _patch(self, texture: np.ndarray, rng: np.random.Generator) -> np.ndarray:
        gain = 1.0 + rng.normal(0.0, self.noise.patch_gain_sigma)
        noisy = texture * gain + rng.normal(0.0, self.noise.patch_noise, texture.shape)
        return np.clip(np.rint(noisy), 0, 255).astype(np.uint8)

    def _false_positives(self, rng: np.random.Generator) -> list[SimulatedDetection]:
        cam = self.camera.config
        size = self.noise.patch_size
        spurious = []
        for _ in range(rng.poisson(self.noise.false_positives_per_frame)):
            side = rng.uniform(*FALSE_POSITIVE_BOX_PX)
            x1, y1 = rng.uniform(0, cam.width - side), rng.uniform(0, cam.height - side)
            depth = rng.uniform(*(self.noise.false_positive_depth or (cam.min_range * 3, cam.max_range)))
            disparity = cam.fx * cam.baseline / depth
            box = np.array([x1, y1, x1 + side, y1 + side])
            centre = self.camera.back_project(np.array([[x1 + side / 2, y1 + side / 2]]), np.array([disparity]))[0]
            texture = 120.0 + 60.0 * rng.standard_normal((size, size))
            spurious.append(
                SimulatedDetection(
                    label=self.labels[int(rng.integers(len(self.labels)))],
                    score=float(rng.uniform(*FALSE_POSITIVE_SCORE)),
                    box_left=box,
                    box_right=box - np.array([disparity, 0.0, disparity, 0.0]),
                    center_camera=centre,
                    patch=np.clip(np.rint(texture), 0, 255).astype(np.uint8),
                    object_id=FALSE_POSITIVE,
                )
            )
        return spurious
