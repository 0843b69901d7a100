"""Which objects of the map are still where the map has them: a parked car leaves, and a route to it then leads to
an empty kerb.

An object is last seen from the latest experience (in the order experiences were made) that holds an observation
of it; that experience's session and frame say when. Since then, every experience the robot made from whose pose
the object lay in the camera's view (`navigation.view_min_range` to `view_range` away in the ground plane, within
half of `field_of_view_deg` of the robot's x axis) and which holds no observation of it is a miss; after
`navigation.stale_after_misses` misses the object is stale. Only experiences of the object's own part of the map
count (a session that never relocalised is in a frame of its own), and occlusion is not modelled: a miss behind a
lorry counts as much as a miss in plain view, which is why one miss is not enough.

What the map cannot tell: a later pass that re-entered the stored experiences (lifelong mapping makes no new ones
on a street driven again the same way) leaves a trace only where it saw something, so only experiences made after
the last sighting count as passes; and a sighting from a re-entered experience counts at that experience's place
in the order, when it was made.

The objects are kept as arrays (`MapObjects`), a row per object, so that a query filters thousands at once.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from neoslam.config import NavigationConfig
from neoslam.geometry import yaw_of
from neoslam.navigation.graph import NavigationGraph
from neoslam.navigation.view import MapView, object_positions

__all__ = ["MapObjects", "ObjectStatus", "map_objects", "object_statuses"]


@dataclass(frozen=True)
class ObjectStatus:
    """An object of the map as a goal: where it is, how often and when it was last seen, whether it is stale."""

    id: int
    label: str
    position: np.ndarray  # (3,) on the corrected map
    observations: int
    last_seen_experience: int  # the latest experience that holds an observation of it
    last_seen_session: int
    last_seen_frame: int  # the frame (of that session) the experience was made at
    sessions: frozenset[int]  # the sessions of the experiences that saw it
    misses: int  # experiences made since it was last seen that had it in view and did not see it
    stale: bool

    def describe(self) -> str:
        """`truck 12`, with `(stale)` when it is."""
        return f"{self.label} {self.id}" + (" (stale)" if self.stale else "")

    def last_seen(self) -> str:
        """`session 1, frame 230 (experience 41)`."""
        return (
            f"session {self.last_seen_session}, frame {self.last_seen_frame} (experience {self.last_seen_experience})"
        )


@dataclass(frozen=True)
class MapObjects:
    """The map's objects seen at least `min_observations` times, a row each, ids increasing."""

    ids: np.ndarray  # (k,) object ids
    labels: np.ndarray  # (k,) str, as the map has them
    keys: np.ndarray  # (k,) str, the labels in lower case (what a query names)
    positions: np.ndarray  # (k, 3)
    sigmas: np.ndarray  # (k,) each position's std, m: one over the root of its observations' summed weights
    observations: np.ndarray  # (k,)
    last_experience: np.ndarray  # (k,)
    last_session: np.ndarray  # (k,)
    last_frame: np.ndarray  # (k,)
    misses: np.ndarray  # (k,)
    stale: np.ndarray  # (k,) bool
    seen: np.ndarray  # (m, 2) rows and the sessions that saw them, each pair once, sorted
    sighted: np.ndarray  # (p, 2) rows and the experiences that saw them, each pair once, sorted

    def __len__(self) -> int:
        return len(self.ids)

    def row(self, object_id: int) -> int | None:
        """The row of an object id, None when it is not among them."""
        row = int(np.searchsorted(self.ids, object_id))
        return row if row < len(self.ids) and self.ids[row] == object_id else None

    def seen_in(self, session: int) -> np.ndarray:
        """(k,) whether each object was seen from an experience that `session` made."""
        mask = np.zeros(len(self), dtype=bool)
        mask[self.seen[self.seen[:, 1] == session, 0]] = True
        return mask

    def experiences_of(self, row: int) -> np.ndarray:
        """The experiences that saw the object of a row, increasing."""
        low, high = np.searchsorted(self.sighted[:, 0], [row, row + 1])
        return self.sighted[low:high, 1]

    def status(self, row: int) -> ObjectStatus:
        sessions = frozenset(int(s) for s in self.seen[self.seen[:, 0] == row, 1])
        return ObjectStatus(
            id=int(self.ids[row]),
            label=str(self.labels[row]),
            position=self.positions[row],
            observations=int(self.observations[row]),
            last_seen_experience=int(self.last_experience[row]),
            last_seen_session=int(self.last_session[row]),
            last_seen_frame=int(self.last_frame[row]),
            sessions=sessions,
            misses=int(self.misses[row]),
            stale=bool(self.stale[row]),
        )

    def statuses(self) -> list[ObjectStatus]:
        return [self.status(row) for row in range(len(self))]


