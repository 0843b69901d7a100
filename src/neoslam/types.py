"""Small typed records passed between NeoSLAM's components.

Frames: inside NeoSLAM every pose is a 4x4 homogeneous matrix T_world_robot in the robot frame of REP-103
(x forward, y left, z up); the robot frame's origin is the left camera's optical centre. Object centres measured
by the stereo camera stay in the camera's optical frame (x right, y down, z forward) until they are moved to the
world; `neoslam.geometry` holds the only conversions between the two.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Literal

import numpy as np

from neoslam.geometry import yaw_of
from neoslam.record_checks import check_frame, check_observation

__all__ = [
    "ObjectObservation",
    "Frame",
    "Keyframe",
    "moved_views",
    "Experience",
    "LoopClosure",
    "Trajectory",
    "Link",
    "HebbianTrace",
    "SessionRecord",
    "StoredClosure",
    "ObjectMapState",
    "MapState",
]


@dataclass(frozen=True, slots=True)
class ObjectObservation:
    """One detected object in one stereo frame, as the detector and stereo matching give it."""

    label: str
    score: float
    box_left: np.ndarray  # (4,) x1, y1, x2, y2 in pixels of the left image
    box_right: np.ndarray  # (4,) same box matched in the right image
    center_camera: np.ndarray  # (3,) triangulated centre in the camera optical frame, metres
    patch: np.ndarray  # (h, w) uint8 grey appearance patch of the object in the left image
    depth_sigma: float | None = None  # std of the centre's depth, m, when the stereo front end measured it

    def __post_init__(self) -> None:
        check_observation(self)  # ValueError naming the field: a wrong value is refused where it enters


@dataclass(frozen=True, slots=True)
class Frame:
    """What the robot knows at one time step: odometry and the objects it sees (paper 3.1, eq. 15)."""

    index: int
    timestamp: float
    odometry_pose: np.ndarray  # (4, 4) T_world_robot integrated from odometry alone
    linear_velocity: np.ndarray  # (3,) body frame, m/s
    angular_velocity: np.ndarray  # (3,) body frame, rad/s
    observations: tuple[ObjectObservation, ...] = ()

    def __post_init__(self) -> None:
        check_frame(self, ObjectObservation)  # ValueError naming the field


@dataclass(frozen=True, slots=True)
class Keyframe:
    """A current object and the objects around it, in the world frame (paper 3.2)."""

    id: int
    frame_index: int
    pose: np.ndarray  # (4, 4) T_world_robot when the keyframe was made
    centers: np.ndarray  # (n, 3) object centres in the world frame
    labels: tuple[str, ...]
    patches: np.ndarray  # (n, h, w) uint8
    # (n,) bool: objects not known to be static yet (moving_objects.unjudged: wait); None: none of them
    provisional: np.ndarray | None = None
    # (n, 2, 2) ground-plane covariance of each centre as its views give it, m²; None: zeros (matching adds its
    # own floor, matching.centre_sigma, to every object)
    covariances: np.ndarray | None = None
    # (m, 3) ground position and heading (x, y, yaw) of the robot where the keyframe's objects were seen from: a
    # keyframe merged from several (loop.places) was seen from each of theirs; None: its own pose
    views: np.ndarray | None = None
    distances: np.ndarray = field(init=False)  # (n, n) pairwise e_ij, eq. 1

    def __post_init__(self) -> None:
        n = len(self.labels)
        provisional = np.zeros(n, dtype=bool) if self.provisional is None else self.provisional
        object.__setattr__(self, "provisional", np.asarray(provisional, dtype=bool))
        covariances = np.zeros((n, 2, 2)) if self.covariances is None else np.asarray(self.covariances, dtype=float)
        if covariances.shape != (n, 2, 2):
            raise ValueError(f"keyframe {self.id}: covariances of shape {covariances.shape}, not ({n}, 2, 2)")
        object.__setattr__(self, "covariances", covariances)
        views = _ground_pose(self.pose)[None] if self.views is None else np.asarray(self.views, dtype=float)
        object.__setattr__(self, "views", views)
        # np.linalg.norm(centres[:, None] - centres[None], axis=-1) written out, its sums in its order: many times
        # faster, by coordinate
        total = 0.0
        for column in np.asarray(self.centers, dtype=float).T:
            offset = column[:, None] - column
            total = total + offset * offset
        object.__setattr__(self, "distances", np.sqrt(total))

    @property
    def nbytes(self) -> int:
        """Memory held by the keyframe's arrays, bytes."""
        arrays = (self.pose, self.centers, self.patches, self.provisional, self.covariances, self.views, self.distances)
        return sum(np.asarray(a).nbytes for a in arrays)

    def moved(self, transform: np.ndarray) -> Keyframe:
        """The same keyframe in another frame: pose and centres moved by `transform` (4, 4), the centres'
        covariances turned by its rotation in the ground plane."""
        turn = transform[:2, :2]
        return Keyframe(
            self.id,
            self.frame_index,
            transform @ self.pose,
            self.centers @ transform[:3, :3].T + transform[:3, 3],
            self.labels,
            self.patches,
            self.provisional,
            turn @ self.covariances @ turn.T,
            moved_views(self.views, transform),
        )


