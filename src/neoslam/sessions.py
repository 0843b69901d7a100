"""A run as a later session of a stored map (beyond the paper; the map file is neoslam.store).

The run starts from the stored map's experiences, objects, Hebbian associations and OVCN, in a part of the map of
its own and in its own frame. The stored keyframes wait in the relocaliser, which matches each new keyframe against
the whole stored map (the session's pose relative to it is unknown). The keyframe's own accepted closure joins the
session's part to the stored one: the session moves into the map's frame, its cells take the stored place's cell
state, and the stored part's keyframes move to the session's loop detector (in its odometry frame, within the
drift-bounded radius from then on). A map with one part per session that never relocalised is joined part by part.
"""

from __future__ import annotations

from dataclasses import replace
from typing import TYPE_CHECKING

import numpy as np

from neoslam.cells.place import offset_in_cells
from neoslam.config import NeoSLAMConfig
from neoslam.geometry import invert_pose
from neoslam.loop.index import KeyframeIndex
from neoslam.loop.relocaliser import MapRelocaliser
from neoslam.types import Keyframe, LoopClosure, MapState, SessionRecord, StoredClosure

if TYPE_CHECKING:
    from neoslam.pipeline import NeoSLAM

__all__ = ["StoredMap"]


class StoredMap:
    """The map a run started from (empty for the first session) and this run as its next session."""

    def __init__(self, config: NeoSLAMConfig, stored: MapState, session_name: str) -> None:
        self.config = config
        self.stored = stored
        self.session = SessionRecord(stored.next_session, session_name, 0, None)
        self.relocaliser = MapRelocaliser(config.keyframes, config.matching, config.map_store, [])
        self._weights: tuple[int, dict[str, np.ndarray]] = (-1, {})  # the OVCN's, by epochs learnt

    def restore(self, slam: NeoSLAM) -> None:
        """Start `slam` from the stored map: experiences, objects, associations and the OVCN as stored; the stored
        keyframes wait in the relocaliser, in the map's frame."""
        stored = self.stored
        if not stored.experiences:
            return
        slam.experience_map.restore(stored, self.session.id)
        slam.object_map.restore(stored.objects)
        slam.hebbian.restore(stored.hebbian, slam.grid_cells.dims, slam.head_direction.cells)
        if stored.object_vector_weights:
            slam.object_vector_cells.restore(stored.object_vector_weights, stored.object_vector_losses)
        self._search(slam, stored.keyframes)

    def _search(self, slam: NeoSLAM, keyframes: list[Keyframe]) -> None:
        in_map = [self._in_map_frame(slam, keyframe) for keyframe in keyframes]
        self.relocaliser = MapRelocaliser(self.config.keyframes, self.config.matching, self.config.map_store, in_map)

    @staticmethod
    def _in_map_frame(slam: NeoSLAM, keyframe: Keyframe, frame: np.ndarray | None = None) -> Keyframe:
        """A stored keyframe moved from the odometry frame it was made in to the corrected map's frame (then, with
        `frame` = T_frame_map, on to another frame)."""
        moved = slam.experience_map.correction(slam.experience_map.experience_of(keyframe.id))
        if frame is not None:
            moved = frame @ moved
        return keyframe.moved(moved)

    def relocalise(
        self, slam: NeoSLAM, frame_index: int, keyframe: Keyframe, odometry: np.ndarray
    ) -> list[LoopClosure]:
        """Closures of a new keyframe with the stored keyframes of parts the session has not joined; its own
        closure joins the two parts (the first such join is the session's relocalisation)."""
        experience_map = slam.experience_map
        if not len(self.relocaliser) or experience_map.current < 0:  # nothing to search, or no pose yet
            return []
        closures = self.relocaliser.query(keyframe, slam.keyframes.odometer_m)
        own = next((c for c in closures if c.query_keyframe == keyframe.id), None)
        if own is None:
            return closures
        if experience_map.join(own, experience_map.current_pose(odometry)):
            self._reset_cells(slam, own)
            if self.session.relocalised_frame is None:
                self.session = replace(self.session, relocalised_frame=frame_index)
        map_from_odometry = experience_map.current_pose(odometry) @ invert_pose(odometry)
        self._take_joined_keyframes(slam, map_from_odometry)
        return closures

    def _take_joined_keyframes(self, slam: NeoSLAM, map_from_odometry: np.ndarray) -> None:
        """Stored keyframes now in the robot's part of the map go to the loop detector (in this session's odometry
        frame, as its own keyframes are, and old enough to be recognised at once); the others stay to be searched."""
        experience_map = slam.experience_map
        part = experience_map.parts.part_of(experience_map.current)
        joined, waiting = [], []
        for keyframe in self.stored.keyframes:
            if keyframe.id in self.relocaliser.index.keyframes:
                here = experience_map.parts.part_of(experience_map.experience_of(keyframe.id)) == part
                (joined if here else waiting).append(keyframe)
        if not joined:
            return
        index = slam.loop_detector.index
        odometer = slam.keyframes.odometer_m - self.config.matching.exclude_recent_distance
        to_odometry = invert_pose(map_from_odometry)
        entries = [(self._in_map_frame(slam, k, to_odometry), odometer) for k in joined]
        entries += [(k, index.odometer(k.id)) for k in index.keyframes]
        slam.loop_detector.index = KeyframeIndex(self.config.matching)
        for keyframe, reading in sorted(entries, key=lambda entry: entry[0].id):  # ids must increase
            slam.loop_detector.index.add(keyframe, reading)
        self._search(slam, waiting)

    @staticmethod
    def _reset_cells(slam: NeoSLAM, closure: LoopClosure) -> None:
        """Relocalised in a stored map: the cells take the stored place's state, moved to where the closure puts
        the robot (the limit of a strong local-view injection; two sessions' cells start apart)."""
        experience_map = slam.experience_map
        stored = experience_map.experiences[experience_map.experience_of(closure.match_keyframe)]
        heading = stored.head_direction * slam.head_direction.cell_angle
        shift, turn = offset_in_cells(heading, stored.pose, closure.relative_pose, slam.grid_cells, slam.head_direction)
        slam.grid_cells.reset((stored.grid_cell + shift) % np.asarray(slam.grid_cells.dims))
        slam.head_direction.reset((stored.head_direction + turn) % slam.head_direction.cells)
        slam.recentre_grid_decoding()

    def record(self, slam: NeoSLAM) -> SessionRecord:
        return replace(self.session, frames=slam.frames_processed)

    def state(self, slam: NeoSLAM) -> MapState:
        """What a map file stores (the arrays are the live ones, not copies)."""
        experience_map = slam.experience_map
        session_of = experience_map.session_of
        closures = [StoredClosure(self.session.id, session_of(c.match_keyframe), c) for c in slam.loop_closures]
        return MapState(
            sessions=[*self.stored.sessions, self.record(slam)],
            keyframes=[*self.stored.keyframes, *slam.own_keyframes()],
            keyframe_experience=experience_map.keyframe_experiences,
            experiences=experience_map.experiences,
            experience_poses=experience_map.graph.poses,
            links=experience_map.graph.links,
            closures=[*self.stored.closures, *closures],
            objects=slam.object_map.state(),
            hebbian=slam.hebbian.traces(),
            object_vector_weights=self._object_vector_weights(slam),
            object_vector_losses=slam.object_vector_cells.loss_history,
        )

    def _object_vector_weights(self, slam: NeoSLAM) -> dict[str, np.ndarray]:
        """The OVCN's weights, copied again only once it has learnt another epoch (a map is committed at every
        keyframe, the OVCN learns a few epochs in all)."""
        epochs = len(slam.object_vector_cells.loss_history)
        if self._weights[0] != epochs:
            self._weights = (epochs, slam.object_vector_cells.weights())
        return self._weights[1]
