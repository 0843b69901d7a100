"""The object experience map (paper 3.6, eq. 15-18): experiences of the cells' state, linked by odometry and by
loop closures, corrected by relaxation (the paper) or pose-graph optimisation (beyond it; neoslam.mapping.backend).

An experience exp = [P_gc, P_hdc, Xr, KF] (eq. 16) is made for every new keyframe (a new template, NeuroSLAM's rule)
and when the decoded cells have moved more than S_max from the current experience's (eq. 17: stretches without
objects still get experiences). Each new experience is linked to the previous one by the odometric displacement.
A loop closure is accepted only when the recognised experience's grid-cell state is within
`gc_distance_threshold` cells of the current one (the paper's second guard, `closure_gate: grid-cells`); it then
links the two experiences with the metric transform of the object fit and triggers the correction. The cells
integrate the odometry, so they drift with it: `closure_gate: drift` (beyond the paper) widens the allowed distance
by `gc_drift_cells_per_100m` for every 100 m of path integration between the cells now and the stored experience's
cells, along the chain of anchors the two were derived from (neoslam.mapping.cell_lineage: a recall re-anchors the
cells at a stored place, whose own cells were derived from earlier ones), as the loop detector's retrieval radius
widens with the distance travelled.

Lifelong mapping (`reuse_places`, RatSLAM's and NeuroSLAM's rule, beyond the paper): a street driven again must not add
a copy of itself. A new keyframe that a closure recognises as a stored one (cells within the guard, heading within
`reuse_max_turn_deg`) makes no experience, provided the map agrees (the closure puts the robot within `reentry_distance`
and `reentry_yaw_deg` of where the map has it): the robot re-enters the stored keyframe's experience, placed in it by
the closure's fit. Coming from an experience it made since it last knew where it was, that one is linked to the stored
one (a loop link, once per pair), which ties it to the map; coming from a stored experience, nothing is added (the map
holds that relation). A closure the map disagrees with (the robot is back after a long loop and the map is off) does
what the paper does: the keyframe gets its own experience and a loop link that corrects the map, until the map agrees.
For `localised_distance` metres after a recognised place the robot knows where it is (with object landmarks, until the
back end withdraws a loop link: `unlocalise_on_withdrawal`), and a new keyframe or a move of the cells that finds an
experience within `reuse_radius` of the corrected pose, heading the same way, re-enters that experience too (no link).
Frames keep the experience they were in and where the robot entered it (a visit), so the trajectory is the same
whichever way the map was built.

Sessions (beyond the paper, neoslam.store): the map can start from a stored one (`restore`). The session's first
experience then starts a part of the map of its own, in the session's frame; the first closure with a stored
keyframe joins the two parts (`join`): the newer part moves rigidly to where the closure puts it in the older's
frame, and a loop link by that closure makes them one part (whichever way the robot drives the stored street). The
grid-cell check compares experiences of one session only: two sessions' cells started apart.
"""

from __future__ import annotations

from array import array
from dataclasses import dataclass

import numpy as np

from neoslam.config import ExperienceMapConfig
from neoslam.geometry import invert_pose, rotation_angle, yaw_of
from neoslam.mapping.backend import MapBackend
from neoslam.mapping.cell_lineage import CellLineage, allowed_cell_distance
from neoslam.mapping.graph import MapGraph
from neoslam.mapping.parts import MapParts
from neoslam.types import Experience, Link, LoopClosure, MapState, Trajectory

__all__ = ["CellState", "ExperienceMap", "Revisit"]

RECENT_MERGED_KEYFRAMES = 8  # keyframes merged into stored ones that a late closure (consecutive test) may still name
INITIAL_VISITS = 256
# A street driven the second time links each experience it re-enters to the one before; those links measure a map
# that already holds them, and the pose graph takes them BATCHED_LINKS at a time, not one optimisation each.
BATCHED_LINKS = 10


def _circular(a: np.ndarray, b: np.ndarray, dims: np.ndarray) -> np.ndarray:
    d = np.abs(np.asarray(a, float) - np.asarray(b, float)) % dims
    return np.minimum(d, dims - d)


@dataclass(frozen=True)
class CellState:
    """Decoded grid-cell centre (cells) and head-direction cell (cells) at one frame."""

    grid: np.ndarray
    head_direction: float


