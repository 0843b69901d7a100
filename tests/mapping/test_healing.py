"""A map that heals: a wrong loop link the optimised map disagrees with is withdrawn and the map recovers; true ones
stay, and a link that alone ties two stretches of the map is kept."""

from __future__ import annotations

import numpy as np
import pytest
from tests.mapping.objects_seen import FakeObjectMap, object_positions

from neoslam.config import ExperienceMapConfig
from neoslam.geometry import make_pose, relative_pose
from neoslam.mapping.experience_map import CellState, ExperienceMap
from neoslam.mapping.graph import MapGraph
from neoslam.mapping.healing import disagreeing_link
from neoslam.mapping.pose_graph import LoopResidual, PoseGraphReport
from neoslam.types import Link, LoopClosure

KEYFRAME_EVERY = 5
WRONG_OFFSET_M = 20.0
STILL = CellState(np.zeros(3), 0.0)
VELOCITIES = (np.array([1.0, 0.0, 0.0]), np.zeros(3))


def two_lap_map(
    square, wrong: bool, noise=None, landmarks: bool = False, until: int | None = None, **update
) -> tuple[ExperienceMap, np.ndarray, int]:
    """Two laps of the yaw-biased square; the second lap closes with the first at each corner (every 25 frames) at
    the true relative pose, and with `wrong` one closure (frame 140 onto frame 40) is 20 m off. The odometry model
    is honest about the square's bias (or as `update` states it, with the odometry's `noise` per root second given
    as the session's estimate; a frame a second), every closure passes the gate. With `landmarks`, the objects
    along the square's sides are landmarks of the pose graph (iSAM2), seen from each experience's true pose;
    `until`: the map as the closure at that frame leaves it, not finished. Returns the map, the truth and the wrong
    link's index."""
    config = ExperienceMapConfig(
        odometry_yaw_sigma_per_root_metre=0.01 * np.sqrt(square.step_m),
        odometry_sigma_per_root_metre=0.05 * np.sqrt(square.step_m),
        closure_gate="none",
        reuse_places=False,
    ).model_copy(update={"object_landmarks": landmarks, **update})
    experience_map = ExperienceMap(config, (36, 36, 36), 36)
    experience_map.backend.odometry_noise = noise
    objects, positions = FakeObjectMap(), object_positions(square)
    if landmarks:
        experience_map.backend.landmark_source = objects
    truth = square.truth(laps=2)
    odometry = square.dead_reckoned(truth)
    wrong_link = -1
    per_lap = square.lap // KEYFRAME_EVERY
    for frame, pose in enumerate(odometry):
        travelled = 0.0 if frame == 0 else float(np.linalg.norm(pose[:3, 3] - odometry[frame - 1][:3, 3]))
        keyframe = frame // KEYFRAME_EVERY if frame % KEYFRAME_EVERY == 0 else None
        made = len(experience_map.experiences)
        experience_map.step(frame, pose, VELOCITIES, STILL, travelled, keyframe, elapsed_s=0.0 if frame == 0 else 1.0)
        for experience in experience_map.experiences[made:]:
            objects.see(experience.id, truth[experience.frame_index], positions, np.arange(len(positions)))
        if keyframe is None or frame < square.lap or (frame % square.side_nodes and frame != 140):
            continue
        matched = keyframe - per_lap
        relative = relative_pose(truth[matched * KEYFRAME_EVERY], truth[frame])
        if frame == 140:
            if not wrong:
                continue
            matched = 40 // KEYFRAME_EVERY
            relative = make_pose(np.eye(3), [0.0, WRONG_OFFSET_M, 0.0])
            wrong_link = len(experience_map.graph.links)
        closure = LoopClosure(frame, matched * KEYFRAME_EVERY, keyframe, matched, 3.0, 6, relative)
        assert experience_map.close_loop(closure, STILL)
        if frame == until:
            return experience_map, truth, wrong_link
    experience_map.finish()
    return experience_map, truth, wrong_link


def trajectory_error(experience_map: ExperienceMap, truth: np.ndarray) -> float:
    """RMS position error of the experiences (keyframes' true poses; experience 0 anchors both frames)."""
    frames = [experience.frame_index for experience in experience_map.experiences]
    errors = experience_map.graph.poses[:, :3, 3] - truth[frames, :3, 3]
    return float(np.sqrt(np.mean(np.sum(errors**2, axis=1))))


def test_a_wrong_closure_is_withdrawn_and_the_map_recovers(biased_square) -> None:
    clean, truth, _ = two_lap_map(biased_square, wrong=False)
    healed, _, wrong_link = two_lap_map(biased_square, wrong=True)
    kept, _, _ = two_lap_map(biased_square, wrong=True, withdraw_sigmas=0.0)

    assert clean.withdrawn_links == []
    assert healed.withdrawn_links == [wrong_link]
    assert kept.withdrawn_links == []
    assert trajectory_error(healed, truth) <= 1.05 * trajectory_error(clean, truth)
    assert trajectory_error(kept, truth) > 1.5 * trajectory_error(clean, truth)


