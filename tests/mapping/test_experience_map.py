"""The object experience map (paper 3.6, eq. 15-18): when experiences are made, how they are linked, which loop
closures it accepts, how each back end corrects it, and the trajectory and keyframe points it gives back."""

from __future__ import annotations

import numpy as np
import pytest
from pydantic import ValidationError
from scipy.spatial.transform import Rotation

from neoslam.config import ExperienceMapConfig
from neoslam.evaluation.trajectory_metrics import absolute_trajectory_error
from neoslam.geometry import invert_pose, make_pose, relative_pose, transform_points
from neoslam.mapping.experience_map import CellState, ExperienceMap
from neoslam.types import LoopClosure, MapState, Trajectory

DIMS = (36, 36, 36)
RING = 36
VELOCITIES = (np.array([1.0, 0.0, 0.0]), np.zeros(3))
CONFIG = ExperienceMapConfig()  # similarity_threshold 3 cells, gc_distance_threshold 7 cells, mu 1 and 1

# The yaw-biased square (conftest.py) is driven once and back to its start; a keyframe every KEYFRAME_EVERY frames.
KEYFRAME_EVERY = 5


def pose(yaw: float, translation=(0.0, 0.0, 0.0)) -> np.ndarray:
    return make_pose(Rotation.from_euler("z", yaw), np.asarray(translation, dtype=float))


def cells(grid=(0.0, 0.0, 0.0), head_direction: float = 0.0) -> CellState:
    return CellState(np.asarray(grid, dtype=float), float(head_direction))


def new_map(**update) -> ExperienceMap:
    return ExperienceMap(CONFIG.model_copy(update=update), DIMS, RING)


def drive(experience_map: ExperienceMap, odometry: np.ndarray) -> None:
    """One step per frame, still cells; keyframe k at frame KEYFRAME_EVERY * k."""
    for frame, odometry_pose in enumerate(odometry):
        travelled = 0.0 if frame == 0 else float(np.linalg.norm(odometry_pose[:3, 3] - odometry[frame - 1][:3, 3]))
        keyframe = frame // KEYFRAME_EVERY if frame % KEYFRAME_EVERY == 0 else None
        experience_map.step(frame, odometry_pose, VELOCITIES, cells(), travelled, keyframe)


def closure(query_keyframe: int, match_keyframe: int, relative: np.ndarray) -> LoopClosure:
    return LoopClosure(
        query_frame=KEYFRAME_EVERY * query_keyframe,
        match_frame=KEYFRAME_EVERY * match_keyframe,
        query_keyframe=query_keyframe,
        match_keyframe=match_keyframe,
        score=3.0,
        n_matches=6,
        relative_pose=relative,
    )


def driven_square(square, backend: str) -> tuple[ExperienceMap, np.ndarray, np.ndarray]:
    """The map of one lap of the biased `square` and back to its start (lap + 1 frames), with its truth and odometry."""
    truth = square.truth(closed=True)
    odometry = square.dead_reckoned(truth)
    experience_map = new_map(backend=backend)
    drive(experience_map, odometry)
    return experience_map, truth, odometry


