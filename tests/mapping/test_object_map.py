"""The object map: observations fused online by label and distance; with the corrected experience poses, each
observation follows the correction of the experience it was made in."""

from __future__ import annotations

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from neoslam.config import ObjectMapConfig
from neoslam.geometry import camera_points_to_robot, invert_pose, make_pose, robot_points_to_camera, transform_points
from neoslam.mapping.object_map import ObjectMap
from neoslam.types import ObjectObservation

CONFIG = ObjectMapConfig()  # association radius 2.5 m, at least 3 observations


def pose(yaw: float, translation) -> np.ndarray:
    return make_pose(Rotation.from_euler("z", yaw), np.asarray(translation, dtype=float))


def seen(label: str, robot_pose: np.ndarray, world_point) -> ObjectObservation:
    """What the camera on `robot_pose` measures of an object at `world_point` (centre in the optical frame)."""
    in_robot = transform_points(invert_pose(robot_pose), np.asarray(world_point, dtype=float)[None])
    centre = robot_points_to_camera(in_robot)[0]
    box = np.array([10.0, 10.0, 40.0, 40.0])
    return ObjectObservation(label, 0.9, box, box, centre, np.zeros((8, 8), np.uint8))


def world_of(robot_pose: np.ndarray, observation: ObjectObservation) -> np.ndarray:
    return transform_points(robot_pose, camera_points_to_robot(observation.center_camera[None]))[0]


def test_no_observations_add_nothing() -> None:
    object_map = ObjectMap(CONFIG)
    assert object_map.add(np.eye(4), ()) == []
    assert object_map.objects() == []


def test_objects_are_the_online_means() -> None:
    object_map = ObjectMap(CONFIG)
    robots = [pose(0.0, (0, 0, 0)), pose(0.3, (2, 0.5, 0)), pose(0.6, (4, 1.5, 0.1)), pose(0.9, (5, 3, 0.2))]
    car = [(10.0, 2.0, 0.5), (10.4, 2.3, 0.4), (9.8, 1.6, 0.6), (10.2, 2.1, 0.5)]
    person = [(12.0, 6.0, 0.9), (12.3, 6.2, 0.9), (11.8, 5.9, 1.0)]
    truck_far = [(10.0, 2.0, 0.5), (30.0, 2.0, 0.5)]  # a truck where the car is: labels never fuse
    ids = []
    for k, robot in enumerate(robots):
        frame = [seen("car", robot, car[k])]
        if k < len(person):
            frame.append(seen("person", robot, person[k]))
        if k < len(truck_far):
            frame.append(seen("truck", robot, truck_far[k]))
        ids.append(object_map.add(robot, tuple(frame)))

    assert ids[0] == [0, 1, 2]
    assert [i[0] for i in ids] == [0, 0, 0, 0]  # the car, every time
    assert ids[1] == [0, 1, 3]  # the second truck is 20 m from the first: a new object
    objects = {o.label: o for o in object_map.objects()}
    assert set(objects) == {"car", "person"}  # the trucks were seen once each
    np.testing.assert_allclose(objects["car"].position, np.mean(car, axis=0), atol=1e-9)
    np.testing.assert_allclose(objects["person"].position, np.mean(person, axis=0), atol=1e-9)
    assert (objects["car"].observations, objects["person"].observations) == (4, 3)
    assert (objects["car"].id, objects["person"].id) == (0, 1)
    # the online means do not depend on what the observations were anchored to
    assert [(o.id, o.observations) for o in object_map.objects(None)] == [(0, 4), (1, 3)]


def test_min_observations() -> None:
    object_map = ObjectMap(CONFIG.model_copy(update={"min_observations": 1}))
    object_map.add(np.eye(4), (seen("bicycle", np.eye(4), (5.0, 1.0, 0.3)),))
    [only] = object_map.objects()
    assert only.label == "bicycle" and only.observations == 1
    np.testing.assert_allclose(only.position, [5.0, 1.0, 0.3], atol=1e-12)


def test_the_camera_measurement_is_moved_to_the_world() -> None:
    """A centre 10 m ahead of the camera (optical z) on a robot facing +y is 10 m along world +y."""
    object_map = ObjectMap(CONFIG.model_copy(update={"min_observations": 1}))
    robot = pose(np.pi / 2, (1.0, 2.0, 0.0))
    box = np.zeros(4)
    object_map.add(robot, (ObjectObservation("car", 0.9, box, box, np.array([0.0, 0.0, 10.0]), None),))
    np.testing.assert_allclose(object_map.objects()[0].position, [1.0, 12.0, 0.0], atol=1e-12)


