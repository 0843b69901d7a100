"""The object map: observations fused online by label and distance; with the corrected experience poses, each
observation follows the correction of the experience it was made in."""

from __future__ import annotations

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from neoslam.config import ObjectMapConfig
from neoslam.geometry import invert_pose, make_pose, transform_points
from neoslam.io.frames import camera_points_to_robot, robot_points_to_camera
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