@dataclass(frozen=True)
class Revisit:
    """The current keyframe is stored keyframe `keyframe` seen again: recognised by a loop closure (whose fit puts
    the robot in that keyframe's experience), or, while the robot knows where it is, found there in the map."""

    keyframe: int
    robot_in_experience: np.ndarray  # (4, 4) T_experience_robot
    closure: LoopClosure | None = None


class ExperienceMap:
    """Experiences, their links and the map correction."""

    def __init__(self, config: ExperienceMapConfig, grid_dims: tuple[int, ...], head_direction_cells: int) -> None:
        self.config = config
        self.grid_dims = np.asarray(grid_dims, dtype=float)
        self.head_direction_cells = float(head_direction_cells)
        self.experiences: list[Experience] = []
        self.graph = MapGraph()
        self.parts = MapParts()
        self.session = 1  # the session whose experiences this run makes
        self._odometry_poses: list[np.ndarray] = []  # each experience's odometry pose when it was made
        self._by_keyframe: dict[int, int] = {}
        self._merged: dict[int, tuple[int, np.ndarray]] = {}  # recent keyframes merged: (experience, T_exp_robot)
        self._linked: set[tuple[int, int]] = set()  # pairs of experiences with a link, smaller id first
        self._reentered: set[int] = set()  # experiences a closure has re-entered
        self._joining: set[tuple[int, int]] = set()  # (query, match) keyframes of the closures that joined parts
        self._unoptimised = 0  # links added since the last optimisation
        self._current = -1
        self._current_is_new = False  # whether the current visit made its experience (not yet tied to the map)
        self._anchor = np.eye(4)  # the current experience's pose in the odometry frame, as entered in this visit
        self._visit_cells: CellState | None = None  # the cells when the current visit began
        self._visit_experience = array("l")  # per visit: the experience entered
        self._visit_anchors = np.zeros((INITIAL_VISITS, 4, 4))  # per visit: its anchor
        self._frame_visit = array("l")  # the visit of every frame
        self._travelled_since = 0.0
        self._seconds_since = 0.0
        self._odometer = 0.0
        self._localised_at = -np.inf  # odometer reading of the last recognised place
        self.lineage = CellLineage()  # where each experience's cells came from (closure gate: drift)
        self.rejected_closures: list[LoopClosure] = []
        self.accepted_closures: list[LoopClosure] = []
        self.backend = MapBackend(config)  # corrects the graph (relaxation, pose graph, object landmarks)

    @property
    def current(self) -> int:
        return self._current

    @property
    def visits(self) -> int:
        """How many times an experience was entered (made or re-entered)."""
        return len(self._visit_experience)

    @property
    def odometer(self) -> float:
        """Metres travelled (reversing counts too)."""
        return self._odometer

    def visited_experiences(self) -> np.ndarray:
        """The experience entered at each visit, in order."""
        return np.frombuffer(self._visit_experience, dtype=self._visit_experience.typecode)

    @property
    def localised(self) -> bool:
        """Whether a place was recognised within the last `localised_distance` metres of travel."""
        return self._odometer - self._localised_at <= self.config.localised_distance

    def similarity(self, cells: CellState, experience: Experience) -> float:
        """S of eq. 17: μ_gc |P_gc − P_gc,i| + μ_hdc |P_hdc − P_hdc,i|, circular distances in cells."""
        return self._similarity(cells, experience.grid_cell, experience.head_direction)

    def _similarity(self, cells: CellState, grid: np.ndarray, head_direction: float) -> float:
        grid_distance = np.linalg.norm(_circular(cells.grid, grid, self.grid_dims))
        heading = float(_circular(cells.head_direction, head_direction, self.head_direction_cells))
        return self.config.mu_gc * grid_distance + self.config.mu_hdc * heading

    def step(self, frame_index: int, odometry_pose: np.ndarray, velocities, cells: CellState, travelled_m: float,
             keyframe_id: int | None, revisit: Revisit | None = None, elapsed_s: float = 0.0) -> None:  # fmt: skip
        """Record one frame (`elapsed_s` after the previous one): a new experience for a new keyframe, or when the
        cells left the current one; with a revisit (see `recognise`), re-enter the stored keyframe's experience
        instead; when the cells move on while the robot knows where it is, re-enter an experience at the corrected
        pose if there is one."""
        self._travelled_since += travelled_m
        self._seconds_since += elapsed_s
        self._odometer += travelled_m
        self.lineage.travelled(travelled_m)
        if revisit is not None:
            self._reenter(revisit, odometry_pose, cells, keyframe_id)
        elif (
            self._current < 0
            or keyframe_id is not None
            or (self._cells_moved_on(cells) and not self._reenter_nearby(odometry_pose, cells))
        ):
            self._create(frame_index, odometry_pose, velocities, cells, keyframe_id)
        self._frame_visit.append(self.visits - 1)

    def _cells_moved_on(self, cells: CellState) -> bool:
        """S of eq. 17 against the cells where the current visit began (for a new experience, its own cells)."""
        visit = self._visit_cells
        assert visit is not None  # set by the first experience
        return self._similarity(cells, visit.grid, visit.head_direction) > self.config.similarity_threshold

    def _begin_visit(self, experience: int, anchor: np.ndarray, cells: CellState, new: bool = False) -> None:
        self._current = experience
        self._current_is_new = new
        self._anchor = anchor.copy()
        self._visit_cells = CellState(np.asarray(cells.grid, float).copy(), float(cells.head_direction))
        self._visit_anchors = _grown(self._visit_anchors, self.visits + 1)
        self._visit_anchors[self.visits] = anchor
        self._visit_experience.append(experience)
        self._travelled_since = self._seconds_since = 0.0

    def _create(self, frame_index, odometry_pose, velocities, cells: CellState, keyframe_id) -> None:
        previous = self.current
        experience = Experience(
            id=len(self.experiences),
            frame_index=frame_index,
            grid_cell=np.asarray(cells.grid, float).copy(),
            head_direction=float(cells.head_direction),
            pose=odometry_pose.copy(),
            linear_velocity=np.asarray(velocities[0]),
            angular_velocity=np.asarray(velocities[1]),
            keyframe_id=keyframe_id,
            session=self.session,
        )
        self.parts.add()
        if previous >= 0:  # place it where the odometry says, relative to the corrected previous experience
            relative = invert_pose(self._anchor) @ odometry_pose
            self.graph.add_node(self.graph.poses[previous] @ relative)
            self._link(Link(previous, experience.id, relative, "odometry", self._travelled_since, self._seconds_since))
        else:
            self.graph.add_node(odometry_pose.copy())
        self.experiences.append(experience)
        self._odometry_poses.append(odometry_pose.copy())
        self.lineage.made()
        if keyframe_id is not None:
            self._by_keyframe[keyframe_id] = experience.id
        self._begin_visit(experience.id, odometry_pose, cells, new=True)

    def _link(self, link: Link) -> None:
        self.graph.add_link(link)
        self.parts.link(link.source, link.target)
        self.backend.linked(self.graph, link)
        self._linked.add((min(link.source, link.target), max(link.source, link.target)))

    def _is_linked(self, a: int, b: int) -> bool:
        return (min(a, b), max(a, b)) in self._linked

    def _optimise(self) -> None:
        self._unoptimised = 0
        self._unlink(self.backend.optimise(self))

    def _unlink(self, withdrawn: list[int]) -> None:
        """Links the back end withdrew: their pairs are not linked any more (unless another link joins them), so
        that a later closure between the two may link them again. The robot may have known where it was by a place
        recognised wrongly: as `unlocalise_on_withdrawal` says, it is not localised until the next place recognised."""
        if not withdrawn:
            return
        rule = self.config.unlocalise_on_withdrawal
        if rule == "always" or (rule == "with-landmarks" and self.config.object_landmarks):
            self._localised_at = -np.inf
        live = {(min(k.source, k.target), max(k.source, k.target)) for k in self.graph.live_links()}
        for index in withdrawn:
            link = self.graph.links[index]
            pair = (min(link.source, link.target), max(link.source, link.target))
            if pair not in live:
                self._linked.discard(pair)

    @property
    def withdrawn_links(self) -> list[int]:
        """Loop links withdrawn because the optimised map disagreed with them (indices into graph.links)."""
        return self.graph.withdrawn

    def finish(self) -> None:
        """Optimise the links still waiting (see BATCHED_LINKS): the map as the last frame leaves it (with object
        landmarks, also the observations of the experience the robot is in)."""
        self._unlink(self.backend.finish(self, waiting=self._unoptimised > 0))
        self._unoptimised = 0

    def recognise(
        self, keyframe_id: int, closures: list[LoopClosure], cells: CellState, odometry_pose: np.ndarray
    ) -> Revisit | None:
        """Whether new keyframe `keyframe_id` is a stored keyframe seen again (`reuse_places`): its own closure among
        `closures`, if the cells agree and it faces the stored keyframe's way; or, with no closure of its own while
        the robot knows where it is, the stored keyframe whose experience lies within `reuse_radius` of the
        corrected pose, heading the same way. None: a new keyframe (and experience)."""
        if not self.config.reuse_places or self._current < 0:
            return None
        own = next((c for c in closures if c.query_keyframe == keyframe_id), None)
        pose = self.current_pose(odometry_pose)
        if own is not None:
            stored = self._by_keyframe.get(own.match_keyframe)
            if stored is None or not self.cells_agree(cells, stored):
                return None
            turn = float(np.degrees(rotation_angle(own.relative_pose[:3, :3])))
            in_map = invert_pose(self.graph.poses[stored]) @ pose  # where the map has the robot
            if turn > self.config.reuse_max_turn_deg or not self._agrees(in_map, own.relative_pose):
                return None
            return Revisit(own.match_keyframe, own.relative_pose, own)
        if not self.localised:
            return None
        target = self._nearest(pose, keyframes_only=True)
        if target is None:
            return None
        keyframe = self.experiences[target].keyframe_id
        assert keyframe is not None
        return Revisit(keyframe, invert_pose(self.graph.poses[target]) @ pose)

    def _agrees(self, estimate: np.ndarray, measurement: np.ndarray) -> bool:
        """Whether two relative poses agree within reentry_distance (in the ground plane: a closure's height is the
        difference of its objects' mean heights, metres off at times) and reentry_yaw_deg."""
        error = invert_pose(estimate) @ measurement
        close = np.linalg.norm(error[:2, 3]) <= self.config.reentry_distance
        return bool(close and np.degrees(rotation_angle(error[:3, :3])) <= self.config.reentry_yaw_deg)

    def cells_agree(self, cells: CellState, experience: int) -> bool:
        """The closure gate (`closure_gate`): the recognised experience's grid cells within the allowed distance of
        the current (for an experience of this session: another session's cells started elsewhere)."""
        if self.config.closure_gate == "none" or self.experiences[experience].session != self.session:
            return True
        distance = np.linalg.norm(_circular(cells.grid, self.experiences[experience].grid_cell, self.grid_dims))
        return bool(distance <= allowed_cell_distance(self.config, self.grid_dims, self.lineage, experience))

    def recalled(self, experience: int, cells: CellState, recalled: CellState) -> None:
        """A recall injected a stored experience's cell state, moved to where the robot is (`recalled`): if the
        cells took it (by eq. 17 they are in that state: S <= S_max), they are anchored at the experience from now
        on. A recall the cells did not take (too weak against their packet) leaves the chain as it was."""
        if self._similarity(cells, recalled.grid, recalled.head_direction) <= self.config.similarity_threshold:
            self.lineage.anchored(experience)

    def _nearest(self, pose: np.ndarray, keyframes_only: bool) -> int | None:
        """The experience nearest to a corrected pose within `reuse_radius`, heading within `reuse_max_turn_deg`."""
        poses = self.graph.poses
        distance = np.linalg.norm(poses[:, :3, 3] - pose[:3, 3], axis=1)
        turn = np.abs(np.angle(np.exp(1j * (yaw_of(poses) - yaw_of(pose)))))
        near = (distance <= self.config.reuse_radius) & (turn <= np.radians(self.config.reuse_max_turn_deg))
        near &= self.parts.members(self.parts.part_of(self.current))  # another part's frame is not this one's
        if keyframes_only:
            near &= np.fromiter((e.keyframe_id is not None for e in self.experiences), bool, len(self.experiences))
        if not near.any():
            return None
        return int(np.flatnonzero(near)[np.argmin(distance[near])])

    def _reenter(self, revisit: Revisit, odometry_pose: np.ndarray, cells: CellState, keyframe_id) -> None:
        """Enter the revisited keyframe's experience where the revisit puts the robot; a closure also links the
        previous experience to it (once per pair) and corrects the map."""
        target = self._by_keyframe[revisit.keyframe]
        robot_in_experience = revisit.robot_in_experience.copy()
        anchor = odometry_pose @ invert_pose(robot_in_experience)
        if keyframe_id is not None:
            self._merged[keyframe_id] = (target, robot_in_experience)
            while len(self._merged) > RECENT_MERGED_KEYFRAMES:
                del self._merged[next(iter(self._merged))]
        linked = False
        if revisit.closure is not None:
            self.accepted_closures.append(revisit.closure)
            self._localised_at = self._odometer
            measured = invert_pose(self._anchor) @ anchor
            if target != self.current and self._current_is_new:  # ties what the robot made to the map
                linked = self._link_if_news(self.current, target, measured)
            elif target != self.current and target not in self._reentered:  # the street's second measurement
                self._link(Link(self.current, target, measured, "loop", 0.0))
                self._unoptimised += 1  # between experiences the map already holds: optimised a batch at a time
                linked = self._unoptimised >= BATCHED_LINKS
        self._reentered.add(target)
        self._begin_visit(target, anchor, cells)
        if linked:
            self._optimise()

    def _link_if_news(self, source: int, target: int, relative: np.ndarray) -> bool:
        """A loop link source -> target measured by a closure, unless the map holds it already: the two are linked
        and the map puts them where the measurement does (within reentry_distance and reentry_yaw_deg). Returns
        whether the link was added. (Used where the robot comes from an experience it made since it last knew
        where it was: the link ties it to the map.)"""
        if self._is_linked(source, target) and self._agrees(self.graph.relative(source, target), relative):
            return False
        self._link(Link(source, target, relative, "loop", 0.0))
        return True

    def _reenter_nearby(self, odometry_pose: np.ndarray, cells: CellState) -> bool:
        """While the robot knows where it is, enter the experience at the corrected pose instead of making one;
        returns whether there was one (staying in the current one counts)."""
        if not self.config.reuse_places or self._current < 0 or not self.localised:
            return False
        pose = self.current_pose(odometry_pose)
        target = self._nearest(pose, keyframes_only=False)
        if target is None:
            return False
        if target == self.current:
            self._visit_cells = cells  # still here: measure the cells' move from now on
        else:
            self._reentered.add(target)
            self._begin_visit(target, odometry_pose @ invert_pose(invert_pose(self.graph.poses[target]) @ pose), cells)
        return True

    def close_loop(self, closure: LoopClosure, cells: CellState) -> bool:
        """Link the experiences of a closure's keyframes if the cells agree (paper: about seven bins); returns
        whether the closure was accepted into the map."""
        stored = self._by_keyframe.get(closure.match_keyframe)
        query = self._by_keyframe.get(closure.query_keyframe)
        merged = self._merged.get(closure.query_keyframe) if query is None else None
        if stored is None or (query is None and merged is None):
            return False
        if self.parts.part_of(stored) != self.parts.part_of(self.current):
            return False  # a stored session's part not joined (see join): its frame is not this one's
        if not self.cells_agree(cells, stored):
            self.rejected_closures.append(closure)
            return False
        self.accepted_closures.append(closure)
        self._localised_at = self._odometer
        if (closure.query_keyframe, closure.match_keyframe) in self._joining:
            return True  # its join linked it (see join): a second link would count the one fit twice
        if query is not None:
            self._link(Link(stored, query, closure.relative_pose, "loop", 0.0))
        else:  # the query keyframe was merged into a stored one: the closure relates two stored experiences
            assert merged is not None
            experience, robot_in_experience = merged
            relative = closure.relative_pose @ invert_pose(robot_in_experience)  # T_stored_experience
            if experience == stored or self._agrees(self.graph.relative(stored, experience), relative):
                return True  # the map holds that already
            self._link(Link(stored, experience, relative, "loop", 0.0))
        self._optimise()
        return True

    def join(self, closure: LoopClosure, query_pose: np.ndarray) -> bool:
        """If a closure's stored keyframe lies in another part of the map than the robot (a stored session, before
        this one relocalised in it), move the newer of the two parts rigidly to where the closure puts it in the
        older one's frame (in all six degrees of freedom: the parts' frames are their sessions' first poses, tilted
        differently), and link the robot's current experience to the stored one by the closure: the two parts are
        one from then on. `query_pose` is the closure's query keyframe pose in the map as it is (the robot's
        current pose for the current keyframe). Returns whether the robot's own part moved (then its frame is the
        stored part's).

        The link is what makes the join last. Without it the parts stayed two until a later link tied them, which
        only re-entering a stored experience did (the robot heading the way the map was made): a robot driving a
        mapped street the other way stayed a part of its own, so every keyframe that relocalised joined again,
        moving the whole session by that one fit, and each join (rotations inverted as if orthonormal) doubled
        their rounding error until they degenerated: headings half a turn off, positions kilometres off."""
        stored = self._by_keyframe.get(closure.match_keyframe)
        if stored is None or self._current < 0:
            return False
        here, there = self.parts.part_of(self.current), self.parts.part_of(stored)
        if here == there:
            return False
        robot_in_current = invert_pose(self.graph.poses[self.current]) @ query_pose
        robot = self.graph.poses[stored] @ closure.relative_pose  # where the closure puts the robot, there
        moved = robot @ invert_pose(query_pose)  # T_there_here
        moving = here
        if there > here:  # the stored part is the newer one: it moves into the robot's part's frame
            moved, moving = invert_pose(moved), there
        members = self.parts.members(moving)
        self.graph.poses[members] = moved @ self.graph.poses[members]
        tie = closure.relative_pose @ invert_pose(robot_in_current)  # T_stored_current
        self._link(Link(stored, self.current, tie, "loop", 0.0))
        self._joining.add((closure.query_keyframe, closure.match_keyframe))
        self.backend.rebuild(self.graph)
        return moving == here

    def restore(self, state: MapState, session: int) -> None:
        """Start from a stored map: its experiences, corrected poses and links; this run's experiences belong to
        `session` and start a part of the map of their own."""
        self.session = session
        self.experiences = list(state.experiences)
        self.graph = MapGraph(np.array(state.experience_poses, dtype=float).reshape(-1, 4, 4), [])
        self.parts = MapParts()
        for _ in self.experiences:
            self.parts.add()
        for link in state.links:
            self._link(link)
        self.graph.withdrawn = list(state.withdrawn_links)
        self._unlink(self.graph.withdrawn)
        self._odometry_poses = [e.pose for e in self.experiences]
        self.lineage = CellLineage()
        self.lineage.restored(len(self.experiences))  # another session's: the gate does not compare its cells
        self._by_keyframe = dict(state.keyframe_experience)
        self.backend.rebuild(self.graph)

    def correct(self) -> None:
        """Per frame: the back end's correction (relaxation once the map has a loop; landmark updates)."""
        self.backend.correct(self, has_loop=bool(self.accepted_closures))

    @property
    def keyframe_experiences(self) -> dict[int, int]:
        """The experience of every keyframe stored (made with it)."""
        return self._by_keyframe

    def experience_of(self, keyframe_id: int) -> int:
        return self._by_keyframe[keyframe_id]

    def session_of(self, keyframe_id: int) -> int:
        """The session that made a stored keyframe."""
        return self.experiences[self._by_keyframe[keyframe_id]].session

    def correction(self, experience: int) -> np.ndarray:
        """T_map_odometry of an experience: from the odometry frame it was made in to the corrected map."""
        return self.graph.poses[experience] @ invert_pose(self._odometry_poses[experience])

    def corrected_points(self, keyframe_id: int, points: np.ndarray) -> np.ndarray:
        """World points of a keyframe (odometry frame when it was made) in the corrected map."""
        correction = self.correction(self._by_keyframe[keyframe_id])
        return points @ correction[:3, :3].T + correction[:3, 3]

    def anchor(self, odometry_pose: np.ndarray) -> tuple[int, np.ndarray]:
        """The current experience and the robot's pose in its frame (from the odometry since it was entered)."""
        return self.current, invert_pose(self._anchor) @ odometry_pose

    def current_pose(self, odometry_pose: np.ndarray) -> np.ndarray:
        """The corrected pose of a frame of the current experience, from its odometry pose."""
        return self.graph.poses[self.current] @ invert_pose(self._anchor) @ odometry_pose

    def trajectory(self, timestamps: np.ndarray, odometry_poses: np.ndarray) -> Trajectory:
        """A pose for every frame: the corrected pose of the experience it was in, moved on by the odometry since
        the robot entered it."""
        visits = np.frombuffer(self._frame_visit, dtype=self._frame_visit.typecode).astype(int)
        owner = self.visited_experiences().astype(int)[visits]
        anchors = self._visit_anchors[visits]
        poses = self.graph.poses[owner] @ invert_pose(anchors) @ odometry_poses
        return Trajectory(np.asarray(timestamps), poses)


def _grown(array_: np.ndarray, size: int) -> np.ndarray:
    """The array with room for `size` rows (capacity doubled as needed)."""
    if size <= len(array_):
        return array_
    grown = np.zeros((max(2 * len(array_), size), *array_.shape[1:]), dtype=array_.dtype)
    grown[: len(array_)] = array_
    return grown
