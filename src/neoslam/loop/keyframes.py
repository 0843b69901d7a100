"""Object keyframes (paper 3.2): the current object and the objects around it, in the world frame.

Single stereo frames see few objects with depth noise that grows with the square of depth, so observations are
first fused over a short stretch of road (the local window), where odometry drift is small: each window object is
the inverse-variance weighted mean of its observations, moved to the world with the pose estimate of the frame
that saw them. Every `spacing` metres of travel, the window object nearest to the robot becomes the current
object and, with the window objects within `neighbourhood_radius` of it, a keyframe. On a sparse street, where
fewer than `sparse_objects` stand that close, the neighbourhood grows (up to `sparse_neighbourhood_radius`) to
take them. With the motion detector's `unjudged: wait`, a window object none of whose views belongs to a track
known to be static is provisional in the keyframe (see loop.matching).
"""

from __future__ import annotations

from array import array
from collections.abc import Callable
from dataclasses import dataclass, field

import numpy as np

from neoslam.config import KeyframeConfig
from neoslam.geometry import camera_points_to_robot
from neoslam.types import Keyframe, ObjectObservation

__all__ = [
    "LocalObjectWindow",
    "KeyframeBuilder",
    "KeyframeStep",
    "footprint_radii",
    "object_centres",
    "view_covariances",
    "WindowViews",
]

# The latest views the window can give back (retract): a moving object is found within a track's views (a few
# dozen), and this bounds the record when the robot stands and the window forgets nothing.
RETRACTABLE_VIEWS = 2048


def footprint_radii(
    labels: list[str] | tuple[str, ...], bearing: np.ndarray, footprints: dict[str, tuple[float, float]]
) -> np.ndarray:
    """Radius of each class's footprint ellipse (length, width) in the direction of a ray `bearing` radians off the
    heading, taking objects to lie along the road (along the heading); 0 for a class without a footprint."""
    footprint = np.array([footprints.get(label, (0.0, 0.0)) for label in labels], dtype=float).reshape(-1, 2) / 2
    with np.errstate(divide="ignore", invalid="ignore"):
        radius = 1.0 / np.sqrt((np.cos(bearing) / footprint[:, 0]) ** 2 + (np.sin(bearing) / footprint[:, 1]) ** 2)
    return np.nan_to_num(radius)  # a class without a footprint is taken as a point


def object_centres(
    observations: tuple[ObjectObservation, ...], footprints: dict[str, tuple[float, float]]
) -> np.ndarray:
    """(n, 3) stereo centres (camera frame) moved from the visible surface to the object's middle, along the viewing
    ray in the ground plane: otherwise a place driven the other way sees every object from its other side, a metre or
    two away, and a far view (the object's end) and a near one (its side) disagree. The depth to add is the radius of
    the class's footprint ellipse (length, width) in the direction of the ray, taking objects to lie along the road,
    that is along the robot's heading. The height is kept: the visible surface's centre is at the object's mid-height
    already, and a shift along the 3-D ray would move it by radius * height / distance, more for near views."""
    surface = np.array([o.center_camera for o in observations], dtype=float).reshape(-1, 3)
    bearing = np.arctan2(surface[:, 0], surface[:, 2])  # angle between the ray and the heading
    radius = footprint_radii([o.label for o in observations], bearing, footprints)
    ground = np.hypot(surface[:, 0], surface[:, 2])  # camera frame: x right, y down, z forward
    with np.errstate(divide="ignore", invalid="ignore"):
        scale = np.where(ground > 0, radius / ground, 0.0)
    shifted = surface.copy()
    shifted[:, [0, 2]] *= 1.0 + scale[:, None]
    return shifted