def _two_experience_map() -> tuple[ObjectMap, np.ndarray, list[np.ndarray], list[np.ndarray]]:
    """A car seen from two frames of experience 0 and from two frames of experience 1; returns the map, the
    experiences' odometry poses, and the world points of the observations per experience."""
    experiences = np.array([pose(0.0, (0, 0, 0)), pose(0.8, (20, 5, 0.5))])
    frames = [(0, pose(0.1, (2, 0.2, 0))), (0, pose(0.2, (5, 0.8, 0.1))), (1, pose(0.9, (21, 6, 0.5)))]
    frames.append((1, pose(1.0, (22, 7.5, 0.6))))
    car = [(12.0, 8.0, 0.5), (12.2, 8.3, 0.5), (12.1, 7.9, 0.6), (11.9, 8.1, 0.4)]
    object_map = ObjectMap(CONFIG)
    points: list[list[np.ndarray]] = [[], []]
    for (experience, robot), point in zip(frames, car, strict=True):
        observation = seen("car", robot, point)
        ids = object_map.add(robot, (observation,), experience, invert_pose(experiences[experience]) @ robot)
        assert ids == [0]
        points[experience].append(world_of(robot, observation))
    return object_map, experiences, points[0], points[1]


def test_with_uncorrected_anchor_poses_the_objects_are_the_online_ones() -> None:
    object_map, experiences, first, second = _two_experience_map()
    [online] = object_map.objects()
    [anchored] = object_map.objects(experiences)
    np.testing.assert_allclose(online.position, np.mean(first + second, axis=0), atol=1e-9)
    np.testing.assert_allclose(anchored.position, online.position, atol=1e-9)
    assert (anchored.id, anchored.label, anchored.observations) == (0, "car", 4)


@pytest.mark.parametrize("moved", [0, 1])
def test_observations_follow_the_correction_of_their_experience(moved: int) -> None:
    """Experience `moved` is corrected by a known transform: its observations move with it, the others do not."""
    object_map, experiences, first, second = _two_experience_map()
    correction = pose(0.25, (-3.0, 4.0, 1.0))
    corrected = experiences.copy()
    corrected[moved] = correction @ experiences[moved]

    [anchored] = object_map.objects(corrected)

    groups = [np.array(first), np.array(second)]
    groups[moved] = transform_points(correction, groups[moved])
    np.testing.assert_allclose(anchored.position, np.concatenate(groups).mean(axis=0), atol=1e-9)


def test_a_map_corrected_as_a_whole_moves_every_object_rigidly() -> None:
    object_map, experiences, first, second = _two_experience_map()
    correction = pose(-1.0, (7.0, -2.0, 0.3))
    [anchored] = object_map.objects(correction @ experiences)
    [online] = object_map.objects()
    np.testing.assert_allclose(anchored.position, transform_points(correction, online.position[None])[0], atol=1e-9)


# ---------------------------------------------------------------------------------------------------------------
# Lifelong mapping: objects seen again are recognised, and a correction merges the copies made before it


def _seen_from(object_map: ObjectMap, experience: int, experience_pose: np.ndarray, robot: np.ndarray, points,
               label: str = "car", odometer_m: float | None = None) -> list[int]:  # fmt: skip
    """Observations of `points` from robot pose `robot` (world as the robot believes it), anchored at `experience`
    whose pose in that world is `experience_pose`."""
    observations = tuple(seen(label, robot, point) for point in points)
    return object_map.add(robot, observations, experience, invert_pose(experience_pose) @ robot, odometer_m)


def test_objects_seen_again_are_merged_once_the_map_is_corrected() -> None:
    """Experience 1 was made 4 m off by drifted odometry: its view of the car is a second car until the map is
    corrected, then the two are one, with every observation, and later views join it."""
    object_map = ObjectMap(CONFIG)
    experiences = np.array([pose(0.0, (0, 0, 0)), pose(0.0, (104, 0, 0))])  # experience 1 really is at (100, 0)
    car = np.array([110.0, 3.0, 0.5])
    first = _seen_from(object_map, 0, experiences[0], pose(0.0, (98, 0, 0)), [car, car + 0.1, car - 0.1])
    drifted = car + [4.0, 0.0, 0.0]  # where the drifted robot places it
    second = _seen_from(object_map, 1, experiences[1], pose(0.0, (104, 0, 0)), [drifted, drifted + 0.2, drifted])
    assert set(first) == {0} and set(second) == {1}
    assert len(object_map.objects(experiences)) == 2

    corrected = experiences.copy()
    corrected[1] = pose(0.0, (100, 0, 0))
    assert object_map.refresh(corrected) == 1

    [merged] = object_map.objects(corrected)
    assert (merged.id, merged.observations) == (0, 6)  # the older object's id stays
    np.testing.assert_allclose(merged.position, car + [0.0, 0.0, 0.0], atol=0.1)
    assert len(object_map) == 1
    # a later view from the corrected map joins it
    assert _seen_from(object_map, 1, corrected[1], pose(0.0, (101, 0, 0)), [car]) == [0]
    [again] = object_map.objects(corrected)
    assert again.observations == 7


