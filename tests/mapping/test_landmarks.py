"""Object landmarks in the pose graph (neoslam.mapping.landmarks): a yaw-biased square whose odometry drifts, with
parked objects along its sides seen from every node within range, fed to the iSAM2 solver node by node."""

from __future__ import annotations

import gtsam
import numpy as np
import pytest
from tests.mapping.objects_seen import FakeObjectMap, object_positions

from neoslam.config import ExperienceMapConfig, NeoSLAMConfig, ObjectMapConfig
from neoslam.datasets.simulated import read_dataset
from neoslam.evaluation.trajectory_metrics import absolute_trajectory_error
from neoslam.geometry import invert_pose
from neoslam.mapping.graph import MapGraph
from neoslam.mapping.landmarks import LandmarkSolver, landmark_key
from neoslam.pipeline import NeoSLAM
from neoslam.types import Link


def drive(square, config: ExperienceMapConfig, ids=None, merge_at=None, wrong=None):
    """Drive one lap node by node: dead-reckoned nodes and odometry links, the views of the node just left added
    to the solver at each step. `ids`: object ids per node (default the objects' own); `merge_at`: (node, gone,
    kept), a merge at that node; `wrong`: (node, object, offset), one view of that object placed `offset` off.
    Returns the graph, the truth, the solver and the fake object map."""
    truth = square.truth(closed=True)
    positions = object_positions(square)
    steps = square.odometry_steps(truth)
    graph, objects, solver = MapGraph(truth[:1].copy()), FakeObjectMap(), LandmarkSolver(config)
    for node in range(len(truth)):
        if node:
            graph.add_node(graph.poses[-1] @ steps[node - 1])
            graph.add_link(Link(node - 1, node, steps[node - 1], "odometry", square.step_m))
        own = np.arange(len(positions)) if ids is None else ids(node)
        seen = positions.copy()
        if wrong is not None and wrong[0] == node:
            seen[wrong[1]] += wrong[2]
        objects.see(node, truth[node], seen, own)
        if merge_at is not None and merge_at[0] == node:
            objects.merge(merge_at[1], merge_at[2])
        solver.update(graph, np.ones(len(graph), bool), objects, np.array([node - 1]), node)
    solver.update(graph, np.ones(len(graph), bool), objects, np.array([len(truth) - 1]), -1, iterations=5)
    return graph, truth, solver, objects


def ate(poses: np.ndarray, truth: np.ndarray) -> float:
    return float(np.sqrt(np.mean(np.sum((poses[:, :3, 3] - truth[:, :3, 3]) ** 2, axis=1))))


@pytest.fixture(scope="module")
def config() -> ExperienceMapConfig:
    return ExperienceMapConfig(object_landmarks=True)


@pytest.fixture(scope="module")
def clean(biased_square, config):
    return drive(biased_square, config)


def test_landmarks_pull_drifting_odometry_back(biased_square, clean):
    graph, truth, solver, _ = clean
    drifted = biased_square.dead_reckoned(truth)
    assert ate(drifted, truth) > 1.0  # 0.2 rad of yaw bias over the lap
    assert ate(graph.poses, truth) < 0.1 * ate(drifted, truth)
    assert len(solver.landmarks) == len(object_positions(biased_square))


@pytest.mark.slow
def test_a_wrong_association_is_down_weighted(biased_square, config, clean):
    """One view of an object placed 3 m off (another object's place): the robust kernel keeps the map."""
    wrong = drive(biased_square, config, wrong=(50, 3, np.array([3.0, 0.0, 0.0])))[0]
    gaussian = ExperienceMapConfig(object_landmarks=True, landmark_robust_kernel="none")
    bent = drive(biased_square, gaussian, wrong=(50, 3, np.array([3.0, 0.0, 0.0])))[0]
    shift = np.abs(wrong.poses[:, :3, 3] - clean[0].poses[:, :3, 3]).max()
    assert shift < 0.5 * np.abs(bent.poses[:, :3, 3] - clean[0].poses[:, :3, 3]).max()
    assert ate(wrong.poses, clean[1]) < 1.5 * ate(clean[0].poses, clean[1]) + 0.01


def test_a_merge_adds_each_view_once(biased_square, config, clean):
    """Object 0 is seen as a new object (id 99) from node 10, until the map merges the two at node 30: the views
    re-filed to object 0 are not added again, and the map is the one of a drive that never split the object."""
    count = len(object_positions(biased_square))

    def ids(node: int) -> np.ndarray:
        own = np.arange(count)
        if 10 <= node < 30:
            own[0] = 99
        return own

    graph, truth, solver, objects = drive(biased_square, config, ids=ids, merge_at=(30, 99, 0))
    assert {0, 99} <= solver.landmarks
    views = len({(o, n) for o, n, _ in objects.pairs})  # one factor per (object, node): each node is left once
    links = len(graph.links) + 1  # and the anchor prior
    assert solver._isam.getFactorsUnsafe().size() == views + links
    assert np.linalg.norm(solver.landmark_position(0) - solver.landmark_position(99)) < 0.1
    assert np.abs(graph.poses[:, :3, 3] - clean[0].poses[:, :3, 3]).max() < 0.1