def view_covariances(rays: np.ndarray, relative_depth_sigma: np.ndarray, bearing_sigma: float) -> np.ndarray:
    """(n, 2, 2) ground-plane covariance of single stereo views of points at `rays` (n, 2) from the camera (world
    axes): along the ray the depth error, which scales the whole ray (std `relative_depth_sigma` x its length);
    across it the bearing error (std `bearing_sigma` rad x the length)."""
    length2 = np.maximum((rays**2).sum(axis=1), 1e-12)
    along = rays[:, :, None] * rays[:, None, :]  # r rᵀ: the ray direction times the length squared
    across = length2[:, None, None] * np.eye(2) - along  # (|r|² I - r rᵀ): the perpendicular, times the same
    return relative_depth_sigma[:, None, None] ** 2 * along + bearing_sigma**2 * across


@dataclass
class _WindowObject:
    label: str
    weighted_sum: np.ndarray
    weight: float
    patch_sum: np.ndarray
    observations: int
    last_seen_m: float  # odometer reading of the last observation
    settled: int = 0  # views whose track the motion detector found static (LocalObjectWindow.settle)
    # sum over views of weight² x the view's ground-plane covariance: the weighted mean's covariance times weight²
    spread: np.ndarray = field(default_factory=lambda: np.zeros((2, 2)))

    @property
    def position(self) -> np.ndarray:
        return self.weighted_sum / self.weight

    @property
    def covariance(self) -> np.ndarray:
        """(2, 2) ground-plane covariance of the position: that of a weighted mean of independent views."""
        return self.spread / self.weight**2


@dataclass(frozen=True)
class WindowViews:
    """The views of one window object: ground-plane points (n, 2), their stereo covariances (n, 2, 2), times (n,)
    and the robot's position (n, 2) at each."""

    points: np.ndarray
    covariances: np.ndarray
    times: np.ndarray
    robots: np.ndarray


