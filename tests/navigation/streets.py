"""Hand-built maps for the navigation tests: drives along polylines make experiences every few metres, linked by
odometry; loop links and objects (seen from chosen experiences) are added by hand."""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
from scipy.spatial.transform import Rotation

from neoslam.geometry import invert_pose, make_pose
from neoslam.types import Experience, Link, MapState, ObjectMapState, SessionRecord

STEP_M = 5.0
SPEED = 8.0  # m/s, each experience's recorded speed


def pose_at(x: float, y: float, yaw: float, z: float = 0.0) -> np.ndarray:
    return make_pose(Rotation.from_euler("z", yaw), np.array([x, y, z]))


def sample(corners: list[tuple[float, float]], step: float = STEP_M) -> list[np.ndarray]:
    """Poses every `step` metres along a polyline (its corners included), heading along it."""
    poses = []
    for (x0, y0), (x1, y1) in zip(corners[:-1], corners[1:], strict=True):
        length = float(np.hypot(x1 - x0, y1 - y0))
        yaw = float(np.arctan2(y1 - y0, x1 - x0))
        for distance in np.arange(0.0, length, step):
            poses.append(pose_at(x0 + (x1 - x0) * distance / length, y0 + (y1 - y0) * distance / length, yaw))
    x, y = corners[-1]
    poses.append(pose_at(x, y, float(np.arctan2(corners[-1][1] - corners[-2][1], corners[-1][0] - corners[-2][0]))))
    return poses


@dataclass
class MapBuilder:
    """Experiences made by drives, links, objects and keyframes, turned into a MapState."""

    poses: list[np.ndarray] = field(default_factory=list)
    sessions: list[int] = field(default_factory=list)
    speeds: list[float] = field(default_factory=list)
    links: list[Link] = field(default_factory=list)
    keyframes: dict[int, int] = field(default_factory=dict)
    objects: list[tuple[str, np.ndarray, dict[int, int]]] = field(default_factory=list)

    def drive(
        self, corners: list[tuple[float, float]], session: int = 1, after: int | None = None, speed: float = SPEED
    ) -> list[int]:
        """Experiences along the polyline, each linked by odometry to the one before (the first to `after`)."""
        made = []
        previous = after
        for pose in sample(corners):
            index = len(self.poses)
            self.poses.append(pose)
            self.sessions.append(session)
            self.speeds.append(speed)
            if previous is not None:
                self.link(previous, index, "odometry")
            made.append(index)
            previous = index
        return made

    def place(self, x: float, y: float, yaw: float = 0.0, session: int = 1) -> int:
        """One experience at a pose, linked to nothing."""
        self.poses.append(pose_at(x, y, yaw))
        self.sessions.append(session)
        self.speeds.append(SPEED)
        return len(self.poses) - 1

    def link(self, source: int, target: int, kind: str = "loop") -> None:
        relative = invert_pose(self.poses[source]) @ self.poses[target]
        distance = float(np.linalg.norm(relative[:3, 3])) if kind == "odometry" else 0.0
        self.links.append(Link(source, target, relative, kind, distance))  # type: ignore[arg-type]

    def nearest(self, x: float, y: float) -> int:
        positions = np.array([p[:2, 3] for p in self.poses])
        return int(np.argmin(np.linalg.norm(positions - (x, y), axis=1)))

    def add_object(
        self, label: str, position: tuple[float, float, float], seen_from: dict[int, int], sigma: float = 1.0
    ) -> int:
        """An object at `position`, observed `count` times from each experience of `seen_from` {experience: count},
        each observation's std `sigma` (m; its weight in the map is one over its square)."""
        self.objects.append((label, np.asarray(position, dtype=float), dict(seen_from), sigma))
        return len(self.objects) - 1

    def state(self) -> MapState:
        poses = np.array(self.poses)
        experiences = [
            Experience(
                id=i,
                frame_index=10 * i,
                grid_cell=np.zeros(3),
                head_direction=0.0,
                pose=poses[i],
                linear_velocity=np.array([self.speeds[i], 0.0, 0.0]),
                angular_velocity=np.zeros(3),
                keyframe_id=next((k for k, e in self.keyframes.items() if e == i), None),
                session=self.sessions[i],
            )
            for i in range(len(poses))
        ]
        names = sorted(set(self.sessions))
        sessions = [SessionRecord(s, f"drive {s}", 100, None if s == 1 else 5) for s in names]
        return MapState(
            sessions=sessions,
            keyframe_experience=dict(self.keyframes),
            experiences=experiences,
            experience_poses=poses,
            links=list(self.links),
            objects=self._object_state(poses),
        )

    def _object_state(self, poses: np.ndarray) -> ObjectMapState:
        labels, sums, weights, counts = [], [], [], []
        pair_object, pair_experience, pair_sums, pair_weights, pair_counts = [], [], [], [], []
        for index, (label, position, seen_from, sigma) in enumerate(self.objects):
            labels.append(label)
            total = sum(seen_from.values())
            weight = 1.0 / sigma**2
            sums.append(total * weight * position)
            weights.append(total * weight)
            counts.append(total)
            for experience, count in sorted(seen_from.items()):
                local = invert_pose(poses[experience]) @ np.append(position, 1.0)
                pair_object.append(index)
                pair_experience.append(experience)
                pair_sums.append(count * weight * local[:3])
                pair_weights.append(count * weight)
                pair_counts.append(count)
        return ObjectMapState(
            labels=labels,
            sums=np.array(sums, dtype=float).reshape(-1, 3),
            weights=np.array(weights, dtype=float),
            counts=np.array(counts, dtype=int),
            pair_object=np.array(pair_object, dtype=int),
            pair_experience=np.array(pair_experience, dtype=int),
            pair_sums=np.array(pair_sums, dtype=float).reshape(-1, 3),
            pair_weights=np.array(pair_weights, dtype=float),
            pair_counts=np.array(pair_counts, dtype=int),
        )


