"""The object map: every observation moved to the world with the current pose estimate and fused with the
nearest object of the same label. Each observation is also kept relative to the experience it was made in, so that
the map follows the experience map's correction. The stereo centre is first moved from the visible surface to the
object's middle (class footprints, as keyframes do), objects are the inverse-variance weighted means of their
views (stereo depth error grows with depth squared), and a view joins an object inside a gate that is the
association radius across the viewing ray, longer along it for a far view, and `height_tolerance` in height.

A robot that drives its streets every day must end with the same map, not a growing copy of it (lifelong mapping):
- observations are associated against the objects where the *corrected* map has them (the map is refreshed
  whenever the experience map has moved by more than REFRESH_SHIFT_M since the last refresh), through a spatial
  hash of cells as large as the association radius (cost per observation independent of the map's size);
- a correction (a loop closure) brings the objects seen again before the robot knew where it was onto the stored
  ones: after each refresh, objects of one label whose corrected positions lie within the association radius in
  the ground plane (and `height_tolerance` in height) are merged (their observations joined; the older id stays);
- objects whose means have converged within the association radius are merged every MERGE_EVERY_M of travel too;
- an object seen fewer than `min_observations` times within `tentative_distance` metres of travel is forgotten: a
  false detection, or an object glimpsed once a pass, would otherwise pile up into an object over the passes;
- objects of two parts of the experience map (a later session before it relocalises, and the stored map) are never
  associated or merged: the parts' frames both start at their session's first pose, so equal coordinates there
  are not one place. Once the parts join, the refresh merges the objects the session saw twice.
Observations are kept summed per (object, experience), so memory grows with the map, not with the frames.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy.spatial import cKDTree

from neoslam.config import ObjectMapConfig
from neoslam.geometry import camera_points_to_robot, transform_points
from neoslam.loop.keyframes import object_centres
from neoslam.types import ObjectMapState, ObjectObservation

__all__ = ["MapObject", "ObjectMap", "depth_sigmas"]


@dataclass(frozen=True, slots=True)
class MapObject:
    id: int
    label: str
    position: np.ndarray  # (3,) world frame, mean of its observations
    observations: int


REFRESH_SHIFT_M = 0.5  # refresh the corrected object positions once an experience has moved this far
INITIAL_CAPACITY = 256
FORGET_EVERY_M = 5.0  # look for tentative objects to forget once per this much travel
MERGE_EVERY_M = 50.0  # and for objects whose means have come within the association radius, once per this much


def depth_sigmas(observations: tuple[ObjectObservation, ...], config: ObjectMapConfig) -> np.ndarray:
    """Std of each observed centre along its viewing ray: stereo depth error grows with depth squared (or the front
    end's own measure, when larger), and no centre is known better than `position_sigma_floor` (the visible surface,
    not the object's middle)."""
    depth = np.array([o.center_camera[2] for o in observations], dtype=float)
    measured = np.array([o.depth_sigma or 0.0 for o in observations], dtype=float)
    stereo = config.depth_sigma_at_1m * depth**2
    return np.maximum(np.maximum(stereo, measured), config.position_sigma_floor)


def _grown(array: np.ndarray, size: int) -> np.ndarray:
    """The array with room for `size` rows (capacity doubled as needed)."""
    if size <= len(array):
        return array
    capacity = max(len(array), 1)
    while capacity < size:
        capacity *= 2
    grown = np.zeros((capacity, *array.shape[1:]), dtype=array.dtype)
    grown[: len(array)] = array
    return grown


class ObjectMap:
    """Objects fused from observations; grows with the streets the robot has seen, not with the passes."""

    def __init__(self, config: ObjectMapConfig, footprints: dict[str, tuple[float, float]] | None = None) -> None:
        self.config = config
        self.footprints = footprints  # class footprints: observed centres are moved to the object's middle
        self._labels: list[str] = []
        self._n = 0  # objects ever made; an object merged into another or forgotten keeps its row with count 0
        self._sums = np.zeros((INITIAL_CAPACITY, 3))  # weighted world sums of its observations (map as refreshed)
        self._weights = np.zeros(INITIAL_CAPACITY)  # sum of its observations' weights
        self._counts = np.zeros(INITIAL_CAPACITY, dtype=int)
        self._last_seen = np.zeros(INITIAL_CAPACITY)  # odometer reading of the last observation, m
        self._home = np.zeros(INITIAL_CAPACITY, dtype=int)  # an experience it was seen from: names its map part
        self._tentative: set[int] = set()  # objects not yet seen min_observations times
        # Observations summed per (object, experience), in the experience's frame: the map follows the correction.
        self._pair_rows: dict[tuple[int, int], int] = {}
        self._p = 0
        self._pair_object = np.zeros(INITIAL_CAPACITY, dtype=int)
        self._pair_anchor = np.zeros(INITIAL_CAPACITY, dtype=int)
        self._pair_sums = np.zeros((INITIAL_CAPACITY, 3))
        self._pair_weights = np.zeros(INITIAL_CAPACITY)
        self._pair_counts = np.zeros(INITIAL_CAPACITY, dtype=int)
        self._compacted_at = INITIAL_CAPACITY
        self._cells: dict[tuple[str, int, int], set[int]] = {}  # spatial hash of the live objects' means
        self._cell_of: dict[int, tuple[str, int, int]] = {}
        self._refreshed_positions: np.ndarray | None = None  # experience positions at the last refresh
        self._forgotten_at = -np.inf
        # (merged away, kept) of every merge in order: a landmark back end (neoslam.mapping.landmarks) follows them
        self.merges: list[tuple[int, int]] = []
        self._merged_at = 0.0

    def __len__(self) -> int:
        """Live objects (seen at least once, not merged into another, not forgotten)."""
        return int(np.count_nonzero(self._counts[: self._n]))

    def add(
        self,
        pose: np.ndarray,
        observations: tuple[ObjectObservation, ...],
        anchor: int = 0,
        anchor_from_robot: np.ndarray | None = None,
        odometer_m: float | None = None,
        parts: np.ndarray | None = None,
    ) -> list[int]:
        """Fuse one frame's observations seen from robot pose T_world_robot; returns their object ids. `anchor`
        names the experience the frame belongs to and `anchor_from_robot` the robot pose in its frame;
        `odometer_m`, the distance travelled, lets tentative objects be forgotten (None: never); `parts`, the map
        part of every experience (MapParts.labels), keeps the objects of other parts apart (None: one part)."""
        if odometer_m is not None:
            self._forget(odometer_m)
            if odometer_m - self._merged_at >= MERGE_EVERY_M:  # copies made before their views converged
                self._merged_at = odometer_m
                self._merge(np.flatnonzero(self._counts[: self._n] > 0), parts)
        if not observations:
            return []
        centres = np.array([o.center_camera for o in observations], dtype=float)
        if self.footprints is not None:
            centres = object_centres(observations, self.footprints)
        in_robot = camera_points_to_robot(centres)
        world = transform_points(pose, in_robot)
        relative = transform_points(np.eye(4) if anchor_from_robot is None else anchor_from_robot, in_robot)
        rays = world[:, :2] - pose[:2, 3]  # in the ground plane; the robot frame's origin is the camera's
        rays /= np.maximum(np.linalg.norm(rays, axis=1, keepdims=True), 1e-9)
        sigmas = depth_sigmas(observations, self.config)
        ids = []
        for observation, point, local, ray, sigma in zip(observations, world, relative, rays, sigmas, strict=True):
            index = self._associate(observation.label, point, ray, float(sigma), anchor, parts)
            self._add_to_pair(index, anchor, local, 1.0 / sigma**2)
            if odometer_m is not None:
                self._last_seen[index] = odometer_m
            ids.append(index)
        return ids

    def _mean(self, index: int) -> np.ndarray:
        return self._sums[index] / self._weights[index]

    def _cell(self, label: str, point: np.ndarray) -> tuple[str, int, int]:
        x, y = np.floor(point[:2] / self.config.association_radius).astype(int)
        return label, int(x), int(y)

    def _place(self, index: int) -> None:
        """(Re)file a live object in the spatial hash under its current mean."""
        cell = self._cell(self._labels[index], self._mean(index))
        previous = self._cell_of.get(index)
        if previous == cell:
            return
        if previous is not None:
            self._leave(previous, index)
        self._cells.setdefault(cell, set()).add(index)
        self._cell_of[index] = cell

    def _unplace(self, index: int) -> None:
        cell = self._cell_of.pop(index, None)
        if cell is not None:
            self._leave(cell, index)

    def _leave(self, cell: tuple[str, int, int], index: int) -> None:
        members = self._cells[cell]
        members.discard(index)
        if not members:  # no empty cells: the hash holds the map, not every place an object ever was
            del self._cells[cell]

    def _associate(
        self, label: str, position: np.ndarray, ray: np.ndarray, sigma: float, anchor: int, parts: np.ndarray | None
    ) -> int:
        """The nearest live object of the label and of the anchor's map part inside the observation's gate (then
        updated), or a new one. In the ground plane the gate is the association radius across the viewing ray and,
        along it, `gate_sigmas` depth stds if that is more (a far stereo centre is off mostly along the ray); in
        height, `height_tolerance` if that is more than the radius (objects stand on the road, and a pitch or
        height error of the pose moves a far view up or down). Nearest in distance scaled by the gate."""
        radius = self.config.association_radius
        along_gate = max(radius, self.config.gate_sigmas * sigma)
        height_gate = max(radius, self.config.height_tolerance)
        reach = int(np.ceil(along_gate / radius))
        _, x, y = self._cell(label, position)
        part = None if parts is None else parts[anchor]
        nearest, nearest_score = -1, 1.0
        for dx in range(-reach, reach + 1):
            for dy in range(-reach, reach + 1):
                for index in self._cells.get((label, x + dx, y + dy), ()):
                    if part is not None and parts[self._home[index]] != part:
                        continue
                    offset = self._mean(index) - position
                    along = float(offset[:2] @ ray)
                    across_squared = max(float(offset[:2] @ offset[:2]) - along * along, 0.0)
                    score = (along / along_gate) ** 2 + across_squared / radius**2 + (offset[2] / height_gate) ** 2
                    if score < nearest_score or (score == nearest_score and (nearest < 0 or index < nearest)):
                        nearest, nearest_score = index, score
        weight = 1.0 / sigma**2
        if nearest < 0:
            nearest = self._n
            self._n += 1
            self._labels.append(label)
            self._sums = _grown(self._sums, self._n)
            self._weights = _grown(self._weights, self._n)
            self._counts = _grown(self._counts, self._n)
            self._last_seen = _grown(self._last_seen, self._n)
            self._home = _grown(self._home, self._n)
            self._home[nearest] = anchor
            if self.config.min_observations > 1:
                self._tentative.add(nearest)
        self._sums[nearest] += weight * position
        self._weights[nearest] += weight
        self._counts[nearest] += 1
        if self._counts[nearest] >= self.config.min_observations:
            self._tentative.discard(nearest)
        self._place(nearest)
        return nearest

    def _add_to_pair(self, index: int, anchor: int, local: np.ndarray, weight: float) -> None:
        row = self._pair_rows.get((index, anchor))
        if row is None:
            row = self._p
            self._p += 1
            self._pair_rows[(index, anchor)] = row
            self._pair_object = _grown(self._pair_object, self._p)
            self._pair_anchor = _grown(self._pair_anchor, self._p)
            self._pair_sums = _grown(self._pair_sums, self._p)
            self._pair_weights = _grown(self._pair_weights, self._p)
            self._pair_counts = _grown(self._pair_counts, self._p)
            self._pair_object[row], self._pair_anchor[row] = index, anchor
        self._pair_sums[row] += weight * local
        self._pair_weights[row] += weight
        self._pair_counts[row] += 1

    def _forget(self, odometer_m: float) -> None:
        """Forget the tentative objects not seen for `tentative_distance` metres (checked every few metres)."""
        if odometer_m - self._forgotten_at < FORGET_EVERY_M:
            return
        self._forgotten_at = odometer_m
        horizon = odometer_m - self.config.tentative_distance
        stale = [index for index in self._tentative if self._last_seen[index] < horizon]
        for index in stale:
            self._tentative.discard(index)
            self._counts[index] = 0
            self._sums[index], self._weights[index] = 0.0, 0.0
            self._unplace(index)
        if stale and self._p >= 2 * self._compacted_at:
            self._compact()

    def _compact(self) -> None:
        """Drop the observation sums of objects that are gone (merged pairs are already re-filed)."""
        keep = np.flatnonzero(self._counts[self._pair_object[: self._p]] > 0)
        self._pair_object = self._pair_object[keep]
        self._pair_anchor = self._pair_anchor[keep]
        self._pair_sums = self._pair_sums[keep]
        self._pair_weights = self._pair_weights[keep]
        self._pair_counts = self._pair_counts[keep]
        self._p = len(keep)
        pairs = zip(self._pair_object, self._pair_anchor, strict=True)
        self._pair_rows = {(int(o), int(a)): row for row, (o, a) in enumerate(pairs)}
        self._compacted_at = max(self._p, INITIAL_CAPACITY)

    def _anchored_sums(self, anchor_poses: np.ndarray) -> np.ndarray:
        """Per object, the weighted sum of its observations moved to the world with the given experience poses."""
        sums = np.zeros((self._n, 3))
        rows = slice(0, self._p)
        anchors = anchor_poses[self._pair_anchor[rows]]
        moved = np.einsum("nij,nj->ni", anchors[:, :3, :3], self._pair_sums[rows])
        moved += self._pair_weights[rows, None] * anchors[:, :3, 3]
        np.add.at(sums, self._pair_object[rows], moved)
        sums[self._counts[: self._n] == 0] = 0.0
        return sums

    def refresh(self, anchor_poses: np.ndarray, force: bool = False, parts: np.ndarray | None = None) -> int:
        """Follow the corrected map: on the first call, once an experience has moved more than REFRESH_SHIFT_M since
        the last refresh (or since it was first given), or with `force`, recompute every object from its
        observations and merge the objects of one label and one map part (`parts`, as for `add`) that now lie
        within the association radius of each other. Returns the number of objects merged away."""
        positions = anchor_poses[:, :3, 3]
        previous = self._refreshed_positions
        force = force or previous is None  # the first refresh: the poses the objects were seen with are unknown
        if previous is None or len(previous) < len(positions):  # new experiences: the objects were seen from there
            start = 0 if previous is None else len(previous)
            previous = np.concatenate([np.zeros((0, 3)) if previous is None else previous, positions[start:]])
            self._refreshed_positions = previous
        if not force and np.abs(positions - previous[: len(positions)]).max(initial=0.0) < REFRESH_SHIFT_M:
            return 0
        self._refreshed_positions = positions.copy()
        if self._p == 0:
            return 0
        self._sums[: self._n] = self._anchored_sums(anchor_poses)
        live = np.flatnonzero(self._counts[: self._n] > 0)
        for index in live:
            self._place(int(index))
        return self._merge(live, parts)

    def _merge(self, live: np.ndarray, parts: np.ndarray | None) -> int:
        """Merge live objects of one label and one map part closer than the association radius, nearest pairs
        first; each merge checks the distance between the merged means, so a chain of objects does not collapse
        into one."""
        if len(live) < 2:
            return 0
        radius = self.config.association_radius
        height_gate = max(radius, self.config.height_tolerance)
        means = self._sums[live] / self._weights[live, None]
        pairs = cKDTree(means[:, :2]).query_pairs(radius, output_type="ndarray")
        labels = np.asarray(self._labels)[live]
        same_label = labels[pairs[:, 0]] == labels[pairs[:, 1]]
        level = np.abs(means[pairs[:, 0], 2] - means[pairs[:, 1], 2]) <= height_gate
        pairs = pairs[same_label & level]
        if parts is not None:
            homes = parts[self._home[live]]
            pairs = pairs[homes[pairs[:, 0]] == homes[pairs[:, 1]]]
        if len(pairs) == 0:
            return 0
        order = np.argsort(np.linalg.norm(means[pairs[:, 0], :2] - means[pairs[:, 1], :2], axis=1), kind="stable")
        root = np.arange(self._n)

        def find(index: int) -> int:
            while root[index] != index:
                index = int(root[index])
            return index

        merged = 0
        for a, b in live[pairs[order]]:
            keep, gone = sorted((find(int(a)), find(int(b))))
            if keep == gone:
                continue
            offset = self._mean(keep) - self._mean(gone)
            if np.linalg.norm(offset[:2]) > radius or abs(offset[2]) > height_gate:
                continue
            self._sums[keep] += self._sums[gone]
            self._weights[keep] += self._weights[gone]
            self._counts[keep] += self._counts[gone]
            self._last_seen[keep] = max(self._last_seen[keep], self._last_seen[gone])
            self._sums[gone], self._weights[gone], self._counts[gone] = 0.0, 0.0, 0
            root[gone] = keep
            self.merges.append((int(gone), int(keep)))
            self._tentative.discard(gone)
            if self._counts[keep] >= self.config.min_observations:
                self._tentative.discard(keep)
            self._unplace(gone)
            self._place(keep)
            merged += 1
        if merged:
            self._refile_pairs(root, find)
        return merged

    def _refile_pairs(self, root: np.ndarray, find) -> None:
        """Move the observation sums of merged objects to the objects they joined, one row per (object, experience)."""
        for index in range(self._n):
            root[index] = find(index)
        objects = root[self._pair_object[: self._p]]
        anchors = self._pair_anchor[: self._p]
        keys, inverse = np.unique(np.stack([objects, anchors], axis=1), axis=0, return_inverse=True)
        inverse = inverse.ravel()
        sums = np.zeros((len(keys), 3))
        weights = np.zeros(len(keys))
        counts = np.zeros(len(keys), dtype=int)
        np.add.at(sums, inverse, self._pair_sums[: self._p])
        np.add.at(weights, inverse, self._pair_weights[: self._p])
        np.add.at(counts, inverse, self._pair_counts[: self._p])
        self._p = len(keys)
        self._pair_object, self._pair_anchor = keys[:, 0].copy(), keys[:, 1].copy()
        self._pair_sums, self._pair_weights, self._pair_counts = sums, weights, counts
        self._pair_rows = {(int(o), int(a)): row for row, (o, a) in enumerate(keys)}

    def state(self) -> ObjectMapState:
        """The map's arrays (views, not copies: a map file writes them at once)."""
        n, p = self._n, self._p
        return ObjectMapState(
            labels=self._labels,
            sums=self._sums[:n],
            weights=self._weights[:n],
            counts=self._counts[:n],
            pair_object=self._pair_object[:p],
            pair_experience=self._pair_anchor[:p],
            pair_sums=self._pair_sums[:p],
            pair_weights=self._pair_weights[:p],
            pair_counts=self._pair_counts[:p],
        )

    def restore(self, state: ObjectMapState) -> None:
        """Take the objects of a stored map. Their positions follow the map from the first refresh on; an object
        not yet confirmed when the map was stored is forgotten unless this session sees it again soon."""
        self._labels = list(state.labels)
        self._n, self._p = len(self._labels), len(state.pair_object)
        self._sums = _grown(np.array(state.sums, float), self._n)
        self._weights = _grown(np.array(state.weights, float), self._n)
        self._counts = _grown(np.array(state.counts, dtype=int), self._n)
        self._last_seen = np.zeros(len(self._counts))
        self._pair_object = _grown(np.array(state.pair_object, dtype=int), self._p)
        self._pair_anchor = _grown(np.array(state.pair_experience, dtype=int), self._p)
        self._pair_sums = _grown(np.array(state.pair_sums, float), self._p)
        self._pair_weights = _grown(np.array(state.pair_weights, float), self._p)
        self._pair_counts = _grown(np.array(state.pair_counts, dtype=int), self._p)
        pairs = zip(self._pair_object[: self._p], self._pair_anchor[: self._p], strict=True)
        self._pair_rows = {(int(o), int(a)): row for row, (o, a) in enumerate(pairs)}
        self._home = np.zeros(len(self._counts), dtype=int)
        self._home[self._pair_object[: self._p]] = self._pair_anchor[: self._p]  # any of its experiences will do
        self._compacted_at = max(self._p, INITIAL_CAPACITY)
        live = self._counts[: self._n] > 0
        self._tentative = set(np.flatnonzero(live & (self._counts[: self._n] < self.config.min_observations)).tolist())
        self._cells.clear()
        self._cell_of.clear()
        for index in np.flatnonzero(live):
            self._place(int(index))
        self._refreshed_positions = None  # the first refresh recomputes every object on the corrected map

    def objects(self, anchor_poses: np.ndarray | None = None) -> list[MapObject]:
        """Objects seen at least min_observations times (single sightings are mostly false positives); with
        `anchor_poses` (the corrected experience poses) their observations follow the corrected map."""
        counts, weights = self._counts[: self._n], self._weights[: self._n]
        sums = self._sums[: self._n] if anchor_poses is None or self._p == 0 else self._anchored_sums(anchor_poses)
        return [
            MapObject(i, self._labels[i], sums[i] / weights[i], int(counts[i]))
            for i in range(self._n)
            if counts[i] >= self.config.min_observations
        ]