def test_a_part_not_joined_keeps_its_objects_apart_until_it_joins() -> None:
    """A later session (experience 1, a part of its own) starts at the identity of its own frame, as the stored map
    (experience 0) did: a car it sees at the stored car's coordinates is another car, neither moved nor merged,
    until the parts join; then the refresh on the joined map merges the car it saw twice."""
    object_map = ObjectMap(CONFIG)
    experiences = np.array([pose(0.0, (0, 0, 0)), pose(0.0, (0, 0, 0))])
    stored_car, later_car = np.array([10.0, 3.0, 0.5]), np.array([10.5, 3.2, 0.5])
    apart = np.array([0, 1])
    stored = [object_map.add(experiences[0], (seen("car", experiences[0], stored_car),), 0, np.eye(4), None, apart)
              for _ in range(3)]  # fmt: skip
    later = [object_map.add(experiences[1], (seen("car", experiences[1], later_car),), 1, np.eye(4), None, apart)
             for _ in range(3)]  # fmt: skip
    assert {i for [i] in stored} == {0} and {i for [i] in later} == {1}
    assert object_map.refresh(experiences, True, apart) == 0  # the parts' frames are not one frame
    np.testing.assert_allclose(object_map.objects()[0].position, stored_car, atol=1e-9)  # the stored car stays

    joined = experiences.copy()
    joined[1] = pose(0.0, (-80.0, 40.0, 0.0))  # the later part moved into the map's frame: its car is elsewhere
    assert object_map.refresh(joined, True, np.array([0, 0])) == 0
    assert len(object_map.objects(joined)) == 2
    same_place = experiences.copy()  # or it really was the stored car: one car once the parts are one
    assert object_map.refresh(same_place, True, np.array([0, 0])) == 1
    [car] = object_map.objects(same_place)
    assert (car.id, car.observations) == (0, 6)


def test_a_map_that_hardly_moved_is_not_refreshed() -> None:
    object_map, experiences, _, _ = _two_experience_map()
    assert object_map.refresh(experiences) == 0  # the first refresh computes, nothing to merge
    nudged = experiences.copy()
    nudged[1] = pose(0.0, (0.3, 0.0, 0.0)) @ nudged[1]
    object_map.refresh(nudged)
    [online] = object_map.objects()
    [anchored] = object_map.objects(experiences)
    np.testing.assert_allclose(online.position, anchored.position, atol=1e-9)  # not recomputed for 0.3 m
    moved = experiences.copy()
    moved[1] = pose(0.0, (2.0, 0.0, 0.0)) @ moved[1]
    object_map.refresh(moved)
    np.testing.assert_allclose(object_map.objects()[0].position, object_map.objects(moved)[0].position, atol=1e-9)


def test_merging_takes_the_nearest_pairs_first_and_does_not_chain() -> None:
    """Three cars 3 m apart in a row, each seen from its own experience; a correction pulls them to about 2 m apart:
    the nearer pair merges, and the third is then 2.95 m from their mean, so it stays."""
    object_map = ObjectMap(CONFIG)
    experiences = np.array([pose(0.0, (3.0 * k, -10.0, 0.0)) for k in range(3)])
    for k in range(3):
        car = np.array([3.0 * k, 0.0, 0.5])
        _seen_from(object_map, k, experiences[k], experiences[k], [car] * 3)
    assert len(object_map.objects(experiences)) == 3
    corrected = np.array([pose(0.0, (x, -10.0, 0.0)) for x in (0.0, 1.9, 3.9)])  # cars 1.9 and 2.0 m apart
    assert object_map.refresh(corrected) == 1
    objects = object_map.objects(corrected)
    assert [(o.id, o.observations) for o in objects] == [(0, 6), (2, 3)]