def test_with_object_landmarks_a_wrong_closure_is_withdrawn_from_the_solver_and_the_map_recovers(
    biased_square,
) -> None:
    clean, truth, _ = two_lap_map(biased_square, wrong=False, landmarks=True)
    healed, _, wrong_link = two_lap_map(biased_square, wrong=True, landmarks=True)
    kept, _, _ = two_lap_map(biased_square, wrong=True, landmarks=True, withdraw_sigmas=0.0)

    assert clean.backend.landmark_solver is not None and clean.backend.landmark_solver.landmarks
    assert clean.withdrawn_links == []
    assert healed.withdrawn_links == [wrong_link]
    assert kept.withdrawn_links == []
    assert trajectory_error(healed, truth) <= 1.05 * trajectory_error(clean, truth)
    # kept, the map still holds the wrong link, though the landmarks keep the map from following it; healed, the
    # link is out of the graph and its factor out of the solver
    assert kept.graph.link_residuals()[wrong_link] > 0.5 * WRONG_OFFSET_M
    assert wrong_link not in healed.graph.live()
    solver = healed.backend.landmark_solver
    assert wrong_link not in solver._loop_factors
    in_solver = solver._isam.getFactorsUnsafe()  # each loop link's factor where the solver holds it
    for link_index, factor in solver._loop_factors.items():
        link = healed.graph.links[link_index]
        assert list(in_solver.at(factor).keys()) == [link.source, link.target]


@pytest.mark.parametrize(
    ("rule", "landmarks", "unlocalised"),
    [
        ("with-landmarks", True, True),
        ("with-landmarks", False, False),
        ("always", False, True),
        ("never", True, False),
    ],
)
def test_a_withdrawn_closure_leaves_the_robot_not_localised_as_configured(
    biased_square, rule: str, landmarks: bool, unlocalised: bool
) -> None:
    """The closure that localised the robot was the wrong one: once withdrawn, no experience is re-entered by
    position (nor an old landmark view trusted) until the next recognised place, with landmarks by default."""
    clean, _, _ = two_lap_map(biased_square, wrong=False, landmarks=landmarks, until=125, unlocalise_on_withdrawal=rule)
    healed, _, wrong_link = two_lap_map(
        biased_square, wrong=True, landmarks=landmarks, until=140, unlocalise_on_withdrawal=rule
    )
    assert clean.localised
    assert healed.withdrawn_links == [wrong_link]
    assert healed.localised != unlocalised


def test_a_withdrawn_pair_can_be_linked_again(biased_square) -> None:
    healed, _, wrong_link = two_lap_map(biased_square, wrong=True)
    link = healed.graph.links[wrong_link]
    assert not healed._is_linked(link.source, link.target)
    assert wrong_link not in healed.graph.live()
    assert len(healed.graph.live_links()) == len(healed.graph.links) - 1


def report_of(*loops: tuple[int, float]) -> PoseGraphReport:
    residuals = tuple(LoopResidual(index, 0.0, sigmas, 1.0) for index, sigmas in loops)
    return PoseGraphReport(iterations=1, initial_error=0.0, final_error=0.0, loops=residuals)


def chain_with_loops() -> MapGraph:
    """Four experiences in a row (odometry 0-1-2), a fourth tied to the rest by loop links only (3->0 and 2->3)."""
    graph = MapGraph(np.tile(np.eye(4), (4, 1, 1)))
    for source in range(2):
        graph.add_link(Link(source, source + 1, np.eye(4), "odometry", 1.0))
    graph.add_link(Link(0, 2, np.eye(4), "loop", 0.0))  # 2
    graph.add_link(Link(2, 3, np.eye(4), "loop", 0.0))  # 3: the only tie of experience 3
    return graph


@pytest.mark.parametrize(
    ("loops", "expected"),
    [
        (((2, 1.0), (3, 1.0)), None),  # every loop link agrees
        (((2, 5.0), (3, 1.0)), 2),  # beyond 3 sigmas, the odometry still joins 0 and 2
        (((2, 4.0), (3, 9.0)), 2),  # 3 disagrees most, but it alone ties experience 3: the next is withdrawn
        (((3, 9.0),), None),
    ],
)
def test_the_worst_disagreeing_link_that_is_not_the_only_tie_is_chosen(loops, expected) -> None:
    graph = chain_with_loops()
    assert disagreeing_link(graph, report_of(*loops), np.ones(4, dtype=bool), 3.0) == expected


def test_withdraw_sigmas_zero_never_withdraws() -> None:
    assert disagreeing_link(chain_with_loops(), report_of((2, 50.0)), np.ones(4, dtype=bool), 0.0) is None


def test_odometry_weighted_by_its_noise_per_second_keeps_the_true_closures(biased_square) -> None:
    """The distance rates stated ten times too small: true closures disagree with the map and are withdrawn. With
    the odometry's noise per root second (as the moving-object tracks estimate it) the links' time makes up for it."""
    step = biased_square.step_m  # a frame a second: per root second, the honest rates per root metre times sqrt(step)
    overconfident = {"odometry_yaw_sigma_per_root_metre": 0.001 * np.sqrt(step),
                     "odometry_sigma_per_root_metre": 0.005 * np.sqrt(step)}  # fmt: skip
    stated, _, _ = two_lap_map(biased_square, wrong=False, **overconfident)
    estimated, truth, _ = two_lap_map(biased_square, wrong=False, noise=(0.01 * step, 0.05 * step), **overconfident)
    clean, _, _ = two_lap_map(biased_square, wrong=False)
    assert len(stated.withdrawn_links) > 0
    assert estimated.withdrawn_links == []
    assert trajectory_error(estimated, truth) == pytest.approx(trajectory_error(clean, truth), rel=1e-6)
    odometry = [link for link in estimated.graph.links if link.kind == "odometry"]
    assert {link.duration_s for link in odometry} == {float(KEYFRAME_EVERY)}
