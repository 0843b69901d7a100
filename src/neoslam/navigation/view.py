"""What navigation reads of a map: a stored `MapState`, or a running `NeoSLAM` through its public parts (its
experience map and object map), without copying them.

Object positions follow the corrected map as the object map's own do (neoslam.mapping.object_map): each object's
observations are kept summed per (object, experience) in the experience's frame, and the corrected experience
poses move them to the map. An object counts once it was seen `object_map.min_observations` times (objects.csv
leaves out the others too: single sightings are mostly false detections).
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import dataclass

import numpy as np

from neoslam.pipeline import NeoSLAM
from neoslam.types import Experience, Link, MapState, ObjectMapState, SessionRecord

__all__ = ["MapSource", "MapView", "map_view", "object_positions", "pose_in_map"]

MapSource = MapState | NeoSLAM  # what a route is planned on


@dataclass(frozen=True)
class MapView:
    """A map as navigation reads it (the arrays are the map's own, not copies: read them, never change them)."""

    experiences: Sequence[Experience]  # ids 0..n-1, in the order they were made
    poses: np.ndarray  # (n, 4, 4) corrected experience poses T_map_robot
    links: Sequence[Link]  # every link made, withdrawn ones too (a link keeps its index)
    withdrawn: Sequence[int]  # loop links withdrawn from the map (indices into links): no road
    keyframe_experience: Mapping[int, int]  # keyframe id -> the experience made with it
    objects: ObjectMapState
    sessions: tuple[SessionRecord, ...]
    current: int | None  # the experience a running robot is in; None for a stored map
    localised: bool  # whether a running robot's pose is in the map's frame (a stored map: True)

    def __len__(self) -> int:
        return len(self.experiences)

    @property
    def positions(self) -> np.ndarray:
        """(n, 3) corrected experience positions."""
        return self.poses[:, :3, 3]


def map_view(source: MapSource) -> MapView:
    """The map of a stored `MapState` or of a running `NeoSLAM` (its live experience map and object map)."""
    if isinstance(source, NeoSLAM):
        return _running(source)
    if isinstance(source, MapState):
        return MapView(
            experiences=source.experiences,
            poses=np.asarray(source.experience_poses, dtype=float).reshape(-1, 4, 4),
            links=source.links,
            withdrawn=source.withdrawn_links,
            keyframe_experience=source.keyframe_experience,
            objects=source.objects,
            sessions=tuple(source.sessions),
            current=None,
            localised=True,
        )
    raise TypeError(f"a route is planned on a MapState or a NeoSLAM, not a {type(source).__name__}")


def _running(slam: NeoSLAM) -> MapView:
    """A running system's map: its session is in the map's frame once it relocalised (the first session's frame is
    the map's)."""
    experience_map = slam.experience_map
    session = slam.session_record()
    current = experience_map.current
    return MapView(
        experiences=experience_map.experiences,
        poses=experience_map.graph.poses,
        links=experience_map.graph.links,
        withdrawn=experience_map.withdrawn_links,
        keyframe_experience=experience_map.keyframe_experiences,
        objects=slam.object_map.state(),
        sessions=(*slam.stored.sessions, session),
        current=current if current >= 0 else None,
        localised=session.id == 1 or session.relocalised_frame is not None,
    )


def pose_in_map(slam: NeoSLAM, pose: np.ndarray) -> np.ndarray | None:
    """The pose `NeoSLAM.step` returned, if it is in the map's frame (the first session, or a later one once it
    relocalised); None before: guidance then says the robot is not localised."""
    session = slam.session
    return pose if session.id == 1 or session.relocalised_frame is not None else None


def object_positions(objects: ObjectMapState, poses: np.ndarray) -> np.ndarray:
    """(k, 3) every object's position on the corrected map: its observations' sums moved by the poses of the
    experiences they were made in, over its weight (an object merged away or forgotten: NaN)."""
    n = len(objects.labels)
    weights = np.asarray(objects.weights[:n], dtype=float)
    sums = np.array(objects.sums[:n], dtype=float)
    if len(objects.pair_object):
        sums = np.zeros((n, 3))
        anchors = poses[np.asarray(objects.pair_experience, dtype=int)]
        moved = np.einsum("nij,nj->ni", anchors[:, :3, :3], np.asarray(objects.pair_sums, dtype=float))
        moved += np.asarray(objects.pair_weights, dtype=float)[:, None] * anchors[:, :3, 3]
        np.add.at(sums, np.asarray(objects.pair_object, dtype=int), moved)
    live = (np.asarray(objects.counts[:n]) > 0) & (weights > 0)
    positions = np.full((n, 3), np.nan)
    positions[live] = sums[live] / weights[live, None]
    return positions
