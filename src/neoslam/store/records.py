"""What a stored map holds, as plain records and arrays: the contract between NeoSLAM's components (which export
and restore them) and the map file (which writes and reads them). Nothing here knows SQLite or the pipeline."""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from neoslam.cells.hebbian import HebbianTrace
from neoslam.mapping.graph import Link
from neoslam.types import Experience, Keyframe, LoopClosure

__all__ = ["MapState", "ObjectMapState", "SessionRecord", "StoredClosure"]


@dataclass(frozen=True, slots=True)
class SessionRecord:
    """One run that made or extended the map. Ids count from 1 in the order the sessions ran."""

    id: int
    name: str  # the dataset's name
    frames: int  # frames processed (so far, while the session runs)
    relocalised_frame: int | None  # the session's frame at which it joined the stored map; None: never (yet)


@dataclass(frozen=True, slots=True)
class StoredClosure:
    """A loop closure accepted into the map, with the sessions of its two keyframes."""

    session: int  # the session that made it (its query keyframe's)
    match_session: int  # the session of the stored keyframe it recognised
    closure: LoopClosure


@dataclass
class ObjectMapState:
    """The object map's arrays (see neoslam.mapping.object_map): one row per object ever made, and the observation
    sums per (object, experience) in the experience's frame, from which positions follow the corrected map."""

    labels: list[str] = field(default_factory=list)
    sums: np.ndarray = field(default_factory=lambda: np.zeros((0, 3)))  # (n, 3) weighted world sums
    weights: np.ndarray = field(default_factory=lambda: np.zeros(0))  # (n,)
    counts: np.ndarray = field(default_factory=lambda: np.zeros(0, dtype=int))  # (n,) 0: merged away or forgotten
    pair_object: np.ndarray = field(default_factory=lambda: np.zeros(0, dtype=int))  # (p,)
    pair_experience: np.ndarray = field(default_factory=lambda: np.zeros(0, dtype=int))  # (p,)
    pair_sums: np.ndarray = field(default_factory=lambda: np.zeros((0, 3)))  # (p, 3) in the experience's frame
    pair_weights: np.ndarray = field(default_factory=lambda: np.zeros(0))  # (p,)
    pair_counts: np.ndarray = field(default_factory=lambda: np.zeros(0, dtype=int))  # (p,)


@dataclass
class MapState:
    """Everything a map holds. Keyframe, experience and object ids are unique over all sessions; an experience's
    `session` names the session that made it (a keyframe's session is its experience's)."""

    sessions: list[SessionRecord] = field(default_factory=list)
    keyframes: list[Keyframe] = field(default_factory=list)  # stored keyframes, ids increasing
    keyframe_experience: dict[int, int] = field(default_factory=dict)  # keyframe id -> its experience
    experiences: list[Experience] = field(default_factory=list)  # ids 0..n-1; .pose is the odometry pose
    experience_poses: np.ndarray = field(default_factory=lambda: np.zeros((0, 4, 4)))  # corrected, map frame
    links: list[Link] = field(default_factory=list)
    closures: list[StoredClosure] = field(default_factory=list)
    objects: ObjectMapState = field(default_factory=ObjectMapState)
    hebbian: dict[int, HebbianTrace] = field(default_factory=dict)  # keyframe id -> its association
    object_vector_weights: dict[str, np.ndarray] = field(default_factory=dict)  # OVCN parameters by name
    object_vector_losses: list[float] = field(default_factory=list)  # per epoch trained

    @property
    def next_session(self) -> int:
        return max((s.id for s in self.sessions), default=0) + 1

    @property
    def next_keyframe(self) -> int:
        return max((k.id for k in self.keyframes), default=-1) + 1