def loop_back_to_start(square, truth: np.ndarray) -> LoopClosure:
    """The last keyframe (back at the start) recognises keyframe 0, with the true relative pose."""
    return closure(square.lap // KEYFRAME_EVERY, 0, relative_pose(truth[0], truth[square.lap]))


def ate(poses: np.ndarray, truth: np.ndarray) -> float:
    stamps = np.arange(len(truth), dtype=float)
    return absolute_trajectory_error(Trajectory(stamps, poses), Trajectory(stamps, truth), "se3").rmse


# ---------------------------------------------------------------------------------------------------------------
# Creating experiences


def test_the_first_frame_makes_an_experience() -> None:
    experience_map = new_map()
    experience_map.step(0, pose(0.3, (1, 2, 0)), VELOCITIES, cells((4, 5, 6), 7), 0.0, None)
    assert len(experience_map.experiences) == 1
    first = experience_map.experiences[0]
    assert (first.id, first.frame_index, first.keyframe_id) == (0, 0, None)
    np.testing.assert_array_equal(first.grid_cell, [4, 5, 6])
    assert first.head_direction == 7
    np.testing.assert_array_equal(experience_map.graph.poses[0], pose(0.3, (1, 2, 0)))
    assert experience_map.graph.links == []


def test_every_keyframe_makes_an_experience_and_nothing_else_does() -> None:
    experience_map = new_map()
    keyframes = {0: 0, 3: 1, 4: 2, 9: 3}  # frame -> keyframe id
    for frame in range(12):
        experience_map.step(frame, pose(0.0, (frame, 0, 0)), VELOCITIES, cells(), 1.0, keyframes.get(frame))
    assert [e.keyframe_id for e in experience_map.experiences] == [0, 1, 2, 3]
    assert [e.frame_index for e in experience_map.experiences] == [0, 3, 4, 9]
    assert [e.id for e in experience_map.experiences] == [0, 1, 2, 3]
    assert len(experience_map.graph) == 4


@pytest.mark.parametrize(
    ("first", "second", "new"),
    [
        (cells((0, 0, 0)), cells((3, 0, 0)), False),  # S = 3 is not above S_max = 3
        (cells((0, 0, 0)), cells((3.5, 0, 0)), True),
        (cells((0, 0, 0)), cells((0, 0, 0), 3), False),
        (cells((0, 0, 0)), cells((0, 0, 0), 3.5), True),
        (cells((0, 0, 0)), cells((2, 0, 0), 2), True),  # eq. 17 adds the two terms: 2 + 2 > 3
        (cells((0, 0, 0)), cells((2, 2, 0)), False),  # Euclidean in the grid: 2.83
        (cells((0, 0, 0)), cells((2, 2, 1)), False),  # 3.0
        (cells((0, 0, 0)), cells((2, 2, 2)), True),  # 3.46
        # circular on the torus and the ring: 35 and 0 are 1 apart
        (cells((35, 0, 0)), cells((0, 0, 0)), False),
        (cells((34, 0, 0)), cells((1, 0, 0)), False),  # 3 apart across the wrap, not 33
        (cells((34, 0, 0)), cells((1.5, 0, 0)), True),
        (cells((0, 35, 0)), cells((0, 1, 0)), False),
        (cells((0, 0, 1)), cells((0, 0, 34)), False),
        (cells((0, 0, 0), 35), cells((0, 0, 0), 0), False),
        (cells((0, 0, 0), 34), cells((0, 0, 0), 1), False),
        (cells((0, 0, 0), 34), cells((0, 0, 0), 1.5), True),
        (cells((0, 0, 0), 0), cells((0, 0, 0), 18), True),  # the farthest point of the ring
        (cells((35, 35, 35), 35), cells((0, 0, 0), 0), False),  # sqrt(3) + 1 = 2.73
    ],
)
def test_a_new_experience_when_the_cells_moved_more_than_s_max(first: CellState, second: CellState, new: bool) -> None:
    experience_map = new_map()
    experience_map.step(0, np.eye(4), VELOCITIES, first, 0.0, None)
    experience_map.step(1, pose(0.0, (1, 0, 0)), VELOCITIES, second, 1.0, None)
    assert len(experience_map.experiences) == (2 if new else 1)
    if new:
        assert experience_map.experiences[1].frame_index == 1
        assert experience_map.experiences[1].keyframe_id is None


def test_the_weights_of_eq_17() -> None:
    """mu_hdc = 0: head-direction moves alone never make an experience; mu_gc = 2 doubles the grid term."""
    no_heading = new_map(mu_hdc=0.0)
    no_heading.step(0, np.eye(4), VELOCITIES, cells(), 0.0, None)
    no_heading.step(1, np.eye(4), VELOCITIES, cells((0, 0, 0), 18), 0.0, None)
    assert len(no_heading.experiences) == 1
    double_grid = new_map(mu_gc=2.0)
    double_grid.step(0, np.eye(4), VELOCITIES, cells(), 0.0, None)
    double_grid.step(1, np.eye(4), VELOCITIES, cells((2, 0, 0)), 0.0, None)
    assert len(double_grid.experiences) == 2
    assert double_grid.similarity(cells((2, 0, 0)), double_grid.experiences[0]) == pytest.approx(4.0)


def test_cells_are_compared_with_the_current_experience_not_the_previous_frame() -> None:
    """One cell per frame, through the wrap 35 -> 0: a new experience once 4 cells from the last one's."""
    experience_map = new_map()
    for frame in range(10):
        x = (33 + frame) % 36
        experience_map.step(frame, pose(0.0, (frame, 0, 0)), VELOCITIES, cells((x, 0, 0)), 1.0, None)
    assert [e.frame_index for e in experience_map.experiences] == [0, 4, 8]
    assert [float(e.grid_cell[0]) for e in experience_map.experiences] == [33.0, 1.0, 5.0]


def test_similarity_is_circular() -> None:
    experience_map = new_map()
    experience_map.step(0, np.eye(4), VELOCITIES, cells((35, 0, 17), 35), 0.0, None)
    stored = experience_map.experiences[0]
    assert experience_map.similarity(cells((0, 0, 17), 0), stored) == pytest.approx(2.0)
    assert experience_map.similarity(cells((35, 0, 17), 35), stored) == 0.0
    assert experience_map.similarity(cells((17, 0, 17), 35), stored) == pytest.approx(18.0)


def test_each_new_experience_is_linked_to_the_previous_by_the_odometry(biased_square) -> None:
    truth = biased_square.truth()[:40]
    odometry = biased_square.dead_reckoned(truth)
    experience_map = new_map()
    drive(experience_map, odometry)

    experiences = experience_map.experiences
    assert len(experiences) == 8  # frames 0, 5, ..., 35
    links = experience_map.graph.links
    assert [(k.source, k.target, k.kind) for k in links] == [(i, i + 1, "odometry") for i in range(7)]
    for link in links:
        source, target = experiences[link.source], experiences[link.target]
        np.testing.assert_allclose(
            link.relative, relative_pose(odometry[source.frame_index], odometry[target.frame_index]), atol=1e-12
        )
        # travelled since the previous experience
        assert link.distance_m == pytest.approx(KEYFRAME_EVERY * biased_square.step_m)
    # uncorrected, the map is the odometry
    np.testing.assert_allclose(experience_map.graph.poses, odometry[[e.frame_index for e in experiences]], atol=1e-9)
    np.testing.assert_allclose(experience_map.graph.link_residuals(), 0.0, atol=1e-9)


def test_the_link_distance_adds_every_frame_since_the_previous_experience() -> None:
    experience_map = new_map()
    travelled = [0.0, 0.5, 0.25, 2.0, 1.0]
    keyframes = [0, None, None, 1, None]
    for frame, (metres, keyframe) in enumerate(zip(travelled, keyframes, strict=True)):
        experience_map.step(frame, pose(0.0, (frame, 0, 0)), VELOCITIES, cells(), metres, keyframe)
    experience_map.step(5, pose(0.0, (5, 0, 0)), VELOCITIES, cells(), 0.75, 2)
    assert [k.distance_m for k in experience_map.graph.links] == pytest.approx([2.75, 1.75])


def test_a_new_experience_is_placed_from_its_corrected_predecessor() -> None:
    """After a correction, the next experience sits where the odometry puts it relative to the corrected map."""
    experience_map = new_map()
    experience_map.step(0, np.eye(4), VELOCITIES, cells(), 0.0, 0)
    experience_map.step(1, pose(0.0, (2, 0, 0)), VELOCITIES, cells(), 2.0, 1)
    correction = pose(0.5, (1.0, -1.0, 0.2))
    experience_map.graph.poses[1] = correction @ experience_map.graph.poses[1]

    experience_map.step(2, pose(0.3, (3, 1, 0)), VELOCITIES, cells(), 1.4, 2)

    expected = experience_map.graph.poses[1] @ relative_pose(pose(0.0, (2, 0, 0)), pose(0.3, (3, 1, 0)))
    np.testing.assert_allclose(experience_map.graph.poses[2], expected, atol=1e-12)
    np.testing.assert_allclose(experience_map.experiences[2].pose, pose(0.3, (3, 1, 0)))  # the odometry pose


# ---------------------------------------------------------------------------------------------------------------
# Loop closures


def two_keyframe_map(**update) -> ExperienceMap:
    experience_map = new_map(**update)
    experience_map.step(0, np.eye(4), VELOCITIES, cells((0, 0, 0)), 0.0, 0)
    experience_map.step(1, pose(0.0, (1, 0, 0)), VELOCITIES, cells((10, 0, 0)), 1.0, 1)
    return experience_map


@pytest.mark.parametrize(
    ("current", "accepted"),
    [
        ((7, 0, 0), True),  # 7 cells: at the threshold
        ((7.5, 0, 0), False),
        ((4, 4, 4), True),  # 6.93
        ((5, 5, 0), False),  # 7.07
        ((30, 0, 0), True),  # 6 cells across the wrap
        ((28, 0, 0), False),  # 8 cells across the wrap
        ((0, 0, 0), True),
    ],
)
def test_a_closure_is_accepted_only_when_the_grid_cells_agree(current: tuple, accepted: bool) -> None:
    experience_map = two_keyframe_map()
    loop = closure(1, 0, pose(0.0, (1, 0, 0)))

    assert experience_map.close_loop(loop, cells(current)) is accepted

    kinds = [k.kind for k in experience_map.graph.links]
    if accepted:
        assert experience_map.accepted_closures == [loop] and experience_map.rejected_closures == []
        assert kinds == ["odometry", "loop"]
        link = experience_map.graph.links[-1]
        assert (link.source, link.target, link.distance_m) == (0, 1, 0.0)  # stored -> query: T_match_query
        np.testing.assert_array_equal(link.relative, loop.relative_pose)
    else:
        assert experience_map.rejected_closures == [loop] and experience_map.accepted_closures == []
        assert kinds == ["odometry"]


def test_the_grid_cell_check_ignores_the_head_direction() -> None:
    experience_map = two_keyframe_map()
    assert experience_map.close_loop(closure(1, 0, np.eye(4)), cells((0, 0, 0), 18))


def test_a_closure_of_an_unknown_keyframe_is_neither_accepted_nor_rejected() -> None:
    experience_map = two_keyframe_map()
    assert not experience_map.close_loop(closure(5, 0, np.eye(4)), cells())
    assert not experience_map.close_loop(closure(1, 7, np.eye(4)), cells())
    assert experience_map.accepted_closures == [] and experience_map.rejected_closures == []
    assert len(experience_map.graph.links) == 1


def long_drive_map(gate: str, metres: float, **update) -> ExperienceMap:
    """Keyframe 0 at cells (0, 0, 0), then `metres` of travel to keyframe 1, whose cells are 12 bins from it: the
    odometry drifted on the way (5 cells beyond the paper's 7)."""
    experience_map = new_map(closure_gate=gate, **update)
    experience_map.step(0, np.eye(4), VELOCITIES, cells((0, 0, 0)), 0.0, 0)
    experience_map.step(1, pose(0.0, (metres, 0, 0)), VELOCITIES, cells((12, 0, 0)), metres, 1)
    return experience_map


@pytest.mark.parametrize(
    ("gate", "metres", "accepted"),
    [
        ("grid-cells", 1000.0, False),  # the paper's check: 12 cells > 7
        ("drift", 1000.0, True),  # 12 <= 7 + 2 x 10
        ("drift", 200.0, False),  # 12 > 7 + 2 x 2: too far for 200 m of drift
        ("drift", 250.0, True),  # at the edge: 7 + 2 x 2.5
        ("none", 0.0, True),
    ],
)
def test_the_drift_gate_admits_the_drift_of_the_metres_since_the_stored_experience(
    gate: str, metres: float, accepted: bool
) -> None:
    experience_map = long_drive_map(gate, metres)
    assert experience_map.close_loop(closure(1, 0, np.eye(4)), cells((12, 0, 0))) is accepted
    assert len(experience_map.rejected_closures) == (not accepted)


def test_the_drift_gate_is_the_papers_check_soon_after_a_recall_at_the_candidate() -> None:
    """After 1 km without a closure the gate admits 27 cells; a recall at the stored experience re-anchors the cells
    there, and 50 m later a closure whose cells are 10 bins off (implausible after 50 m of drift) is rejected,
    although the stored experience was made 1050 m before."""
    experience_map = long_drive_map("drift", 1000.0)
    assert experience_map.close_loop(closure(1, 0, np.eye(4)), cells((12, 0, 0)))
    experience_map.recalled(0, cells((0.5, 0, 0)), cells((0.5, 0, 0)))
    experience_map.step(2, pose(0.0, (1050, 0, 0)), VELOCITIES, cells((10, 0, 0)), 50.0, 2)

    implausible = closure(2, 0, np.eye(4))
    assert not experience_map.close_loop(implausible, cells((10, 0, 0)))  # 10 > 7 + 2 x 0.5
    assert experience_map.rejected_closures == [implausible]
    assert experience_map.close_loop(closure(2, 0, np.eye(4)), cells((8, 0, 0)))  # 8 <= 8


def test_the_drift_gate_follows_the_chain_through_a_recalled_place_to_the_candidate() -> None:
    """Keyframe 0, then 1 km to keyframe 1, then 10 m to keyframe 2. A recall at keyframe 1's experience re-anchors
    the cells there; 10 m on, a closure with keyframe 0 is judged over the 1 km that separates keyframe 1's cells
    from keyframe 0's, not over the 10 m since the recall."""
    experience_map = long_drive_map("drift", 1000.0)
    experience_map.step(2, pose(0.0, (1010, 0, 0)), VELOCITIES, cells((13, 0, 0)), 10.0, 2)
    experience_map.recalled(1, cells((12, 0, 0)), cells((12, 0, 0)))
    experience_map.step(3, pose(0.0, (1020, 0, 0)), VELOCITIES, cells((13, 0, 0)), 10.0, None)

    assert experience_map.lineage.chain_metres(0) == pytest.approx(1010.0)
    assert experience_map.close_loop(closure(2, 0, np.eye(4)), cells((13, 0, 0)))  # 13 <= 7 + 2 x 10.1


def test_a_recall_the_cells_did_not_take_leaves_the_chain_as_it_was() -> None:
    """The cells stayed 10 bins from the recalled place (the injection lost against their packet): they are not
    anchored there, and the gate still judges by the metres since keyframe 0 was made."""
    experience_map = long_drive_map("drift", 1000.0)
    experience_map.recalled(0, cells((10, 0, 0)), cells((0, 0, 0)))
    assert experience_map.lineage.anchor == 1
    assert experience_map.lineage.chain_metres(0) == pytest.approx(1000.0)
    experience_map.recalled(0, cells((1, 0, 0)), cells((0, 0, 0)))  # within S_max (3 cells) of the place: taken
    assert experience_map.lineage.anchor == 0 and experience_map.lineage.chain_metres(0) == 0.0


def test_the_drift_gate_also_decides_which_closures_are_revisits() -> None:
    """recognise (lifelong mapping) asks the same gate as close_loop."""
    relative = pose(0.0, (0.5, 0.0, 0.0))
    for gate, revisit in (("grid-cells", False), ("drift", True)):
        experience_map = long_drive_map(gate, 1000.0, reentry_distance=1000.0)
        experience_map.step(2, pose(0.0, (1000.5, 0, 0)), VELOCITIES, cells((12, 0, 0)), 0.5, None)
        found = experience_map.recognise(2, [closure(2, 0, relative)], cells((12, 0, 0)), pose(0.0, (1000.5, 0, 0)))
        assert (found is not None) is revisit


@pytest.mark.parametrize(
    "update",
    [{"closure_gate": "mahalanobis"}, {"gc_drift_cells_per_100m": -1.0}, {"gc_drift_cells_per_100m": float("inf")}],
)
def test_the_closure_gate_settings_are_checked(update: dict) -> None:
    with pytest.raises(ValidationError):
        ExperienceMapConfig(**update)


def test_a_rejected_closure_leaves_the_map(biased_square) -> None:
    for backend in ("relaxation", "pose-graph"):
        experience_map, truth, _ = driven_square(biased_square, backend)
        before = experience_map.graph.poses.copy()
        assert not experience_map.close_loop(loop_back_to_start(biased_square, truth), cells((18, 18, 18)))
        experience_map.correct()
        np.testing.assert_array_equal(experience_map.graph.poses, before)
        assert all(k.kind == "odometry" for k in experience_map.graph.links)


def test_pose_graph_backend_corrects_the_map_at_once(biased_square) -> None:
    experience_map, truth, odometry = driven_square(biased_square, "pose-graph")
    frames = [e.frame_index for e in experience_map.experiences]
    drift_gap = np.linalg.norm(odometry[biased_square.lap, :3, 3] - odometry[0, :3, 3])
    drift_ate = ate(experience_map.graph.poses, truth[frames])

    assert experience_map.close_loop(loop_back_to_start(biased_square, truth), cells())

    assert drift_gap > 1.0
    # a least-squares compromise (loop_sigma 0.5 m against 20 odometry links), not an exact fit
    assert experience_map.graph.link_residuals()[-1] < drift_gap / 10
    assert ate(experience_map.graph.poses, truth[frames]) < drift_ate / 10
    before = experience_map.graph.poses.copy()
    experience_map.correct()  # nothing more to do per frame
    np.testing.assert_array_equal(experience_map.graph.poses, before)


def test_relaxation_backend_corrects_the_map_frame_by_frame(biased_square) -> None:
    experience_map, truth, _ = driven_square(biased_square, "relaxation")
    frames = [e.frame_index for e in experience_map.experiences]
    experience_map.correct()  # no loop yet: nothing to relax
    np.testing.assert_allclose(experience_map.graph.link_residuals(), 0.0, atol=1e-9)
    before = experience_map.graph.poses.copy()
    drift_ate = ate(before, truth[frames])

    assert experience_map.close_loop(loop_back_to_start(biased_square, truth), cells())
    np.testing.assert_array_equal(experience_map.graph.poses, before)  # the closure alone moves nothing
    gap = experience_map.graph.link_residuals()[-1]
    experience_map.correct()
    assert experience_map.graph.link_residuals()[-1] < gap
    for _ in range(200):
        experience_map.correct()

    assert gap > 1.0
    assert experience_map.graph.link_residuals()[-1] < 0.01
    assert ate(experience_map.graph.poses, truth[frames]) < drift_ate / 10


# ---------------------------------------------------------------------------------------------------------------
# Trajectory and keyframe points


def test_trajectory_without_correction_is_the_odometry(biased_square) -> None:
    experience_map, _, odometry = driven_square(biased_square, "relaxation")
    stamps = 0.1 * np.arange(len(odometry))
    trajectory = experience_map.trajectory(stamps, odometry)
    assert len(trajectory) == len(odometry)
    np.testing.assert_array_equal(trajectory.timestamps, stamps)
    np.testing.assert_allclose(trajectory.poses, odometry, atol=1e-9)


def test_trajectory_frames_follow_their_experience(biased_square) -> None:
    experience_map, truth, odometry = driven_square(biased_square, "pose-graph")
    experience_map.close_loop(loop_back_to_start(biased_square, truth), cells())
    stamps = 0.1 * np.arange(len(odometry))

    trajectory = experience_map.trajectory(stamps, odometry)

    assert len(trajectory) == len(odometry)
    for experience in experience_map.experiences:
        first = experience.frame_index
        np.testing.assert_allclose(trajectory.poses[first], experience_map.graph.poses[experience.id], atol=1e-9)
        for frame in range(first, min(first + KEYFRAME_EVERY, len(odometry))):  # frames it owns
            np.testing.assert_allclose(
                relative_pose(trajectory.poses[first], trajectory.poses[frame]),
                relative_pose(odometry[first], odometry[frame]),
                atol=1e-9,
            )
    assert ate(trajectory.poses, truth) < ate(odometry, truth) / 5
    # the online pose of the last frame is the trajectory's
    np.testing.assert_allclose(experience_map.current_pose(odometry[-1]), trajectory.poses[-1], atol=1e-9)


def test_trajectory_moves_with_a_known_correction() -> None:
    experience_map = new_map()
    odometry = np.array([pose(0.1 * k, (k, 0.2 * k, 0)) for k in range(8)])
    for frame, odometry_pose in enumerate(odometry):
        experience_map.step(frame, odometry_pose, VELOCITIES, cells(), 1.0, {0: 0, 4: 1}.get(frame))
    correction = pose(-0.4, (2.0, 3.0, -1.0))
    experience_map.graph.poses[1] = correction @ experience_map.graph.poses[1]

    poses = experience_map.trajectory(np.arange(8.0), odometry).poses

    np.testing.assert_allclose(poses[:4], odometry[:4], atol=1e-12)
    np.testing.assert_allclose(poses[4:], correction @ odometry[4:], atol=1e-12)
    anchor, anchor_from_robot = experience_map.anchor(odometry[6])
    assert anchor == 1
    np.testing.assert_allclose(anchor_from_robot, relative_pose(odometry[4], odometry[6]), atol=1e-12)


def test_corrected_points_move_with_their_experience() -> None:
    experience_map = new_map()
    odometry = [pose(0.0), pose(0.7, (5, 1, 0)), pose(1.2, (8, 4, 0))]
    for frame, odometry_pose in enumerate(odometry):
        experience_map.step(frame, odometry_pose, VELOCITIES, cells(), 1.0, frame + 10)  # keyframes 10, 11, 12
    points = np.array([[6.0, 3.0, 1.0], [4.0, -2.0, 0.5]])
    np.testing.assert_allclose(experience_map.corrected_points(11, points), points, atol=1e-12)

    correction = pose(0.3, (-1.0, 2.0, 0.4))
    experience_map.graph.poses[1] = correction @ experience_map.graph.poses[1]

    np.testing.assert_allclose(experience_map.corrected_points(11, points), transform_points(correction, points))
    np.testing.assert_allclose(experience_map.corrected_points(10, points), points, atol=1e-12)
    np.testing.assert_allclose(experience_map.corrected_points(12, points), points, atol=1e-12)
    # seen from the corrected experience, the points are where they were seen from its odometry pose
    np.testing.assert_allclose(
        transform_points(invert_pose(experience_map.graph.poses[1]), experience_map.corrected_points(11, points)),
        transform_points(invert_pose(odometry[1]), points),
        atol=1e-12,
    )


def test_trajectory_of_an_empty_map_is_empty() -> None:
    trajectory = new_map().trajectory(np.zeros(0), np.zeros((0, 4, 4)))
    assert len(trajectory) == 0


# ---------------------------------------------------------------------------------------------------------------
# Lifelong mapping: a street driven again re-enters its experiences instead of adding copies (reuse_places)


def drive_laps(experience_map: ExperienceMap, truth: np.ndarray, odometry: np.ndarray, lap: int) -> list[tuple]:
    """Keyframes every KEYFRAME_EVERY frames (ids counting on over the laps); from the second lap on, each keyframe's
    own closure recognises the keyframe of the first lap at that place, with the true relative pose: a revisit where
    the map agrees, else (as the pipeline does) a new keyframe whose closure corrects the map. The map is corrected
    every frame; returns (experiences, links) at the end of each lap."""
    per_lap = lap // KEYFRAME_EVERY
    sizes = []
    for frame, odometry_pose in enumerate(odometry):
        travelled = 0.0 if frame == 0 else float(np.linalg.norm(odometry_pose[:3, 3] - odometry[frame - 1][:3, 3]))
        keyframe = frame // KEYFRAME_EVERY if frame % KEYFRAME_EVERY == 0 else None
        revisit, closures = None, []
        if keyframe is not None and keyframe >= per_lap:
            stored = keyframe % per_lap
            closures = [closure(keyframe, stored, relative_pose(truth[KEYFRAME_EVERY * stored], truth[frame]))]
            revisit = experience_map.recognise(keyframe, closures, cells(), odometry_pose)
            assert revisit is None or revisit.keyframe == stored
        experience_map.step(frame, odometry_pose, VELOCITIES, cells(), travelled, keyframe, revisit)
        if closures and revisit is None:
            assert experience_map.close_loop(closures[0], cells())
        experience_map.correct()
        if (frame + 1) % lap == 0:
            sizes.append((len(experience_map.experiences), len(experience_map.graph.links)))
    return sizes


@pytest.mark.parametrize("backend", ["pose-graph", "relaxation"])
def test_a_lap_driven_again_reenters_the_experiences_of_the_first(biased_square, backend: str) -> None:
    """Lap 1 drifts (11 degrees of yaw bias a lap): the first closures of lap 2 find the map off and correct it
    (new experiences with loop links, as the paper); once the map agrees, lap 2 re-enters lap 1's experiences, each
    the first time with a loop link from the one before (the street measured a second time), and the later laps add
    nothing but, once, a link between experiences not moved between before (lap 2 ended in lap 1's last experience,
    and lap 3 moves on from it to the first)."""
    truth = biased_square.truth(laps=4)
    odometry = biased_square.dead_reckoned(truth)
    experience_map = new_map(backend=backend)
    sizes = drive_laps(experience_map, truth, odometry, biased_square.lap)

    per_lap = biased_square.lap // KEYFRAME_EVERY
    (first, first_links), (second, second_links), (third, third_links), fourth = sizes
    assert first == per_lap and first_links == per_lap - 1
    assert per_lap < second <= per_lap + 5  # the closures that corrected the map
    assert third == second and third_links - second_links <= 1  # the third lap re-enters only
    assert fourth == (third, third_links)
    links = [(k.source, k.target, k.kind) for k in experience_map.graph.links]
    assert links[: per_lap - 1] == [(i, i + 1, "odometry") for i in range(per_lap - 1)]
    loops = [link for link in links if link[2] == "loop"]
    assert per_lap - 2 <= len(loops) <= per_lap + 2 * (second - per_lap) + 1
    assert len(experience_map.accepted_closures) == 3 * per_lap
    trajectory = experience_map.trajectory(np.arange(len(truth), dtype=float), odometry)
    later = slice(biased_square.lap, None)
    assert ate(trajectory.poses[later], truth[later]) < 0.2 * ate(odometry[later], truth[later])
    # within a visit the trajectory follows the odometry; the last frame's online pose is the trajectory's
    np.testing.assert_allclose(experience_map.current_pose(odometry[-1]), trajectory.poses[-1], atol=1e-9)


def test_a_closure_is_a_revisit_only_where_the_cells_heading_and_map_agree(biased_square) -> None:
    truth = biased_square.truth()
    odometry = biased_square.dead_reckoned(truth)
    experience_map = new_map()
    drive(experience_map, odometry[:50])
    # where the map has the robot (frame 48) seen from keyframe 8's experience (made at frame 40, on the same side)
    in_map = invert_pose(experience_map.graph.poses[8]) @ experience_map.current_pose(odometry[48])
    agreeing = closure(10, 8, in_map @ pose(0.02, (0.5, -0.5, 0.0)))
    assert experience_map.recognise(10, [agreeing], cells(), odometry[48]).keyframe == 8
    assert experience_map.recognise(10, [agreeing], cells((8, 0, 0)), odometry[48]) is None  # cells 8 bins off
    off = closure(10, 8, in_map @ pose(0.0, (1.5, 1.5, 0.0)))  # 2.1 m from where the map has the robot
    assert experience_map.recognise(10, [off], cells(), odometry[48]) is None
    higher = closure(10, 8, in_map @ pose(0.0, (0.0, 0.0, 3.0)))  # height does not count: a closure's is rough
    assert experience_map.recognise(10, [higher], cells(), odometry[48]) is not None
    turned_map = closure(10, 8, in_map @ pose(np.radians(4.0)))  # turned 4 degrees from the map
    assert experience_map.recognise(10, [turned_map], cells(), odometry[48]) is None
    # a stored keyframe seen the other way is another experience, even where the map agrees
    backwards = new_map(reentry_yaw_deg=180.0)
    drive(backwards, odometry[:50])
    turned = closure(10, 8, in_map @ pose(np.radians(60.0)))  # beyond reuse_max_turn_deg (45)
    assert backwards.recognise(10, [turned], cells(), odometry[48]) is None
    assert new_map(reuse_places=False).recognise(10, [agreeing], cells(), odometry[48]) is None


def test_while_localised_a_keyframe_at_a_stored_one_is_a_revisit_without_a_closure(biased_square) -> None:
    truth = biased_square.truth(laps=2)
    odometry = biased_square.dead_reckoned(truth)
    experience_map = new_map(localised_distance=8.0)
    per_lap = biased_square.lap // KEYFRAME_EVERY
    drive(experience_map, odometry[: biased_square.lap])
    assert experience_map.recognise(per_lap, [], cells(), odometry[biased_square.lap]) is None  # not localised
    # a closure at the first keyframe of lap 2 finds the map off (lap 1 drifted): a new experience and a loop
    # link correct it ...
    frame = biased_square.lap
    first = closure(per_lap, 0, relative_pose(truth[0], truth[frame]))
    assert experience_map.recognise(per_lap, [first], cells(), odometry[frame]) is None
    experience_map.step(frame, odometry[frame], VELOCITIES, cells(), 1.0, per_lap)
    assert experience_map.close_loop(first, cells())
    for frame in range(biased_square.lap + 1, biased_square.lap + KEYFRAME_EVERY):
        experience_map.step(frame, odometry[frame], VELOCITIES, cells(), 1.0, None)
    # ... and the next keyframe, 5 m on, is found at stored keyframe 1 in the corrected map
    frame = biased_square.lap + KEYFRAME_EVERY
    found = experience_map.recognise(per_lap + 1, [], cells(), odometry[frame])
    assert found is not None and found.keyframe == 1 and found.closure is None
    np.testing.assert_allclose(found.robot_in_experience[:3, 3], 0.0, atol=0.3)  # it is where keyframe 1 was made
    links = len(experience_map.graph.links)
    experience_map.step(frame, odometry[frame], VELOCITIES, cells(), 1.0, per_lap + 1, found)
    assert len(experience_map.experiences) == per_lap + 1 and experience_map.current == 1
    assert len(experience_map.graph.links) == links  # a revisit found in the map adds no link
    # the pose does not jump where the robot re-enters by the map
    trajectory = experience_map.trajectory(np.arange(frame + 1.0), odometry[: frame + 1])
    step = relative_pose(trajectory.poses[frame - 1], trajectory.poses[frame])
    np.testing.assert_allclose(step, relative_pose(odometry[frame - 1], odometry[frame]), atol=1e-9)
    # 8 m after the closure the robot no longer knows where it is: a new keyframe is new
    entered = frame
    for frame in range(entered + 1, entered + 5):
        experience_map.step(frame, odometry[frame], VELOCITIES, cells(), 1.0, None)
    assert experience_map.recognise(per_lap + 2, [], cells(), odometry[entered + 4]) is None


def test_a_late_closure_of_a_merged_keyframe_links_where_it_was_merged(biased_square) -> None:
    truth = biased_square.truth(laps=2)
    odometry = truth  # no drift: the map agrees with every closure
    experience_map = new_map()
    per_lap = biased_square.lap // KEYFRAME_EVERY
    drive(experience_map, odometry[: biased_square.lap])
    frame = biased_square.lap
    # the first keyframe of lap 2 is merged into stored keyframe 0 by its own closure ...
    relative = relative_pose(truth[0], truth[frame])
    revisit = experience_map.recognise(per_lap, [closure(per_lap, 0, relative)], cells(), odometry[frame])
    assert revisit is not None
    experience_map.step(frame, odometry[frame], VELOCITIES, cells(), 1.0, per_lap, revisit)
    links = len(experience_map.graph.links)
    assert len(experience_map.experiences) == per_lap
    # ... a later closure naming it (against keyframe 1) relates experience 0 to experience 1: they are linked by
    # the odometry where the closure puts them, so nothing is added, but the closure counts as accepted
    late = closure(per_lap, 1, relative_pose(truth[KEYFRAME_EVERY], truth[frame]))
    assert experience_map.close_loop(late, cells())
    assert len(experience_map.graph.links) == links
    # one that puts them 3 m further apart is news: a loop link from keyframe 1's experience to experience 0
    off = closure(per_lap, 1, relative_pose(truth[KEYFRAME_EVERY], truth[frame]) @ pose(0.0, (3.0, 0.0, 0.0)))
    assert experience_map.close_loop(off, cells())
    assert [(k.source, k.target, k.kind) for k in experience_map.graph.links[links:]] == [(1, 0, "loop")]
    # unknown keyframes are not closures of the map
    assert not experience_map.close_loop(closure(per_lap + 7, 1, np.eye(4)), cells())


# ---------------------------------------------------------------------------------------------------------------
# Sessions: a later session joins a stored map (neoslam.store)


def street_map(length: int) -> ExperienceMap:
    """A map of a straight street driven east, a metre a frame, a keyframe every KEYFRAME_EVERY frames."""
    stored = new_map()
    drive(stored, np.array([pose(0.0, (float(x), 0.0, 0.0)) for x in range(length)]))
    return stored


def later_session(stored: ExperienceMap) -> ExperienceMap:
    """A new session over the stored map, in its own frame: session 2, with no experience yet."""
    experience_map = new_map()
    state = MapState(
        keyframe_experience=dict(stored.keyframe_experiences),
        experiences=stored.experiences,
        experience_poses=stored.graph.poses.copy(),
        links=stored.graph.links,
    )
    experience_map.restore(state, session=2)
    return experience_map


def test_a_session_driving_the_street_the_other_way_joins_the_map_once() -> None:
    # The stored street runs east from x = 0 to 59; the session starts at x = 50 facing west (its frame's origin)
    # and drives west. Its first closure, stored keyframe 10 (x = 50) seen from the other side, joins it to the map;
    # from then on its closures are loop links in one map (driving against the map it re-enters no stored
    # experience, and the join used to be all that tied the two, so every later closure joined the session again).
    stored = street_map(60)
    experience_map = later_session(stored)
    first = max(stored.keyframe_experiences) + 1  # the session's keyframe ids follow the stored ones
    turned = pose(np.pi)  # T_stored_query: the same place, facing the other way
    odometry = [pose(0.0, (float(x), 0.0, 0.0)) for x in range(12)]  # the session's own frame: forward is west
    experience_map.step(0, odometry[0], VELOCITIES, cells(), 0.0, first)
    assert experience_map.join(closure(first, 10, turned), experience_map.current_pose(odometry[0]))
    assert len(experience_map.parts.roots()) == 1
    links = len(experience_map.graph.links)
    assert experience_map.close_loop(closure(first, 10, turned), cells())  # accepted, and linked by the join
    assert len(experience_map.graph.links) == links
    for frame in range(1, 6):
        experience_map.step(frame, odometry[frame], VELOCITIES, cells(), 1.0, first + 1 if frame == 5 else None)
    later = closure(first + 1, 9, turned)  # five metres on, stored keyframe 9 (x = 45)
    assert not experience_map.join(later, experience_map.current_pose(odometry[5]))
    assert experience_map.close_loop(later, cells())
    assert [k.kind for k in experience_map.graph.links[links:]] == ["odometry", "loop"]
    # the session is in the map's frame, at x = 45 heading west
    np.testing.assert_allclose(experience_map.current_pose(odometry[5]), pose(np.pi, (45.0, 0.0, 0.0)), atol=1e-9)
