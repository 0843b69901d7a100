"""The local object window (fusion of repeated observations) and the keyframes built from it (paper 3.2)."""

from __future__ import annotations

import warnings
from dataclasses import replace

import numpy as np
import pytest

from neoslam.config import KeyframeConfig
from neoslam.geometry import robot_points_to_camera, transform_points
from neoslam.loop.keyframes import KeyframeBuilder, LocalObjectWindow
from neoslam.types import Keyframe, ObjectObservation

POINT = "sign"  # a label without a footprint: its stereo centre is taken as is
DEFAULTS = KeyframeConfig()
FIXED_RADIUS = {"sparse_objects": 1}  # the neighbourhood never grows: every street counts as dense


def _seen(point_robot, label: str = POINT, grey: float = 128) -> ObjectObservation:
    """An exact observation of a point given in the robot frame (x forward, y left, z up)."""
    box = np.array([0.0, 0.0, 10.0, 10.0])
    centre = robot_points_to_camera(np.asarray(point_robot, dtype=float)[None])[0]
    return ObjectObservation(label, 0.9, box, box, centre, np.full((16, 16), grey, np.uint8))


def _at(x: float, y: float = 0.0, yaw: float = 0.0) -> np.ndarray:
    pose = np.eye(4)
    c, s = np.cos(yaw), np.sin(yaw)
    pose[:2, :2] = [[c, -s], [s, c]]
    pose[:2, 3] = x, y
    return pose


# ----------------------------------------------------------------------------------------------------------- window


def test_a_near_view_dominates_a_far_one_by_inverse_variance() -> None:
    window = LocalObjectWindow(DEFAULTS)
    # The same object, measured 21 m away from x = 0, then 5.1 m away from x = 15 (world points differ by noise).
    far, near = np.array([21.0, 4.5, 0.3]), np.array([20.1, 4.0, 0.0])
    window.add(_at(0.0), (_seen(far),), odometer_m=0.0)
    window.add(_at(15.0), (_seen(near - [15.0, 0, 0]),), odometer_m=15.0)

    assert len(window.objects) == 1 and window.objects[0].observations == 2
    # Depth std = sigma_1m z^2, so the weight is 1 / (sigma_1m z^2)^2 with z the depth of each view.
    sigma = DEFAULTS.depth_sigma_at_1m
    w_far, w_near = 1 / (sigma * 21.0**2) ** 2, 1 / (sigma * 5.1**2) ** 2
    expected = (w_far * far + w_near * near) / (w_far + w_near)
    np.testing.assert_allclose(window.objects[0].position, expected, atol=1e-9)
    # (21 / 5.1)^4 = 287: the fused object sits within a few millimetres of the near view.
    assert np.linalg.norm(window.objects[0].position - near) < 0.01 * np.linalg.norm(far - near)


def test_a_larger_measured_depth_sigma_replaces_the_model() -> None:
    """The stereo front end's own uncertainty of a centre (few or scattered keypoints) weighs in where it is larger
    than the depth model's; the simulator gives none."""
    window = LocalObjectWindow(DEFAULTS)
    first, second = np.array([10.0, 4.0, 0.0]), np.array([10.6, 4.0, 0.0])
    uncertain = replace(_seen(first), depth_sigma=1.0)
    precise = replace(_seen(second), depth_sigma=1e-6)  # smaller than the model's: the model stands
    window.add(_at(0.0), (uncertain,), odometer_m=0.0)
    window.add(_at(0.0), (precise,), odometer_m=0.0)
    w_first, w_second = 1.0, 1 / (DEFAULTS.depth_sigma_at_1m * 10.6**2) ** 2
    expected = (w_first * first + w_second * second) / (w_first + w_second)
    np.testing.assert_allclose(window.objects[0].position, expected, atol=1e-9)