def test_incremental_equals_batch(biased_square, clean):
    """iSAM2's result against Levenberg-Marquardt on the same factors, from the dead-reckoned poses."""
    graph, truth, solver, _ = clean
    factors = solver._isam.getFactorsUnsafe()
    initial = gtsam.Values()
    drifted = biased_square.dead_reckoned(truth)
    for node, pose in enumerate(drifted):
        initial.insert(node, gtsam.Pose3(pose))
    for obj in sorted(solver.landmarks):
        initial.insert(landmark_key(obj), solver.landmark_position(obj) + 0.5)
    batch = gtsam.LevenbergMarquardtOptimizer(factors, initial).optimize()
    batch_positions = np.array([batch.atPose3(node).translation() for node in range(len(truth))])
    assert np.abs(batch_positions - graph.poses[:, :3, 3]).max() < 0.01


def test_deterministic(biased_square, config, clean):
    again = drive(biased_square, config)[0]
    assert again.poses.tobytes() == clean[0].poses.tobytes()


def test_only_the_views_of_left_nodes_are_added(biased_square, config):
    """Views of the current node wait until the robot leaves it; a repeated update adds nothing twice."""
    truth = biased_square.truth()[:3]
    objects = FakeObjectMap(ObjectMapConfig(min_observations=1))  # one node: every object seen once
    graph = MapGraph(truth[:1].copy())
    solver = LandmarkSolver(config)
    objects.see(0, truth[0], object_positions(biased_square), np.arange(len(object_positions(biased_square))))
    solver.update(graph, np.ones(1, bool), objects, np.array([0]), 0)
    assert not solver.landmarks
    solver.update(graph, np.ones(1, bool), objects, np.array([0]), -1)
    factors = solver._isam.getFactorsUnsafe().size()
    assert solver.landmarks
    solver.update(graph, np.ones(1, bool), objects, np.array([0]), -1)
    assert solver._isam.getFactorsUnsafe().size() == factors
    assert np.allclose(invert_pose(graph.poses[0]) @ truth[0], np.eye(4), atol=1e-6)


@pytest.fixture(scope="module")
def block_frames(block_seed5) -> list:
    dataset = read_dataset(block_seed5)
    return list(dataset.frames()), dataset.ground_truth


def run_block(frames, experience_map: dict, source: bool = True):
    config = NeoSLAMConfig()
    config = config.model_copy(update={"experience_map": config.experience_map.model_copy(update=experience_map)})
    slam = NeoSLAM(config)
    if not source:
        slam.experience_map.backend.landmark_source = None  # the map as it was before landmarks existed
    for frame in frames:
        slam.step(frame)
    return slam.result(np.zeros(len(frames)))


@pytest.mark.slow
def test_switched_off_the_map_is_todays(block_frames, block_seed5_run):
    """block_seed5_run is the default config's run: object_landmarks off, the landmark source in place."""
    frames, _ = block_frames
    today = run_block(frames, {"object_landmarks": False}, source=False).estimate.poses
    assert not block_seed5_run.experience_map.backend.uses_landmarks
    assert block_seed5_run.estimate.poses.tobytes() == today.tobytes()


@pytest.mark.slow
def test_the_relaxation_ignores_the_switch(block_frames):
    frames, _ = block_frames
    relaxed = run_block(frames, {"backend": "relaxation"}).estimate.poses
    switched = run_block(frames, {"backend": "relaxation", "object_landmarks": True}).estimate.poses
    assert switched.tobytes() == relaxed.tobytes()


@pytest.mark.slow
def test_a_run_with_landmarks_is_deterministic_and_no_worse(block_frames, block_seed5_run):
    frames, truth = block_frames
    first = run_block(frames, {"object_landmarks": True})
    second = run_block(frames, {"object_landmarks": True})
    assert first.estimate.poses.tobytes() == second.estimate.poses.tobytes()
    assert first.experience_map.backend.uses_landmarks and first.experience_map.backend.seconds > 0
    off = block_seed5_run  # the default config: object_landmarks off
    assert not off.experience_map.backend.uses_landmarks
    error = absolute_trajectory_error(first.estimate, truth, "se3").rmse
    assert error <= absolute_trajectory_error(off.estimate, truth, "se3").rmse + 0.05