@dataclass
class LocalObjectWindow:
    """Objects fused from the observations of the last `window_length` metres of travel."""

    config: KeyframeConfig
    marks_provisional: bool = False  # objects without a settled view are provisional in keyframes (`unjudged: wait`)
    objects: list[_WindowObject] = field(default_factory=list)
    # id(view) -> (view, the object it joined, its weighted point, its weight, its weighted covariance, when and
    # from where (robot x, y) it was seen), oldest first: what retract undoes and what a view's motion test reads.
    _taken: dict[int, tuple[ObjectObservation, _WindowObject, np.ndarray, float, np.ndarray, float, np.ndarray]] = (
        field(default_factory=dict)
    )
    _settled: set[int] = field(default_factory=set)  # id(view) of the settled views held in _taken

    def add(
        self, pose: np.ndarray, observations: tuple[ObjectObservation, ...], odometer_m: float, time: float = 0.0
    ) -> list[_WindowObject]:
        """Fuse one frame's observations, seen from robot pose T_world_robot at `time` (s), and forget stale
        objects; returns the window object each observation joined."""
        joined = []
        if observations:
            measured_depth = np.array([o.center_camera[2] for o in observations])
            rays = camera_points_to_robot(self._object_centres(observations)) @ pose[:3, :3].T
            world = rays + pose[:3, 3]
            # Stereo depth error grows with the measured depth squared: weight each view by its inverse variance,
            # or by the front end's own uncertainty of the centre where it measured a larger one.
            sigma = np.maximum(
                self.config.depth_sigma_at_1m * measured_depth**2,
                np.array([o.depth_sigma or 0.0 for o in observations]),
            )
            weights = 1.0 / sigma**2
            covariances = view_covariances(rays[:, :2], sigma / measured_depth, self.config.bearing_sigma)
            for observation, point, weight, covariance in zip(observations, world, weights, covariances, strict=True):
                joined.append(self._fuse(observation, point, float(weight), covariance, odometer_m))
                self._taken[id(observation)] = (
                    observation, joined[-1], weight * point, float(weight), weight**2 * covariance, time,
                    pose[:2, 3].copy(),
                )  # fmt: skip
        horizon = odometer_m - self.config.window_length
        kept = [o for o in self.objects if o.last_seen_m >= horizon]
        if len(kept) < len(self.objects):
            live = {id(o) for o in kept}
            self._taken = {k: v for k, v in self._taken.items() if id(v[1]) in live}
        self.objects = kept
        for oldest in list(self._taken)[: max(len(self._taken) - RETRACTABLE_VIEWS, 0)]:
            del self._taken[oldest]
        self._settled.intersection_update(self._taken)
        return joined

    def settle(self, observations: tuple[ObjectObservation, ...]) -> None:
        """Mark views fused earlier as views of a static object (their track was found static): with
        `marks_provisional`, a window object is provisional in keyframes until it holds one. Views no longer held
        are skipped."""
        for observation in observations:
            entry = self._taken.get(id(observation))
            if entry is None or entry[0] is not observation or id(observation) in self._settled:
                continue
            entry[1].settled += 1
            self._settled.add(id(observation))

    def retract(self, observations: tuple[ObjectObservation, ...]) -> int:
        """Take views fused earlier back out of their objects (views of an object since found moving); an object
        left without views leaves the window. Views no longer held are skipped. Returns the views taken out."""
        taken = 0
        for observation in observations:
            entry = self._taken.pop(id(observation), None)
            if entry is None or entry[0] is not observation:
                continue
            _, joined, weighted_point, weight, weighted_covariance, _, _ = entry
            joined.weighted_sum -= weighted_point
            joined.weight -= weight
            joined.spread -= weighted_covariance
            joined.patch_sum -= observation.patch
            joined.observations -= 1
            if id(observation) in self._settled:
                self._settled.discard(id(observation))
                joined.settled -= 1
            if joined.observations == 0:
                self.objects = [o for o in self.objects if o is not joined]
            taken += 1
        return taken

    def _object_centres(self, observations: tuple[ObjectObservation, ...]) -> np.ndarray:
        return object_centres(observations, self.config.footprints)

    def _fuse(
        self,
        observation: ObjectObservation,
        point: np.ndarray,
        weight: float,
        covariance: np.ndarray,
        odometer_m: float,
    ) -> _WindowObject:
        same_label = [o for o in self.objects if o.label == observation.label]
        if same_label:
            distances = [np.linalg.norm(o.position - point) for o in same_label]
            nearest = same_label[int(np.argmin(distances))]
            if min(distances) <= self.config.association_radius:
                nearest.weighted_sum += weight * point
                nearest.weight += weight
                nearest.spread += weight**2 * covariance
                nearest.patch_sum += observation.patch
                nearest.observations += 1
                nearest.last_seen_m = odometer_m
                return nearest
        joined = _WindowObject(
            observation.label,
            weight * point,
            weight,
            observation.patch.astype(float),
            1,
            odometer_m,
            spread=weight**2 * covariance,
        )
        self.objects.append(joined)
        return joined

    def views(self, objects: list[_WindowObject]) -> list[WindowViews]:
        """The views each of `objects` holds that the window still records (the latest RETRACTABLE_VIEWS)."""
        held: dict[int, list] = {id(o): [] for o in objects}
        for _, joined, weighted_point, weight, weighted_covariance, time, robot in self._taken.values():
            if id(joined) in held:
                held[id(joined)].append(
                    (weighted_point[:2] / weight, weighted_covariance[:2, :2] / weight**2, time, robot)
                )
        return [
            WindowViews(*(np.array(column) for column in zip(*held[id(o)], strict=True)))
            if held[id(o)]
            else WindowViews(np.zeros((0, 2)), np.zeros((0, 2, 2)), np.zeros(0), np.zeros((0, 2)))
            for o in objects
        ]

    def confirmed(self) -> list[_WindowObject]:
        """Objects seen often enough to trust (single sightings are mostly false positives)."""
        return [o for o in self.objects if o.observations >= self.config.min_observations]


@dataclass(frozen=True)
class KeyframeStep:
    """One frame through the keyframe builder: the observations it took, the window object each joined, the keyframe
    made (None when none was due or the window held too few objects) and the odometer after the frame."""

    frame_index: int
    observations: tuple[ObjectObservation, ...]
    joined: list[_WindowObject]
    keyframe: Keyframe | None
    odometer_m: float