def test_repeated_observations_fuse_only_within_the_association_radius() -> None:
    window = LocalObjectWindow(DEFAULTS)
    window.add(np.eye(4), (_seen([10.0, 3.0, 0.0]),), 0.0)
    window.add(np.eye(4), (_seen([10.0, 3.0 + 0.9 * DEFAULTS.association_radius, 0.0]),), 1.0)
    assert len(window.objects) == 1 and window.objects[0].observations == 2
    window.add(np.eye(4), (_seen([10.0, 3.0 - 1.1 * DEFAULTS.association_radius, 0.0]),), 2.0)
    assert [o.observations for o in window.objects] == [2, 1]


def test_different_labels_never_fuse() -> None:
    window = LocalObjectWindow(DEFAULTS.model_copy(update={"footprints": {}}))
    point = [12.0, -4.0, 0.5]
    for odometer, label in enumerate(["car", "person", "car", POINT, "person"]):
        window.add(np.eye(4), (_seen(point, label),), float(odometer))
    assert sorted((o.label, o.observations) for o in window.objects) == [("car", 2), ("person", 2), (POINT, 1)]
    for o in window.objects:
        np.testing.assert_allclose(o.position, point, atol=1e-12)


def test_objects_not_seen_for_the_window_length_are_forgotten() -> None:
    window = LocalObjectWindow(DEFAULTS)
    window.add(np.eye(4), (_seen([10.0, 3.0, 0.0]),), odometer_m=10.0)
    window.add(np.eye(4), (_seen([10.0, -20.0, 0.0]),), odometer_m=40.0)
    window.add(np.eye(4), (), odometer_m=10.0 + DEFAULTS.window_length)  # exactly window_length: still there
    assert len(window.objects) == 2
    window.add(np.eye(4), (), odometer_m=10.5 + DEFAULTS.window_length)
    assert len(window.objects) == 1
    np.testing.assert_allclose(window.objects[0].position, [10.0, -20.0, 0.0], atol=1e-12)
    # A new sighting keeps an object alive.
    window.add(np.eye(4), (_seen([10.0, -20.0, 0.0]),), odometer_m=95.0)
    window.add(np.eye(4), (), odometer_m=95.0 + DEFAULTS.window_length)
    assert len(window.objects) == 1 and window.objects[0].observations == 2


def test_confirmed_needs_min_observations() -> None:
    window = LocalObjectWindow(DEFAULTS)
    window.add(np.eye(4), (_seen([30.0, -3.0, 0.0]),), 0.0)  # seen once only
    for odometer in range(DEFAULTS.min_observations):
        assert window.confirmed() == []
        window.add(np.eye(4), (_seen([10.0, 3.0, 0.0]),), float(odometer))
    assert len(window.objects) == 2
    assert [o.observations for o in window.confirmed()] == [DEFAULTS.min_observations]
    np.testing.assert_allclose(window.confirmed()[0].position, [10.0, 3.0, 0.0])
    single = LocalObjectWindow(DEFAULTS.model_copy(update={"min_observations": 1}))
    single.add(np.eye(4), (_seen([10.0, 3.0, 0.0]),), 0.0)
    assert len(single.confirmed()) == 1


def test_a_car_seen_straight_ahead_moves_half_its_length_along_the_ray() -> None:
    window = LocalObjectWindow(DEFAULTS)
    length = DEFAULTS.footprints["car"][0]
    assert length == 4.3
    # Robot at (100, 50) facing +y; the visible rear of the car is 10 m ahead, 0.9 m below the camera.
    pose = _at(100.0, 50.0, yaw=np.pi / 2)
    surface = np.array([10.0, 0.0, -0.9])
    window.add(pose, (_seen(surface, "car"),), 0.0)
    # Along the ray in the ground plane: the height is kept (the visible surface is at the car's mid-height).
    centre = surface + np.array([length / 2, 0.0, 0.0])
    np.testing.assert_allclose(window.objects[0].position, transform_points(pose, centre[None])[0], atol=1e-9)
    np.testing.assert_allclose(np.linalg.norm(centre - surface), 2.15)