@pytest.mark.slow
def test_a_later_session_rebuilds_the_solver_in_the_joined_map(town_sessions):
    """Town driven in two sessions with landmarks: the second starts its own part, relocalises in the stored map
    and joins it (a rigid move), after which the solver holds the joined part, stored experiences included."""
    config = NeoSLAMConfig()
    config = config.model_copy(
        update={"experience_map": config.experience_map.model_copy(update={"object_landmarks": True})}
    )
    first, second = town_sessions.folders  # the sessions' simulator settings are those of this config
    slam = NeoSLAM(config, None, "a")
    for frame in read_dataset(first).frames():
        slam.step(frame)
    stored = slam.map_state()
    stored_experiences = len(stored.experiences)
    slam = NeoSLAM(config, stored, "b")
    for frame in read_dataset(second).frames():
        slam.step(frame)
    result = slam.result(np.zeros(0))
    assert result.session.relocalised_frame is not None
    solver = result.experience_map.backend.landmark_solver
    assert solver is not None and solver.nodes.min() == 0 and solver.nodes.max() >= stored_experiences


def test_old_landmarks_wait_until_the_robot_knows_where_it_is(biased_square, config):
    """A view of a landmark made long ago counts only while the robot is localised: before a closure, the object
    map associated it by a drifted pose."""
    truth = biased_square.truth()[:2]
    positions = object_positions(biased_square)
    graph = MapGraph(truth.copy(), [Link(0, 1, invert_pose(truth[0]) @ truth[1], "odometry", 1.0)])
    sizes = {}
    for localised in (False, True):
        objects = FakeObjectMap(ObjectMapConfig(min_observations=1))
        solver = LandmarkSolver(config)
        objects.see(0, truth[0], positions, np.arange(len(positions)))
        solver.update(graph, np.ones(2, bool), objects, np.array([0]), 1)
        before = solver._isam.getFactorsUnsafe().size()
        solver.odometer, solver.localised = 2 * config.localised_distance, localised
        objects.see(1, truth[1], positions, np.arange(len(positions)))
        solver.update(graph, np.ones(2, bool), objects, np.array([1]), -1)
        sizes[localised] = solver._isam.getFactorsUnsafe().size() - before
    assert sizes[False] == 0 and sizes[True] > 0


@pytest.mark.parametrize("axis", ["along", "across", "up"])
def test_an_observation_is_uncertain_along_its_ray_and_in_height(axis):
    """A landmark moved one std off a view (ground-plane ray, across it, up) costs one std, whichever way GTSAM's
    Unit3 tangent basis lies: the centre shift's uncertainty (footprint radius) along the ray, the stereo floor
    across it, landmark_height_sigma in height."""
    config = ExperienceMapConfig(object_landmarks=True, landmark_robust_kernel="none")
    objects = ObjectMapConfig()
    solver = LandmarkSolver(config)
    local = np.array([8.0, 4.0, -1.65])
    ground = np.array([local[0], local[1], 0.0]) / np.linalg.norm(local[:2])
    shift = 1.3  # m, a radius of the class's footprint
    weight = 1.0 / objects.position_sigma_floor**2  # a near view: its depth std is the floor
    stds = {
        "along": np.hypot(objects.position_sigma_floor, config.landmark_centre_sigma * shift),
        "across": objects.position_sigma_floor,
        "up": config.landmark_height_sigma,
    }
    direction = {"along": ground, "across": np.cross([0.0, 0.0, 1.0], ground), "up": np.array([0.0, 0.0, 1.0])}
    covariance = solver._point_covariance(local, weight, 1, shift, objects)
    factor = solver._observation_factor(0, 0, local, covariance)
    small = 1e-3  # of a std: the factor is linearised at the measurement
    values = gtsam.Values()
    values.insert(0, gtsam.Pose3())
    values.insert(landmark_key(0), local + small * stds[axis] * direction[axis])
    np.testing.assert_allclose(np.sqrt(2 * factor.error(values)) / small, 1.0, rtol=0.02)


def test_a_frame_that_jumps_far_is_solved():
    """A link of 8.6e7 m (motion limits at their largest) makes Cholesky find the system indeterminate: the solver
    turns to QR and goes on."""
    jump = np.eye(4)
    jump[0, 3] = 8.6e7
    poses = np.stack([np.eye(4), jump, jump])
    poses[2, 0, 3] += 1.0
    graph = MapGraph(poses[:1].copy())
    solver = LandmarkSolver(ExperienceMapConfig(object_landmarks=True))
    for node in (1, 2):
        graph.add_node(poses[node])
        relative = invert_pose(poses[node - 1]) @ poses[node]
        graph.add_link(Link(node - 1, node, relative, "odometry", float(np.linalg.norm(relative[:3, 3]))))
        solver.update(graph, np.ones(len(graph), bool), FakeObjectMap(), np.array([node - 1]), node)
    assert solver._isam.params().getFactorization() == "QR"
    np.testing.assert_allclose(graph.poses[:, 0, 3], [0.0, 8.6e7, 8.6e7 + 1.0])
