"""Maps to navigate on, made from the real KITTI ground-truth trajectories (benchmarks/navigation.py).

A drive becomes an experience map as NeoSLAM lays one: an experience every SPACING_M of travel at the true pose
(the corrected map of a good run), each linked by odometry to the one before, with the speed the car drove there,
and a loop link wherever the drive comes back within REVISIT_M of an experience it made at least LOOP_TRAVEL_M of
travel before (KITTI 00, 02, 05, 06, 08 and 09 revisit their streets). Drives are laid side by side TILE_GAP_M
apart, each joined to the next by a straight road from its last experience to the next one's first (experiences
every SPACING_M on it too), until the map has the experiences asked for (KITTI 00-10 give about 4,400; the drives
are laid again after that): one connected map, Dijkstra's worst case. Objects stand along the drives (an object
every OBJECT_EVERY_M on either side, classes in street proportions), each seen from the experiences behind it; a
seed fixes them.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy.spatial import cKDTree

from benchmarks.harness import require_data
from neoslam.geometry import invert_pose
from neoslam.io.trajectory_files import read_kitti
from neoslam.types import Experience, Link, MapState, ObjectMapState, SessionRecord

SEQUENCES = ("00", "01", "02", "03", "04", "05", "06", "07", "08", "09", "10")
SPACING_M = 5.0  # experiences of a NeoSLAM map are made a keyframe (about 5 m) apart
REVISIT_M = 3.0
LOOP_TRAVEL_M = 100.0
TILE_GAP_M = 300.0
ROAD_SPEED = 12.0  # m/s on the roads between drives
OBJECT_EVERY_M = 15.0
OBJECT_LATERAL_M = 5.0  # parked objects stand this far beside the route (the simulator's lateral_offset)
SEEN_FROM = 3  # experiences behind an object that observed it
CLASSES = {"car": 0.6, "bicycle": 0.15, "person": 0.15, "truck": 0.1}


@dataclass(frozen=True)
class Drive:
    """One KITTI ground truth as experiences: positions (n, 3), poses (n, 4, 4) and speeds (n,) every SPACING_M."""

    name: str
    poses: np.ndarray
    speeds: np.ndarray


def load_drives() -> list[Drive]:
    """Every KITTI ground truth, sampled every SPACING_M of travel."""
    drives = []
    for sequence in SEQUENCES:
        trajectory = read_kitti(require_data("kitti", "poses", f"{sequence}.txt"))
        positions = trajectory.positions
        travelled = np.concatenate([[0.0], np.cumsum(np.linalg.norm(np.diff(positions, axis=0), axis=1))])
        marks = np.searchsorted(travelled, np.arange(0.0, travelled[-1], SPACING_M))
        speeds = np.gradient(travelled, trajectory.timestamps)[marks]
        drives.append(Drive(sequence, trajectory.poses[marks], speeds))
    return drives


def kitti_map(drives: list[Drive], experiences: int, seed: int = 1) -> MapState:
    """A map of `experiences` experiences: the drives laid side by side (again from the first when all are laid)."""
    poses, speeds, links = [], [], []
    shift = 0.0
    count = 0
    index = 0
    while count < experiences:
        drive = drives[index % len(drives)]
        laid = drive.poses.copy()
        laid[:, :3, 3] -= laid[:, :3, 3].min(axis=0) * np.array([1.0, 1.0, 0.0])
        laid[:, 0, 3] += shift
        shift = float(laid[:, 0, 3].max()) + TILE_GAP_M
        laid_speeds = drive.speeds
        if count:  # driven from the previous drive's end on a road of its own
            road = _road(poses[-1], laid[0])
            laid, laid_speeds = (
                np.concatenate([road, laid]),
                np.concatenate([np.full(len(road), ROAD_SPEED), laid_speeds]),
            )
            links.append(_link(poses[-1], laid[0], count - 1, count, "odometry"))
        take = min(len(laid), experiences - count)
        links += _drive_links(laid[:take], count)
        poses += list(laid[:take])
        speeds += list(laid_speeds[:take])
        count += take
        index += 1
    stacked = np.array(poses)
    return MapState(
        sessions=[SessionRecord(1, "kitti", count, None)],
        experiences=[_experience(i, pose, speed) for i, (pose, speed) in enumerate(zip(stacked, speeds, strict=True))],
        experience_poses=stacked,
        links=links,
        objects=_objects(stacked, np.random.default_rng(seed)),
    )


def _experience(index: int, pose: np.ndarray, speed: float) -> Experience:
    return Experience(
        id=index,
        frame_index=index,
        grid_cell=np.zeros(3),
        head_direction=0.0,
        pose=pose,
        linear_velocity=np.array([speed, 0.0, 0.0]),
        angular_velocity=np.zeros(3),
    )


def _link(source_pose: np.ndarray, target_pose: np.ndarray, source: int, target: int, kind: str) -> Link:
    relative = invert_pose(source_pose) @ target_pose
    distance = float(np.linalg.norm(relative[:3, 3])) if kind == "odometry" else 0.0
    return Link(source, target, relative, kind, distance)  # type: ignore[arg-type]


def _road(start: np.ndarray, end: np.ndarray) -> np.ndarray:
    """Experiences every SPACING_M on the straight road between two poses (neither included), heading along it."""
    offset = end[:3, 3] - start[:3, 3]
    length = float(np.linalg.norm(offset[:2]))
    yaw = float(np.arctan2(offset[1], offset[0]))
    c, s = np.cos(yaw), np.sin(yaw)
    steps = np.arange(SPACING_M, length - SPACING_M / 2, SPACING_M) / max(length, 1e-9)
    road = np.tile(np.eye(4), (len(steps), 1, 1))
    road[:, :3, :3] = [[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]]
    road[:, :3, 3] = start[:3, 3] + steps[:, None] * offset
    return road


def _drive_links(poses: np.ndarray, first: int) -> list[Link]:
    """Odometry links along a drive and loop links where it comes back (to the nearest earlier experience within
    REVISIT_M made LOOP_TRAVEL_M of travel before)."""
    links = [_link(poses[i - 1], poses[i], first + i - 1, first + i, "odometry") for i in range(1, len(poses))]
    tree = cKDTree(poses[:, :2, 3])
    behind = int(LOOP_TRAVEL_M / SPACING_M)
    for i, near in enumerate(tree.query_ball_point(poses[:, :2, 3], REVISIT_M)):
        earlier = [j for j in near if j < i - behind]
        if earlier:
            j = min(earlier, key=lambda k: np.linalg.norm(poses[k, :2, 3] - poses[i, :2, 3]))
            links.append(_link(poses[j], poses[i], first + j, first + i, "loop"))
    return links


def _objects(poses: np.ndarray, rng: np.random.Generator) -> ObjectMapState:
    """An object every OBJECT_EVERY_M (every third experience) on alternating sides, seen from the SEEN_FROM
    experiences before it, a few observations each."""
    every = int(OBJECT_EVERY_M / SPACING_M)
    anchors = np.arange(SEEN_FROM, len(poses), every)
    side = np.where(np.arange(len(anchors)) % 2 == 0, 1.0, -1.0) * OBJECT_LATERAL_M
    local = np.column_stack([np.zeros(len(anchors)), side, np.zeros(len(anchors))])
    centres = np.einsum("nij,nj->ni", poses[anchors, :3, :3], local) + poses[anchors, :3, 3]
    labels = rng.choice(list(CLASSES), size=len(anchors), p=list(CLASSES.values())).tolist()
    pair_object = np.repeat(np.arange(len(anchors)), SEEN_FROM)
    pair_experience = (anchors[:, None] - np.arange(1, SEEN_FROM + 1)[None]).ravel()
    pair_counts = rng.integers(1, 5, size=len(pair_object))
    rotations, origins = poses[pair_experience, :3, :3], poses[pair_experience, :3, 3]
    in_frame = np.einsum("nji,nj->ni", rotations, centres[pair_object] - origins)
    counts = np.bincount(pair_object, weights=pair_counts, minlength=len(anchors)).astype(int)
    return ObjectMapState(
        labels=labels,
        sums=centres * counts[:, None],
        weights=counts.astype(float),
        counts=counts,
        pair_object=pair_object,
        pair_experience=pair_experience,
        pair_sums=in_frame * pair_counts[:, None],
        pair_weights=pair_counts.astype(float),
        pair_counts=pair_counts,
    )
