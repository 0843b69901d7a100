"""Relocalisation in a stored map: a run as a later session of a map kept in a file (beyond the paper; the map
file is neoslam.store).

The run starts from the stored map's experiences, objects, Hebbian associations and OVCN, in a part of the map of
its own and in its own frame. The stored keyframes wait in the relocaliser, which matches each new keyframe against
the whole stored map (the session's pose relative to it is unknown). The keyframe's own accepted closure joins the
session's part to the stored one: the session moves into the map's frame (and the system's cells take the stored
place's cell state), and the stored part's keyframes move to the session's loop detector (in its odometry frame,
within the drift-bounded radius from then on). A map with one part per session that never relocalised is joined
part by part.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from neoslam.config import NeoSLAMConfig
from neoslam.geometry import invert_pose
from neoslam.loop.detector import LoopClosureDetector
from neoslam.loop.index import KeyframeIndex
from neoslam.loop.relocaliser import MapRelocaliser
from neoslam.mapping.experience_map import ExperienceMap
from neoslam.types import Keyframe, LoopClosure

__all__ = ["Relocalisation", "StoredMapRelocalisation"]


@dataclass(frozen=True, slots=True)
class Relocalisation:
    """A new keyframe's closures with the stored map, and the one (if any) that joined the robot's part of the map
    to a stored part: the cells then take that stored place's state."""

    closures: list[LoopClosure]
    joined: LoopClosure | None = None


class StoredMapRelocalisation:
    """The stored keyframes of the parts of the map the session has not joined, searched whole for each new keyframe.

    It works on the two components a join changes: the experience map (which joins the parts and moves the
    session into the map's frame) and the loop detector (which takes the joined part's keyframes)."""

    def __init__(
        self,
        config: NeoSLAMConfig,
        stored_keyframes: list[Keyframe],
        experience_map: ExperienceMap,
        loop_detector: LoopClosureDetector,
    ) -> None:
        """`stored_keyframes` in the odometry frames they were made in; the experience map restored from the same
        stored map (its corrections move them to the map's frame)."""
        self.config = config
        self.experience_map = experience_map
        self.loop_detector = loop_detector
        self.stored_keyframes = stored_keyframes
        self.relocaliser = self._search(stored_keyframes if experience_map.experiences else [])

    def __len__(self) -> int:
        return len(self.relocaliser)

    def _search(self, keyframes: list[Keyframe]) -> MapRelocaliser:
        in_map = [self._in_map_frame(keyframe) for keyframe in keyframes]
        return MapRelocaliser(self.config.keyframes, self.config.matching, self.config.map_store, in_map)

    def _in_map_frame(self, keyframe: Keyframe, frame: np.ndarray | None = None) -> Keyframe:
        """A stored keyframe moved from the odometry frame it was made in to the corrected map's frame (then, with
        `frame` = T_frame_map, on to another frame)."""
        moved = self.experience_map.correction(self.experience_map.experience_of(keyframe.id))
        if frame is not None:
            moved = frame @ moved
        return keyframe.moved(moved)

    def relocalise(self, keyframe: Keyframe, odometry: np.ndarray, odometer_m: float) -> Relocalisation:
        """Closures of a new keyframe with the stored keyframes of parts the session has not joined; its own
        closure joins the two parts (the first such join is the session's relocalisation)."""
        experience_map = self.experience_map
        if not len(self.relocaliser) or experience_map.current < 0:  # nothing to search, or no pose yet
            return Relocalisation([])
        closures = self.relocaliser.query(keyframe, odometer_m)
        own = next((c for c in closures if c.query_keyframe == keyframe.id), None)
        if own is None:
            return Relocalisation(closures)
        joined = own if experience_map.join(own, experience_map.current_pose(odometry)) else None
        map_from_odometry = experience_map.current_pose(odometry) @ invert_pose(odometry)
        self._take_joined_keyframes(map_from_odometry, odometer_m)
        return Relocalisation(closures, joined)

    def _take_joined_keyframes(self, map_from_odometry: np.ndarray, odometer_m: float) -> None:
        """Stored keyframes now in the robot's part of the map go to the loop detector (in this session's odometry
        frame, as its own keyframes are, and old enough to be recognised at once); the others stay to be searched."""
        experience_map = self.experience_map
        part = experience_map.parts.part_of(experience_map.current)
        joined, waiting = [], []
        for keyframe in self.stored_keyframes:
            if keyframe.id in self.relocaliser.index.keyframes:
                here = experience_map.parts.part_of(experience_map.experience_of(keyframe.id)) == part
                (joined if here else waiting).append(keyframe)
        if not joined:
            return
        index = self.loop_detector.index
        odometer = odometer_m - self.config.matching.exclude_recent_distance
        to_odometry = invert_pose(map_from_odometry)
        entries = [(self._in_map_frame(k, to_odometry), odometer) for k in joined]
        entries += [(k, index.odometer(k.id)) for k in index.keyframes]
        self.loop_detector.index = KeyframeIndex(self.config.matching)
        for keyframe, reading in sorted(entries, key=lambda entry: entry[0].id):  # ids must increase
            self.loop_detector.index.add(keyframe, reading)
        self.relocaliser = self._search(waiting)