def map_objects(view: MapView, graph: NavigationGraph, config: NavigationConfig, min_observations: int) -> MapObjects:
    """The map's objects seen at least `min_observations` times, with their staleness."""
    objects = view.objects
    n = len(objects.labels)
    counts = np.asarray(objects.counts[:n], dtype=int)
    seen = np.asarray(objects.pair_counts, dtype=int) > 0
    pair_object = np.asarray(objects.pair_object, dtype=int)[seen]
    pair_experience = np.asarray(objects.pair_experience, dtype=int)[seen]
    positions = object_positions(objects, view.poses)
    last = np.full(n, -1)
    np.maximum.at(last, pair_object, pair_experience)
    ids = np.flatnonzero((counts >= min_observations) & np.isfinite(positions).all(axis=1) & (last >= 0))
    misses = _misses(ids, positions[ids], last[ids], pair_object, pair_experience, view, graph, config)
    rows = np.full(n, -1)
    rows[ids] = np.arange(len(ids))
    labels = np.asarray(objects.labels, dtype=object)[ids] if n else np.zeros(0, dtype=object)
    weights = np.asarray(objects.weights[:n], dtype=float)[ids]
    return MapObjects(
        ids=ids,
        labels=labels,
        keys=np.char.lower(labels.astype(str)) if len(labels) else np.zeros(0, dtype=str),
        positions=positions[ids],
        sigmas=1.0 / np.sqrt(np.maximum(weights, np.finfo(float).tiny)),
        observations=counts[ids],
        last_experience=last[ids],
        last_session=graph.sessions[last[ids]],
        last_frame=graph.frames[last[ids]],
        misses=misses,
        stale=misses >= config.stale_after_misses,
        seen=_pairs(rows[pair_object], graph.sessions[pair_experience]),
        sighted=_pairs(rows[pair_object], pair_experience),
    )


def object_statuses(
    view: MapView, graph: NavigationGraph, config: NavigationConfig, min_observations: int
) -> list[ObjectStatus]:
    """Every object seen at least `min_observations` times, ids increasing, with its staleness."""
    return map_objects(view, graph, config, min_observations).statuses()


def _pairs(rows: np.ndarray, values: np.ndarray) -> np.ndarray:
    """(m, 2) each (row, value) pair once, sorted; observations of objects left out (row -1) dropped."""
    kept = rows >= 0
    span = int(values.max(initial=0)) + 1
    keys = np.unique(rows[kept] * span + values[kept])
    return np.column_stack([keys // span, keys % span]).astype(int).reshape(-1, 2)


def _misses(
    ids: np.ndarray,
    positions: np.ndarray,
    last: np.ndarray,
    pair_object: np.ndarray,
    pair_experience: np.ndarray,
    view: MapView,
    graph: NavigationGraph,
    config: NavigationConfig,
) -> np.ndarray:
    """Per object, the experiences made after its last sighting, in its part of the map, that had it in view and
    hold no observation of it. Vectorised over every (object, nearby experience) pair the KD-tree finds."""
    if len(ids) == 0 or len(graph) == 0:
        return np.zeros(len(ids), dtype=int)
    nearby = graph.tree.query_ball_point(positions[:, :2], config.view_range)
    lengths = np.fromiter((len(found) for found in nearby), dtype=int, count=len(ids))
    owner = np.repeat(np.arange(len(ids)), lengths)  # index into ids
    experience = np.fromiter((e for found in nearby for e in found), dtype=int, count=int(lengths.sum()))
    later = experience > last[owner]
    same_part = graph.components[experience] == graph.components[last[owner]]
    owner, experience = owner[later & same_part], experience[later & same_part]
    in_view = _in_view(positions[owner], view.poses[experience], config)
    owner, experience = owner[in_view], experience[in_view]
    observed = np.isin(ids[owner] * len(graph) + experience, pair_object * len(graph) + pair_experience)
    return np.bincount(owner[~observed], minlength=len(ids))


def _in_view(points: np.ndarray, poses: np.ndarray, config: NavigationConfig) -> np.ndarray:
    """Whether each point lies in the camera's view from each pose: in range and within half the field of view of
    the robot's x axis, in the ground plane."""
    offset = points[:, :2] - poses[:, :2, 3]
    heading = yaw_of(poses)
    forward = np.cos(heading) * offset[:, 0] + np.sin(heading) * offset[:, 1]
    left = -np.sin(heading) * offset[:, 0] + np.cos(heading) * offset[:, 1]
    distance = np.hypot(forward, left)
    bearing = np.abs(np.arctan2(left, forward))
    in_range = (distance >= config.view_min_range) & (distance <= config.view_range)
    return in_range & (bearing <= np.radians(config.field_of_view_deg) / 2)