@dataclass
class Ladder:
    """Two parallel streets 50 m apart from x=0 to x=200 and three cross streets (x = 0, 100, 200): the perimeter
    driven counter-clockwise from (0, 0) and closed by a loop link to the start, then the middle cross street driven
    north and joined to both streets by loop links. Objects: trucks at (160, -5) and (40, 55), cars along the south
    street, a person on the middle street."""

    builder: MapBuilder
    perimeter: list[int]
    middle: list[int]

    @property
    def state(self) -> MapState:
        return self.builder.state()

    def at(self, x: float, y: float) -> int:
        return self.builder.nearest(x, y)


def ladder() -> Ladder:
    builder = MapBuilder()
    perimeter = builder.drive([(0, 0), (200, 0), (200, 50), (0, 50), (0, 5)])
    builder.link(perimeter[-1], perimeter[0])  # back at the start: a loop closure
    south, north = builder.nearest(100, 0), builder.nearest(100, 50)
    middle = builder.drive([(100, 5), (100, 45)], after=None)
    builder.link(south, middle[0])
    builder.link(middle[-1], north)
    builder.keyframes = {7: builder.nearest(60, 0), 8: builder.nearest(200, 25)}
    seen = lambda x, y: {builder.nearest(x, y): 3, builder.nearest(x - 5, y): 2}  # noqa: E731
    builder.add_object("truck", (160, -5, 0.5), seen(160, 0))
    builder.add_object("truck", (40, 55, 0.5), {builder.nearest(45, 50): 3, builder.nearest(40, 50): 1})
    builder.add_object("car", (20, -5, 0.5), seen(20, 0))
    builder.add_object("car", (120, -5, 0.5), seen(120, 0))
    builder.add_object("person", (105, 25, 0.5), {builder.nearest(100, 20): 4})
    return Ladder(builder, perimeter, middle)