@pytest.mark.parametrize("side", [1.0, -1.0])
def test_a_car_seen_at_ninety_degrees_moves_half_its_width(side: float) -> None:
    window = LocalObjectWindow(DEFAULTS)
    width = DEFAULTS.footprints["car"][1]
    # Straight to the side the depth is 0, which add() cannot weight (1 / 0): the correction itself is checked.
    surface = robot_points_to_camera(np.array([[0.0, 5.0 * side, 0.0]]))
    centre = window._object_centres((ObjectObservation("car", 0.9, np.zeros(4), np.zeros(4), surface[0], None),))
    np.testing.assert_allclose(centre[0], surface[0] * (5.0 + width / 2) / 5.0, atol=1e-12)


def test_an_oblique_car_moves_between_half_its_width_and_half_its_length() -> None:
    window = LocalObjectWindow(DEFAULTS)
    surface = robot_points_to_camera(np.array([[8.0, 8.0, 0.0]]))[0]  # 45 degrees to the left
    centre = window._object_centres((ObjectObservation("car", 0.9, np.zeros(4), np.zeros(4), surface, None),))[0]
    shift = np.linalg.norm(centre - surface)
    assert 0.9 < shift < 2.15
    np.testing.assert_allclose(np.cross(centre, surface), 0.0, atol=1e-12)  # along the ray


def test_a_label_without_footprint_is_not_moved() -> None:
    window = LocalObjectWindow(DEFAULTS)
    pose = _at(3.0, -2.0, yaw=0.4)
    point = np.array([12.0, 3.0, -0.5])
    window.add(pose, (_seen(point, POINT),), 0.0)
    np.testing.assert_allclose(window.objects[0].position, transform_points(pose, point[None])[0], atol=1e-12)


def test_a_label_without_footprint_straight_ahead_raises_no_warning() -> None:
    window = LocalObjectWindow(DEFAULTS)
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        window.add(np.eye(4), (_seen([10.0, 0.0, 0.0], POINT),), 0.0)
    np.testing.assert_allclose(window.objects[0].position, [10.0, 0.0, 0.0])


def test_fusion_weights_use_the_measured_depth() -> None:
    window = LocalObjectWindow(DEFAULTS)
    far_surface, near_surface = np.array([20.0, 0.0, 0.0]), np.array([5.0, 0.0, 0.0])
    window.add(np.eye(4), (_seen(far_surface, "car"),), 0.0)
    window.add(_at(15.5), (_seen(near_surface, "car"),), 15.5)  # the near view sees the car 0.5 m further on
    far, near = np.array([22.15, 0, 0]), np.array([22.65, 0, 0])  # centres, world
    w_far, w_near = 20.0**-4, 5.0**-4
    np.testing.assert_allclose(window.objects[0].position, (w_far * far + w_near * near) / (w_far + w_near))


# -------------------------------------------------------------------------------------------------------- keyframes


def _street_objects() -> np.ndarray:
    """World points every 6 m along both sides of a street on the x axis."""
    x = np.arange(0.0, 200.0, 6.0)
    return np.column_stack([x, np.where(np.arange(len(x)) % 2 == 0, 5.0, -5.0), np.zeros(len(x))])


def _drive(builder: KeyframeBuilder, objects: np.ndarray, stop: float = 150.0, step: float = 1.0):
    """Drive along x one frame per `step` m, seeing every object 2-30 m ahead exactly; yields (odometer, keyframe)."""
    for frame, x in enumerate(np.arange(0.0, stop, step)):
        ahead = objects - [x, 0.0, 0.0]
        visible = ahead[(ahead[:, 0] > 2.0) & (ahead[:, 0] < 30.0)]
        keyframe = builder.add(frame, _at(x), tuple(_seen(p) for p in visible), step if frame else 0.0)
        yield builder.odometer_m, keyframe