def moved_views(views: np.ndarray, transform: np.ndarray) -> np.ndarray:
    """Views (m, 3) of x, y, yaw moved to another frame by `transform` (4, 4), turned by its yaw."""
    return np.column_stack([views[:, :2] @ transform[:2, :2].T + transform[:2, 3], views[:, 2] + yaw_of(transform)])


def _ground_pose(pose: np.ndarray) -> np.ndarray:
    """(x, y, yaw) of a pose T_world_robot: the robot's x axis is its heading."""
    return np.array([pose[0, 3], pose[1, 3], yaw_of(pose)])


@dataclass(slots=True)
class Experience:
    """A node of the object experience map, exp_t = [P_gc, P_hdc, Xr_t, KF_t] (eq. 16)."""

    id: int
    frame_index: int
    grid_cell: np.ndarray  # (3,) decoded grid-cell peak, in cells
    head_direction: float  # decoded head-direction peak, in cells
    pose: np.ndarray  # (4, 4) T_world_robot from the odometry when it was made (the map's graph holds it corrected)
    linear_velocity: np.ndarray  # (3,)
    angular_velocity: np.ndarray  # (3,)
    keyframe_id: int | None = None
    session: int = 1  # the session (run) that made it, in a map kept over several (neoslam.store)


@dataclass(frozen=True, slots=True)
class LoopClosure:
    """An accepted match between the current keyframe and a stored one."""

    query_frame: int
    match_frame: int
    query_keyframe: int
    match_keyframe: int
    score: float
    n_matches: int
    relative_pose: np.ndarray  # (4, 4) T_match_query from the rigid fit of the matched objects


@dataclass(frozen=True, slots=True)
class Trajectory:
    """Timestamped poses T_world_robot."""

    timestamps: np.ndarray  # (n,) seconds, strictly increasing
    poses: np.ndarray  # (n, 4, 4)

    def __post_init__(self) -> None:
        if self.poses.ndim != 3 or self.poses.shape[1:] != (4, 4):
            raise ValueError(f"poses must have shape (n, 4, 4), got {self.poses.shape}")
        if self.timestamps.shape != (len(self.poses),):
            raise ValueError(f"{len(self.timestamps)} timestamps for {len(self.poses)} poses")

    def __len__(self) -> int:
        return len(self.poses)

    @property
    def positions(self) -> np.ndarray:
        return self.poses[:, :3, 3]

    def path_length(self) -> float:
        """Distance travelled along the positions, metres."""
        return float(np.linalg.norm(np.diff(self.positions, axis=0), axis=1).sum())

    def subset(self, indices: np.ndarray) -> Trajectory:
        return Trajectory(self.timestamps[indices], self.poses[indices])


LinkKind = Literal["odometry", "loop"]


@dataclass(frozen=True, slots=True)
class Link:
    """A measured relative pose T_source_target between two experiences."""

    source: int
    target: int
    relative: np.ndarray  # (4, 4)
    kind: LinkKind
    distance_m: float  # travelled along an odometry link (its uncertainty grows with it); 0 for a loop link
    duration_s: float = 0.0  # the time an odometry link spans (its uncertainty grows with that too); 0 for a loop


@dataclass(slots=True)
class HebbianTrace:
    """One keyframe's association: the sparse max-marginals of β_k and the cell state it was learnt with."""

    gc_indices: np.ndarray
    gc_weights: np.ndarray
    hd_indices: np.ndarray
    hd_weights: np.ndarray
    gc_peak: tuple[int, int, int]
    hd_peak: int
    strength: float

    @property
    def nbytes(self) -> int:
        return self.gc_indices.nbytes + self.gc_weights.nbytes + self.hd_indices.nbytes + self.hd_weights.nbytes


# What a stored map holds, as plain records and arrays: the contract between NeoSLAM's components (which export
# and restore them) and the map file (which writes and reads them).


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
    withdrawn_links: list[int] = field(default_factory=list)  # loop links taken out again (indices into links)
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