def test_objects_seen_too_few_times_are_forgotten() -> None:
    config = CONFIG.model_copy(update={"tentative_distance": 50.0})
    object_map = ObjectMap(config)
    robot = pose(0.0, (0, 0, 0))
    _seen_from(object_map, 0, robot, robot, [(10.0, 3.0, 0.5)], label="person", odometer_m=0.0)  # once
    _seen_from(object_map, 0, robot, robot, [(12.0, -4.0, 0.5)] * 3, odometer_m=1.0)  # three times: confirmed
    assert len(object_map) == 2
    _seen_from(object_map, 0, robot, robot, [], odometer_m=40.0)
    assert len(object_map) == 2  # not yet
    _seen_from(object_map, 0, robot, robot, [], odometer_m=60.0)
    assert len(object_map) == 1  # the person seen once is gone, the car stays
    # a new sighting where the person was is a new object
    assert _seen_from(object_map, 0, robot, robot, [(10.0, 3.0, 0.5)], label="person", odometer_m=61.0) == [2]
    [car] = object_map.objects()
    assert (car.id, car.label, car.observations) == (1, "car", 3)


@pytest.mark.slow
@pytest.mark.parametrize("seed", range(3))
def test_the_spatial_hash_associates_as_a_full_search(seed: int) -> None:
    """Each observation joins the nearest object of its label inside its gate (in the ground plane the association
    radius across the viewing ray and two depth stds along it; height_tolerance in height), as a search over all
    objects would find it."""
    rng = np.random.default_rng(seed)
    config = CONFIG.model_copy(update={"min_observations": 1})
    object_map = ObjectMap(config)
    sums: list[np.ndarray] = []
    weights: list[float] = []
    labels: list[str] = []
    radius = config.association_radius
    for _ in range(400):
        label = str(rng.choice(["car", "person"]))
        point = rng.uniform([-45, -45, -2], [45, 45, 4])  # up to 64 m away: far views have wide gates
        centre = robot_points_to_camera(point[None])[0]
        [got] = object_map.add(np.eye(4), (ObjectObservation(label, 0.9, np.zeros(4), np.zeros(4), centre, None),))
        sigma = max(config.depth_sigma_at_1m * centre[2] ** 2, config.position_sigma_floor)
        along_gate = max(radius, config.gate_sigmas * sigma)
        ray = point[:2] / np.linalg.norm(point[:2])
        scores = []
        for total, weight, known in zip(sums, weights, labels, strict=True):
            offset = total / weight - point
            along = offset[:2] @ ray
            across = np.linalg.norm(offset[:2] - along * ray)
            height = offset[2] / max(radius, config.height_tolerance)
            scores.append((along / along_gate) ** 2 + (across / radius) ** 2 + height**2 if known == label else np.inf)
        if scores and min(scores) <= 1.0:
            expected = int(np.argmin(scores))
        else:
            expected = len(sums)
            sums.append(np.zeros(3))
            weights.append(0.0)
            labels.append(label)
        sums[expected] = sums[expected] + point / sigma**2
        weights[expected] += 1.0 / sigma**2
        assert got == expected


def test_a_far_view_joins_an_object_along_its_ray_not_across_it() -> None:
    """Seen 50 m away a stereo centre is metres off along the viewing ray (std 0.0015 x 50^2 = 3.75 m): a view 4 m
    beyond a known car joins it, one 4 m beside it does not; the far view barely moves the car (inverse-variance
    weights)."""
    object_map = ObjectMap(CONFIG)
    robot = np.eye(4)
    car = np.array([50.0, 2.0, 0.5])
    near = pose(0.0, (40.0, 0.0, 0.0))  # 10 m from the car
    assert _seen_from(object_map, 0, robot, near, [car] * 3) == [0, 0, 0]
    ray = (car - robot[:3, 3]) / np.linalg.norm(car - robot[:3, 3])
    beyond = car + 4.0 * ray
    beside = car + 4.0 * np.array([-ray[1], ray[0], 0.0])
    assert _seen_from(object_map, 0, robot, robot, [beyond]) == [0]
    assert _seen_from(object_map, 0, robot, robot, [beside]) == [1]
    [known] = [o for o in object_map.objects() if o.id == 0]
    assert known.observations == 4
    far_sigma = CONFIG.depth_sigma_at_1m * beyond[0] ** 2  # its depth: the robot looks along x
    near_weight, far_weight = 3 / CONFIG.position_sigma_floor**2, 1 / far_sigma**2
    np.testing.assert_allclose(known.position, (near_weight * car + far_weight * beyond) / (near_weight + far_weight))
    assert np.linalg.norm(known.position - car) < 0.01