class KeyframeBuilder:
    """Makes a keyframe every `spacing` metres of travel from the local window."""

    def __init__(self, config: KeyframeConfig, first_id: int = 0, marks_provisional: bool = False) -> None:
        """`marks_provisional`: a window object none of whose views the motion detector settled (found static) is
        provisional in keyframes: a car's track that breaks off before it is found moving, or a far car coming on
        whose first views are neither, leaves an object that is no contradiction to a match when it is missing."""
        self.config = config
        self.window = LocalObjectWindow(config, marks_provisional)
        self.odometer_m = 0.0
        self._next_keyframe_m = 0.0
        self.first_id = first_id  # ids continue those of a stored map
        self._next_id = first_id
        self.frames = array("l")  # the frame of every keyframe made (id - first_id is the position here)
        # Called after every frame with what it did (KeyframeStep): lets a benchmark or a tool follow the keyframes
        # without changing them; the pipeline itself adds none.
        self.observers: list[Callable[[KeyframeStep], None]] = []
        # Given the views of a provisional window object, whether they show it moving: such objects join no
        # keyframe (the pipeline sets the motion detector's test; None: every object joins).
        self.moves: Callable[[WindowViews], bool] | None = None

    def add(
        self, frame_index: int, pose: np.ndarray, observations, travelled_m: float, time: float = 0.0
    ) -> Keyframe | None:
        """Feed one frame (pose estimate and observations, `time` in s); returns a new keyframe when one is due."""
        self.odometer_m += travelled_m
        joined = self.window.add(pose, observations, self.odometer_m, time)
        keyframe = None
        if self.odometer_m >= self._next_keyframe_m:
            keyframe = self._make(frame_index, pose)
            if keyframe is not None:
                self._next_keyframe_m = self.odometer_m + self.config.spacing
        for observer in self.observers:
            observer(KeyframeStep(frame_index, tuple(observations), joined, keyframe, self.odometer_m))
        return keyframe

    def _make(self, frame_index: int, pose: np.ndarray) -> Keyframe | None:
        objects = self._still(self.window.confirmed())
        if not objects:
            return None
        positions = np.array([o.position for o in objects])
        current = int(np.argmin(np.linalg.norm(positions[:, :2] - pose[:2, 3], axis=1)))  # the current object
        around = self._neighbourhood(np.linalg.norm(positions - positions[current], axis=1))
        if len(around) < self.config.min_objects:
            return None
        keyframe = Keyframe(
            id=self._next_id,
            frame_index=frame_index,
            pose=pose.copy(),
            centers=positions[around],
            labels=tuple(objects[i].label for i in around),
            patches=np.array([objects[i].patch_sum / objects[i].observations for i in around]),
            provisional=np.array([objects[i].settled == 0 for i in around]) & self.window.marks_provisional,
            covariances=np.array([objects[i].covariance for i in around]),
        )
        self._next_id += 1
        self.frames.append(frame_index)
        return keyframe

    def _still(self, objects: list[_WindowObject]) -> list[_WindowObject]:
        """The objects without those provisional ones whose views show them moving (`moves`): a car's track that
        broke off before it was judged leaves a window object of its first views."""
        if self.moves is None or not self.window.marks_provisional:
            return objects
        provisional = [o for o in objects if o.settled == 0]
        moving = {
            id(o) for o, views in zip(provisional, self.window.views(provisional), strict=True) if self.moves(views)
        }
        return [o for o in objects if id(o) not in moving]

    def _neighbourhood(self, distances: np.ndarray) -> np.ndarray:
        """Indices of the objects within `neighbourhood_radius` of the current object; where fewer than
        `sparse_objects` stand that close (a sparse street), the radius grows until it holds them, up to
        `sparse_neighbourhood_radius`: a keyframe of barely `min_objects` rarely verifies, since every one of its
        objects must then be matched."""
        radius = self.config.neighbourhood_radius
        wanted = self.config.sparse_objects
        if np.count_nonzero(distances <= radius) < wanted:
            nearest = np.sort(distances)[min(wanted, len(distances)) - 1]
            radius = min(max(radius, nearest), self.config.sparse_neighbourhood_radius)
        return np.flatnonzero(distances <= radius)