def test_a_keyframe_every_spacing_metres_with_consecutive_ids() -> None:
    config = DEFAULTS.model_copy(update={"footprints": {}})
    builder = KeyframeBuilder(config)
    made = [(odometer, keyframe) for odometer, keyframe in _drive(builder, _street_objects()) if keyframe is not None]
    odometers = np.array([odometer for odometer, _ in made])
    assert len(made) > 20
    assert odometers[0] == 2.0  # the first frame where min_observations sightings were made
    np.testing.assert_allclose(np.diff(odometers), config.spacing)
    assert [k.id for _, k in made] == list(range(len(made)))
    for odometer, k in made:
        assert k.frame_index == int(odometer)
        np.testing.assert_array_equal(k.pose, _at(odometer))
        assert len(k.labels) >= config.min_objects and k.centers.shape == (len(k.labels), 3)
        # Objects are exact: the keyframe holds true street objects.
        assert np.min(np.linalg.norm(k.centers[:, None] - _street_objects()[None], axis=2), axis=1).max() < 1e-9


def test_keyframe_is_the_current_object_and_its_neighbourhood() -> None:
    config = DEFAULTS.model_copy(
        update={**FIXED_RADIUS, "footprints": {}, "min_observations": 1, "neighbourhood_radius": 6.0, "min_objects": 3}
    )
    pose = _at(100.0, 50.0, yaw=np.radians(30))
    #   A: nearest the robot (current);  B, C within 6 m of A;  D 8 m from A (4 m from B);  E far.
    #   Seen in the order B, D, A, E, C: around B, the first seen, the keyframe would be B, D, A.
    points = {"B": [8, 2, 0], "D": [12, 2, 0], "A": [4, 2, 0], "E": [30, -3, 0], "C": [4, -3, 0]}
    seen = tuple(_seen(p, label) for label, p in points.items())
    keyframe = KeyframeBuilder(config).add(7, pose, seen, 0.0)
    assert keyframe is not None and keyframe.id == 0 and keyframe.frame_index == 7
    assert keyframe.labels == ("B", "A", "C")
    np.testing.assert_array_equal(keyframe.pose, pose)
    expected = transform_points(pose, np.array([points[k] for k in "BAC"], dtype=float))
    np.testing.assert_allclose(keyframe.centers, expected, atol=1e-9)
    np.testing.assert_allclose(keyframe.distances[1], [4, 0, 5], atol=1e-9)  # e_ij of eq. 1, from A


def test_no_keyframe_with_fewer_than_min_objects_around_the_current_object() -> None:
    config = DEFAULTS.model_copy(
        update={**FIXED_RADIUS, "footprints": {}, "min_observations": 1, "neighbourhood_radius": 6.0, "min_objects": 4}
    )
    builder = KeyframeBuilder(config)
    few = (_seen([4, 2, 0], "A"), _seen([8, 2, 0], "B"), _seen([4, -3, 0], "C"), _seen([12, 2, 0], "D"))
    assert builder.add(0, _at(0.0), few, 0.0) is None  # D is 8 m from the current object A
    # The keyframe stays due: the next frame with a fourth object near A makes it, with id 0.
    keyframe = builder.add(1, _at(0.5), (_seen([3.5, 5, 0], "F"),), 0.5)
    assert keyframe is not None and keyframe.id == 0 and keyframe.frame_index == 1
    assert sorted(keyframe.labels) == ["A", "B", "C", "F"]
    # Then the next one is `spacing` metres on.
    assert builder.add(2, _at(5.25), (), 4.75) is None
    assert builder.add(3, _at(5.5), (), 0.25) is not None


def test_keyframe_patches_are_the_mean_of_the_observed_patches() -> None:
    config = DEFAULTS.model_copy(update={"footprints": {}, "min_objects": 1})
    builder = KeyframeBuilder(config)
    keyframe = None
    for frame, grey in enumerate([10, 20, 60]):
        keyframe = builder.add(frame, np.eye(4), (_seen([10, 2, 0], grey=grey),), 0.0)
    assert keyframe is not None and keyframe.patches.shape == (1, 16, 16)
    np.testing.assert_allclose(keyframe.patches, 30.0)


