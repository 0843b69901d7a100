"""Small typed records passed between NeoSLAM's components.

Frames: inside NeoSLAM every pose is a 4x4 homogeneous matrix T_world_robot in the robot frame of REP-103
(x forward, y left, z up); the robot frame's origin is the left camera's optical centre. Object centres measured
by the stereo camera stay in the camera's optical frame (x right, y down, z forward) until they are moved to the
world; `neoslam.io.frames` holds the only conversions between the two.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

__all__ = [
    "ObjectObservation",
    "Frame",
    "Keyframe",
    "Experience",
    "LoopClosure",
    "Trajectory",
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


@dataclass(frozen=True, slots=True)
class Frame:
    """What the robot knows at one time step: odometry and the objects it sees (paper 3.1, eq. 15)."""

    index: int
    timestamp: float
    odometry_pose: np.ndarray  # (4, 4) T_world_robot integrated from odometry alone
    linear_velocity: np.ndarray  # (3,) body frame, m/s
    angular_velocity: np.ndarray  # (3,) body frame, rad/s
    observations: tuple[ObjectObservation, ...] = ()


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
    distances: np.ndarray = field(init=False)  # (n, n) pairwise e_ij, eq. 1

    def __post_init__(self) -> None:
        n = len(self.labels)
        provisional = np.zeros(n, dtype=bool) if self.provisional is None else self.provisional
        object.__setattr__(self, "provisional", np.asarray(provisional, dtype=bool))
        covariances = np.zeros((n, 2, 2)) if self.covariances is None else np.asarray(self.covariances, dtype=float)
        if covariances.shape != (n, 2, 2):
            raise ValueError(f"keyframe {self.id}: covariances of shape {covariances.shape}, not ({n}, 2, 2)")
        object.__setattr__(self, "covariances", covariances)
        diff = self.centers[:, None, :] - self.centers[None, :, :]
        object.__setattr__(self, "distances", np.linalg.norm(diff, axis=-1))

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
        )


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