def test_on_a_sparse_street_the_neighbourhood_grows_to_hold_more_objects() -> None:
    config = DEFAULTS.model_copy(
        update={
            "footprints": {},
            "min_observations": 1,
            "neighbourhood_radius": 6.0,
            "min_objects": 3,
            "sparse_objects": 4,
            "sparse_neighbourhood_radius": 15.0,
        }
    )
    # A is the current object; B and C stand within 6 m of it, D 8 m and E 11 m away, F 40 m away. Only three
    # within 6 m: the radius grows to the 4th nearest (D, 8 m), so D joins and E does not.
    points = {"A": [4, 2, 0], "B": [8, 2, 0], "C": [4, -3, 0], "D": [12, 2, 0], "E": [15, 2, 0], "F": [44, 2, 0]}
    seen = {label: _seen(p, label) for label, p in points.items()}
    keyframe = KeyframeBuilder(config).add(0, _at(0.0), tuple(seen.values()), 0.0)
    assert keyframe is not None and sorted(keyframe.labels) == ["A", "B", "C", "D"]
    # A dense street (four objects within 6 m) keeps the plain radius.
    dense = (*seen.values(), _seen([6, 0, 0], "G"))
    keyframe = KeyframeBuilder(config).add(0, _at(0.0), dense, 0.0)
    assert keyframe is not None and sorted(keyframe.labels) == ["A", "B", "C", "G"]
    # Never beyond the sparse radius: F, 40 m from A, does not make up the numbers.
    assert KeyframeBuilder(config).add(0, _at(0.0), (seen["A"], seen["B"], seen["F"]), 0.0) is None


# ------------------------------------------------------------------------------------------------------ covariances


def test_a_far_view_is_uncertain_along_its_ray_and_sharp_across_it() -> None:
    window = LocalObjectWindow(DEFAULTS)
    window.add(_at(0.0), (_seen([40.0, 0.0, 0.0]),), odometer_m=0.0)
    covariance = window.objects[0].covariance
    along = DEFAULTS.depth_sigma_at_1m * 40.0**2  # the depth std of a view at 40 m, along the ray (x)
    across = DEFAULTS.bearing_sigma * 40.0
    np.testing.assert_allclose(covariance, np.diag([along**2, across**2]), rtol=1e-9, atol=1e-15)


def test_a_keyframe_object_is_known_better_the_more_views_fused_it() -> None:
    """The covariance of the weighted mean of independent views: two alike views halve the variance; a view from
    the side is sharp where the first view was not."""
    window = LocalObjectWindow(DEFAULTS)
    window.add(_at(0.0), (_seen([30.0, 0.0, 0.0]),), odometer_m=0.0)
    one = window.objects[0].covariance.copy()
    window.add(_at(0.0), (_seen([30.0, 0.0, 0.0]),), odometer_m=0.0)
    np.testing.assert_allclose(window.objects[0].covariance, one / 2, rtol=1e-9)
    side = LocalObjectWindow(DEFAULTS)
    side.add(_at(0.0), (_seen([30.0, 0.0, 0.0]),), odometer_m=0.0)
    side.add(_at(30.0, -30.0, np.pi / 2), (_seen([30.0, 0.0, 0.0]),), odometer_m=50.0)  # the same point, seen along y
    assert side.objects[0].covariance[0, 0] < one[0, 0] / 2


def test_a_retracted_view_takes_its_covariance_with_it() -> None:
    window = LocalObjectWindow(DEFAULTS)
    first, second = _seen([30.0, 0.0, 0.0]), _seen([30.0, 0.0, 0.0])
    window.add(_at(0.0), (first,), odometer_m=0.0)
    one = window.objects[0].covariance.copy()
    window.add(_at(0.0), (second,), odometer_m=0.0)
    window.retract((second,))
    np.testing.assert_allclose(window.objects[0].covariance, one, rtol=1e-9)


def test_keyframes_carry_their_objects_covariances_and_move_with_them() -> None:
    builder = KeyframeBuilder(DEFAULTS.model_copy(update={"min_objects": 2, "min_observations": 1, **FIXED_RADIUS}))
    points = [_seen([12.0, 4.0, 0.0]), _seen([20.0, -4.0, 0.0])]
    keyframe = builder.add(0, _at(0.0), tuple(points), travelled_m=0.0)
    assert keyframe is not None and keyframe.covariances.shape == (2, 2, 2)
    assert keyframe.covariances[1, 0, 0] > keyframe.covariances[0, 0, 0]  # the farther object, along its ray
    turn = _at(100.0, 50.0, np.pi / 2)
    moved = keyframe.moved(turn)
    np.testing.assert_allclose(moved.centers, transform_points(turn, keyframe.centers))
    np.testing.assert_allclose(moved.pose, turn @ keyframe.pose)
    np.testing.assert_allclose(moved.covariances[:, 1, 1], keyframe.covariances[:, 0, 0])  # x became y
    np.testing.assert_allclose(moved.distances, keyframe.distances)


def test_a_keyframe_refuses_covariances_of_the_wrong_shape() -> None:
    keyframe = KeyframeBuilder(
        DEFAULTS.model_copy(update={"min_objects": 2, "min_observations": 1, **FIXED_RADIUS})
    ).add(0, _at(0.0), (_seen([12.0, 4.0, 0.0]), _seen([20.0, -4.0, 0.0])), travelled_m=0.0)
    assert keyframe is not None
    with pytest.raises(ValueError, match=r"covariances of shape \(8,\), not \(2, 2, 2\)"):
        replace(keyframe, covariances=keyframe.covariances.ravel())


def test_keyframe_distances_are_those_of_numpys_norm() -> None:
    rng = np.random.default_rng(0)
    centres = rng.normal(0.0, 30.0, (40, 3))
    keyframe = Keyframe(0, 0, np.eye(4), centres, ("car",) * 40, np.zeros((40, 16, 16), np.uint8))
    assert np.array_equal(keyframe.distances, np.linalg.norm(centres[:, None] - centres[None], axis=-1))


def test_the_window_gives_each_objects_views_with_their_time_and_robot_position() -> None:
    window = LocalObjectWindow(DEFAULTS.model_copy(update={"footprints": {}}))
    for i in range(3):
        window.add(_at(float(i)), (_seen([10.0 - i, 2.0, 0.0]),), float(i), time=0.1 * i)
    (views,) = window.views(window.objects)
    np.testing.assert_allclose(views.points, [[10.0, 2.0]] * 3, atol=1e-9)
    np.testing.assert_allclose(views.times, [0.0, 0.1, 0.2])
    np.testing.assert_allclose(views.robots, [[0.0, 0.0], [1.0, 0.0], [2.0, 0.0]])
    assert views.covariances.shape == (3, 2, 2)


def test_provisional_objects_whose_views_show_them_moving_join_no_keyframe() -> None:
    """With `moves` set, a provisional window object it finds moving is left out of keyframes; a settled object
    (a view of a track known to be static) is never put to the test."""
    config = DEFAULTS.model_copy(update={**FIXED_RADIUS, "footprints": {}, "min_observations": 1, "min_objects": 2})
    points = {"A": [4, 2, 0], "B": [8, 2, 0], "C": [12, -2, 0]}
    seen = tuple(_seen(p, label) for label, p in points.items())
    tested: list[int] = []

    def moves(views) -> bool:
        tested.append(len(views.times))
        return bool(np.isclose(views.points[0, 1], -2.0))  # C

    builder = KeyframeBuilder(config, marks_provisional=True)
    builder.moves = moves
    first = builder.add(0, _at(0.0), seen, 0.0)
    assert first is not None and first.labels == ("A", "B") and tested == [1, 1, 1]
    builder.window.settle(seen[:1])  # A's first view: a track known to be static
    tested.clear()
    again = tuple(_seen(p, label) for label, p in points.items())
    second = builder.add(1, _at(0.0), again, config.spacing)
    assert second is not None and second.labels == ("A", "B")
    assert tested == [2, 2]  # B and C, two views each; not A
    unmarked = KeyframeBuilder(config)
    unmarked.moves = moves
    made = unmarked.add(0, _at(0.0), seen, 0.0)
    assert made is not None and made.labels == ("A", "B", "C")  # no provisional objects: nothing to test
