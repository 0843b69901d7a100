"""Moving objects: tracks in the odometry frame; a track whose velocity is significant against its stereo noise
and fast enough is moving, and its observations are kept out of keyframes and the map."""

from __future__ import annotations

import numpy as np
import pytest
from pydantic import ValidationError

from neoslam.config import KeyframeConfig, MovingObjectsConfig, NeoSLAMConfig, ObjectMapConfig
from neoslam.geometry import invert_pose, robot_points_to_camera, transform_points
from neoslam.loop.keyframes import LocalObjectWindow, WindowViews, view_covariances
from neoslam.mapping.moving_objects import MovingObjectDetector
from neoslam.types import Frame, ObjectObservation

PERIOD = 0.1  # s, KITTI's 10 Hz
OBJECT_MAP = ObjectMapConfig()
FX, BASELINE = 707.0912, 0.5372
# Disparity noise that gives the object map's depth std (depth_sigma_at_1m * depth^2): the noise it allows for.
DISPARITY_SIGMA = OBJECT_MAP.depth_sigma_at_1m * FX * BASELINE
PIXEL_SIGMA = 1.0


def robot_pose(x: float, y: float = 0.0) -> np.ndarray:
    pose = np.eye(4)
    pose[:2, 3] = x, y
    return pose


def measured(label: str, pose: np.ndarray, point, rng: np.random.Generator) -> ObjectObservation | None:
    """The stereo camera's view of an object at a world point: disparity and pixel noise (depth error ~ depth^2);
    None when behind the camera or nearer than 2 m."""
    centre = robot_points_to_camera(transform_points(invert_pose(pose), np.asarray(point, float)[None]))[0]
    if centre[2] < 2.0:
        return None
    disparity = FX * BASELINE / centre[2] + rng.normal(0.0, DISPARITY_SIGMA)
    depth = FX * BASELINE / disparity
    column = FX * centre[0] / centre[2] + rng.normal(0.0, PIXEL_SIGMA)
    noisy = np.array([column * depth / FX, centre[1] * depth / centre[2], depth])
    box = np.array([10.0, 10.0, 40.0, 40.0])
    return ObjectObservation(label, 0.9, box, box, noisy, np.zeros((8, 8), np.uint8))


def frame(index: int, pose: np.ndarray, observations: list[ObjectObservation | None]) -> Frame:
    kept = tuple(o for o in observations if o is not None)
    return Frame(index, index * PERIOD, pose, np.zeros(3), np.zeros(3), kept)


def drive(objects: list[tuple[str, np.ndarray, np.ndarray]], frames: int, robot_speed: float, seed: int = 0):
    """Frames of a robot driving along x past objects (label, start, velocity); yields the frame and, per object,
    whether it was seen."""
    rng = np.random.default_rng(seed)
    for i in range(frames):
        t = i * PERIOD
        pose = robot_pose(robot_speed * t)
        views = [measured(label, pose, start + velocity * t, rng) for label, start, velocity in objects]
        yield frame(i, pose, views), [v is not None for v in views]


def flags(detector: MovingObjectDetector, objects, frames: int, robot_speed: float, seed: int = 0) -> np.ndarray:
    """(frames, objects): 1 kept out, 0 kept, -1 not seen."""
    table = np.full((frames, len(objects)), -1)
    for i, (f, seen) in enumerate(drive(objects, frames, robot_speed, seed)):
        kept_out = detector.update(f)
        table[i, np.flatnonzero(seen)] = kept_out
    return table


def detector(**changes) -> MovingObjectDetector:
    return MovingObjectDetector(MovingObjectsConfig(**changes), OBJECT_MAP)


def judge() -> MovingObjectDetector:
    """A detector that holds nothing back: what it keeps out it has judged moving."""
    return detector(hold_sigmas=MovingObjectsConfig().significance_sigmas)


def first_flagged(column: np.ndarray) -> int:
    """Frames from the first view to the first flag (the first view counts as frame 1)."""
    seen = np.flatnonzero(column >= 0)
    flagged = np.flatnonzero(column == 1)
    assert len(flagged), "never flagged"
    return int(np.count_nonzero(seen <= flagged[0]))


@pytest.mark.slow
@pytest.mark.parametrize("seed", range(5))
def test_static_objects_are_never_judged_moving_even_far(seed: int) -> None:
    """Parked cars and people out to 40 m and more, with the stereo noise the depth model allows (2.5 times the
    simulator's), from a robot driving by at 10 m/s and from one standing still."""
    rng = np.random.default_rng(100 + seed)
    xs = rng.uniform(10.0, 60.0, 20)
    ys = rng.choice([-1.0, 1.0], 20) * rng.uniform(3.0, 20.0, 20)
    labels = rng.choice(["car", "person"], 20)
    objects = [(str(label), np.array([x, y, 0.0]), np.zeros(3)) for label, x, y in zip(labels, xs, ys, strict=True)]
    for speed in (10.0, 0.0):
        assert (flags(judge(), objects, 60, speed, seed) == 1).sum() == 0
        held = flags(detector(), objects, 60, speed, seed)  # undecided views held back: a few
        assert (held == 1).sum() <= 0.06 * (held >= 0).sum()


def test_a_static_object_40_m_ahead_stays_static_for_long() -> None:
    objects = [("car", np.array([40.0, 2.0, 0.0]), np.zeros(3))]
    assert (flags(judge(), objects, 300, 0.0) == 1).sum() == 0


@pytest.mark.parametrize(
    ("start", "velocity", "within"),
    [
        ((30.0, -3.0, 0.0), (-8.0, 0.0, 0.0), 10),  # oncoming in the other lane, closing at 18 m/s
        ((12.0, 0.0, 0.0), (8.0, 0.0, 0.0), 5),  # ahead, driving with the robot (the robot is faster)
        ((30.0, 3.0, 0.0), (-12.0, 0.0, 0.0), 10),  # fast: 1.2 m a frame
        ((-8.0, -3.0, 0.0), (14.0, 0.0, 0.0), 10),  # overtaking the robot from behind
    ],
)
def test_a_car_driving_towards_or_with_the_robot_is_flagged_within_a_few_frames(start, velocity, within) -> None:
    """At 30 m the depth noise the model allows is 1.35 m a view: a second of views tells 8 m/s from standing."""
    objects = [("car", np.array(start), np.array(velocity))]
    table = flags(detector(), objects, 30, 10.0)
    assert first_flagged(table[:, 0]) <= within
    seen = table[:, 0][table[:, 0] >= 0]
    assert (seen[within:] == 1).all()  # and stays flagged: one track


def test_a_person_walking_across_is_flagged_below_the_vehicles_speed() -> None:
    """The default min_speed (2 m/s) is for vehicles; people have their own (label_min_speed), and a walker is
    found; not at 2 m/s."""
    objects = [("person", np.array([20.0, 6.0, 0.0]), np.array([0.0, -1.4, 0.0]))]
    assert first_flagged(flags(detector(), objects, 60, 2.0)[:, 0]) <= 15
    assert (flags(judge_with(label_min_speed={}), objects, 60, 2.0) == 1).sum() == 0
    car = [("car", *objects[0][1:])]
    assert (flags(judge(), car, 60, 2.0) == 1).sum() == 0


def odometry_errors(rng: np.random.Generator, frames: int, heading_noise: float, distance_noise: float):
    """Per frame, the odometry's heading error (a random walk from 0) and its position error's increment."""
    steps = rng.normal(0.0, heading_noise * np.sqrt(PERIOD), frames)
    steps[0] = 0.0
    return np.cumsum(steps), rng.normal(0.0, distance_noise * np.sqrt(PERIOD), (frames, 2))


def realised_noise(frames: int, heading_noise: float, distance_noise: float, seed: int, lag: int, last: int):
    """The random walks' rates as drawn for `drifting_flags` (the RMS of their `lag`-frame increments over the last
    `last` frames): a 30 s drive holds 30 independent 1 s increments, so they are within about 15 % of the rates
    asked for."""
    heading, shifts = odometry_errors(np.random.default_rng(seed), frames, heading_noise, distance_noise)
    position = np.cumsum(shifts, axis=0)
    turns = (heading[lag:] - heading[:-lag])[-last:]
    moves = (position[lag:] - position[:-lag])[-last:]
    return np.sqrt(np.mean(turns**2) / (lag * PERIOD)), np.sqrt(np.mean(moves**2) / (lag * PERIOD))


def drifting_flags(
    detector: MovingObjectDetector,
    objects,
    frames: int,
    speed: float,
    heading_noise: float,
    seed: int,
    distance_noise: float = 0.0,
):
    """Like `flags`, but the odometry integrates a heading that random-walks, `heading_noise` rad per square root
    of a second, and adds a position random walk, `distance_noise` m per square root of a second, into the pose the
    frames carry (the views are of the true pose): parked cars seem to turn about the robot and shift."""
    rng = np.random.default_rng(seed)
    heading, shifts = odometry_errors(rng, frames, heading_noise, distance_noise)
    path = np.cumsum(speed * PERIOD * np.column_stack([np.cos(heading), np.sin(heading)]) + shifts, axis=0)
    table = np.full((frames, len(objects)), -1)
    for i in range(frames):
        true_pose = robot_pose(speed * PERIOD * (i + 1))
        views = [measured(label, true_pose, start + velocity * i * PERIOD, rng) for label, start, velocity in objects]
        odometry = robot_pose(*path[i])
        odometry[:2, :2] = [[np.cos(heading[i]), -np.sin(heading[i])], [np.sin(heading[i]), np.cos(heading[i])]]
        kept_out = detector.update(frame(i, odometry, views))
        table[i, [j for j, v in enumerate(views) if v is not None]] = kept_out
    return table


def test_parked_cars_seen_with_drifting_odometry_are_not_moving_when_the_drift_is_allowed_for() -> None:
    """Heavy heading noise (0.03 rad per square root of a second, the simulated `heavy` profile's) turns a parked
    car 30 m off by a metre in a second: with the odometry's noise left out it seems to move, with it not."""
    rng = np.random.default_rng(5)
    objects = [
        ("car", np.array([x, side * rng.uniform(4.0, 15.0), 0.0]), np.zeros(3))
        for x in np.linspace(25.0, 80.0, 12)
        for side in (-1, 1)
    ]
    heavy = {"odometry_heading_noise": 0.032, "odometry_distance_noise": 0.32}
    moved_by_drift, allowed = 0, 0
    for seed in range(4):
        unaware = judge_with(min_speed=0.7, odometry_heading_noise=0.0, odometry_noise="stated")
        moved_by_drift += int((drifting_flags(unaware, objects, 40, 8.0, 0.032, seed) == 1).sum())
        aware = judge_with(min_speed=0.7, odometry_noise="stated", **heavy)
        allowed += int((drifting_flags(aware, objects, 40, 8.0, 0.032, seed) == 1).sum())
    assert moved_by_drift >= 20
    assert allowed == 0


def parked_and_driving(length: float, seed: int) -> tuple[list, int]:
    """Parked cars on both sides of a street `length` m long, then cars driving both ways in the lanes; and how many
    of them are parked (the first ones)."""
    rng = np.random.default_rng(seed)
    parked = [
        ("car", np.array([x, side * rng.uniform(4.0, 15.0), 0.0]), np.zeros(3))
        for x in np.arange(10.0, length, 12.0)
        for side in (-1, 1)
    ]
    oncoming = [
        ("car", np.array([x, -3.0, 0.0]), np.array([-10.0, 0.0, 0.0])) for x in np.arange(100.0, 2 * length, 30.0)
    ]
    ahead = [("car", np.array([x, 2.0, 0.0]), np.array([12.0, 0.0, 0.0])) for x in np.arange(-50.0, length, 30.0)]
    return [*parked, *oncoming, *ahead], len(parked)


@pytest.mark.slow
@pytest.mark.parametrize(("heading", "distance"), [(0.032, 0.32), (0.0, 0.3)])
def test_the_odometry_noise_is_estimated_from_the_street(heading, distance) -> None:
    """Heavy odometry noise not stated (the defaults are `vo`'s, ten and five times less): the tracks estimate it
    from how what they see drifts, through traffic (about a factor 1.3 off on such a short drive)."""
    objects, _ = parked_and_driving(400.0, seed=5)
    estimating = judge_with()
    drifting_flags(estimating, objects, 400, 8.0, heading, seed=1, distance_noise=distance)
    estimate = estimating.noise_estimate.noise()
    assert estimate is not None
    drawn = realised_noise(400, heading, distance, 1, MovingObjectsConfig().noise_lag, 300)
    assert estimate[0] == pytest.approx(drawn[0], abs=0.3 * 0.032)
    assert estimate[1] == pytest.approx(drawn[1], rel=0.5)
    assert estimating.odometry_noise() == (max(estimate[0], 0.0032), max(estimate[1], 0.063))


@pytest.mark.slow
def test_parked_cars_are_judged_by_the_estimated_noise() -> None:
    """Under heavy odometry noise not stated, the estimate takes half or more of the parked cars' views the stated
    (`vo`) noise takes for moving back in, and the traffic the stated noise finds is still found."""
    objects, parked = parked_and_driving(400.0, seed=5)
    estimated = stated = driving = driven = 0
    for seed in (1, 2):
        table = drifting_flags(judge_with(), objects, 400, 8.0, 0.032, seed, 0.32)
        as_stated = drifting_flags(judge_with(odometry_noise="stated"), objects, 400, 8.0, 0.032, seed, 0.32)
        estimated += int((table[:, :parked] == 1).sum())
        stated += int((as_stated[:, :parked] == 1).sum())
        driving += int((table[:, parked:] == 1).sum())
        driven += int((as_stated[:, parked:] == 1).sum())
    assert estimated <= 0.6 * stated
    assert driving >= 0.8 * driven  # most of what the stated noise finds (cars 100 m and more off are not judged)


@pytest.mark.slow
def test_odometry_as_good_as_stated_leaves_the_stated_noise() -> None:
    """Odometry with `vo`'s noise, through traffic: the estimate stays near or below the stated floor."""
    objects, _ = parked_and_driving(300.0, seed=6)
    estimating = judge_with()
    drifting_flags(estimating, objects, 300, 8.0, 0.0032, seed=2, distance_noise=0.063)
    estimate = estimating.noise_estimate.noise()
    assert estimate is not None and estimate[0] < 0.006 and estimate[1] < 0.12
    assert estimating.odometry_noise() == pytest.approx((max(estimate[0], 0.0032), max(estimate[1], 0.063)))


def test_stated_noise_is_taken_as_given() -> None:
    objects, _ = parked_and_driving(200.0, seed=6)
    stated = judge_with(odometry_noise="stated")
    drifting_flags(stated, objects, 150, 8.0, 0.032, seed=2, distance_noise=0.32)
    assert stated.noise_estimate.views == 0 and stated.odometry_noise() == (0.0032, 0.063)


def judge_with(**changes) -> MovingObjectDetector:
    """`judge()` with other settings."""
    return detector(hold_sigmas=MovingObjectsConfig().significance_sigmas, **changes)


def test_a_moving_car_among_parked_ones_leaves_them_static() -> None:
    parked = [("car", np.array([x, side * 4.0, 0.0]), np.zeros(3)) for x in (15, 25, 35) for side in (-1, 1)]
    mover = ("car", np.array([30.0, -2.0, 0.0]), np.array([-8.0, 0.0, 0.0]))
    table = flags(judge(), [*parked, mover], 25, 8.0)
    assert (table[:, :-1] == 1).sum() == 0
    assert first_flagged(table[:, -1]) <= 15  # views in two gates restart the fit: slower among parked cars


def test_unjudged_tracks_are_held_only_when_asked() -> None:
    objects = [("car", np.array([20.0, 4.0, 0.0]), np.zeros(3))]
    holding = detector(unjudged="out", hold_sigmas=MovingObjectsConfig().significance_sigmas)
    assert (flags(holding, objects, 5, 10.0)[:, 0] == [1, 1, 0, 0, 0]).all()
    assert (flags(judge(), objects, 5, 10.0)[:, 0] == 0).all()


def test_static_passes_observations_and_counts_flags() -> None:
    objects = [("car", np.array([45.0, -3.0, 0.0]), np.array([-8.0, 0.0, 0.0]))]
    on, off = detector(), detector(enabled=False)
    for f, _ in drive(objects, 20, 10.0):
        assert off.static(f) is f.observations
        on.static(f)
    assert on.flagged > 0 and off.flagged == 0


def test_moving_objects_are_reported_where_last_seen() -> None:
    objects = [("car", np.array([45.0, -3.0, 0.0]), np.array([-8.0, 0.0, 0.0]))]
    found = detector()
    frames = list(drive(objects, 20, 10.0))
    for f, _ in frames:
        found.update(f)
    poses = np.array([f.odometry_pose for f, _ in frames])
    (moving,) = found.objects(poses)
    last = max(i for i, (_, seen) in enumerate(frames) if seen[0])
    truth = objects[0][1] + objects[0][2] * last * PERIOD
    assert moving.label == "car" and moving.id == 0
    assert np.linalg.norm(moving.position[:2] - truth[:2]) < 1.5


def test_tracks_end_and_memory_stays_bounded() -> None:
    found = detector(max_tracks=8)
    rng = np.random.default_rng(3)
    for i in range(200):  # a new object every frame, each seen once (the robot stands)
        pose = robot_pose(20.0 * i - 20.0)
        found.update(frame(i, pose, [measured("car", pose, [20.0 * i, 5.0, 0.0], rng)]))
    assert found._live.sum() <= 8
    assert found.objects(np.tile(np.eye(4), (200, 1, 1))) == []


def test_same_input_same_flags() -> None:
    objects = [
        ("car", np.array([45.0, -3.0, 0.0]), np.array([-8.0, 0.0, 0.0])),
        ("car", np.array([30.0, 4.0, 0.0]), np.zeros(3)),
        ("person", np.array([20.0, 6.0, 0.0]), np.array([0.0, -1.4, 0.0])),
    ]
    assert np.array_equal(flags(detector(), objects, 40, 8.0, 7), flags(detector(), objects, 40, 8.0, 7))


@pytest.mark.parametrize(
    "changes",
    [{"gate_radius": 0}, {"significance_sigmas": -1}, {"min_speed": -0.5}, {"judge_after": 1}, {"max_tracks": 0},
     {"track_length": 1}, {"max_unseen": float("inf")}, {"unknown": 1}, {"unjudged": "hold"},
     {"odometry_heading_noise": -0.01}, {"odometry_distance_noise": float("nan")}, {"odometry_noise": "guess"},
     {"noise_lag": 20}, {"noise_lag": 5, "track_length": 5}, {"noise_bins": 1}, {"noise_window": 0},
     {"noise_max_speed": 0}, {"label_min_speed": {"person": -1.0}}],
)  # fmt: skip
def test_config_ranges_are_validated(changes: dict) -> None:
    with pytest.raises(ValidationError):
        MovingObjectsConfig(**changes)


def test_config_section_is_registered() -> None:
    config = NeoSLAMConfig.model_validate({"moving_objects": {"enabled": False, "min_speed": 1.0}})
    assert config.moving_objects.enabled is False and config.moving_objects.min_speed == 1.0


def test_views_let_through_are_taken_back_from_the_keyframe_window() -> None:
    """An oncoming car's first views join the keyframe window before it is found moving; then they leave it."""
    window = LocalObjectWindow(KeyframeConfig())
    found = detector()
    objects = [("car", np.array([30.0, -3.0, 0.0]), np.array([-8.0, 0.0, 0.0]))]
    for f, _ in drive(objects, 20, 10.0):
        window.add(f.odometry_pose, found.static(f, window), 10.0 * f.timestamp)
    assert found.retracted > 0
    assert window.objects == []


def test_a_parked_car_is_provisional_in_keyframes_until_its_track_is_found_static() -> None:
    """`unjudged: wait`: the window holds its first views at once; its object is provisional until the track is
    found static (judge_after views, speed plus static_sigmas stds below min_speed), then the earlier views settle."""
    window = LocalObjectWindow(KeyframeConfig(), marks_provisional=True)
    found = detector()
    objects = [("car", np.array([12.0, -4.0, 0.0]), np.zeros(3))]
    settled = []
    for f, _ in drive(objects, 8, 2.0):
        window.add(f.odometry_pose, found.static(f, window), 2.0 * f.timestamp)
        settled.append(window.objects[0].settled)
    assert settled[:2] == [0, 0] and settled[-1] == 7  # the latest view settles with the next frame's
    assert window.confirmed()[0].settled > 0


def test_a_car_coming_on_from_far_is_not_found_static() -> None:
    """Three views of a car 45 m ahead coming on at 8 m/s move mostly along the viewing ray, where stereo depth is
    least sure: too few to call it moving, and not enough to call it static either."""
    window = LocalObjectWindow(KeyframeConfig(), marks_provisional=True)
    found = judge()
    objects = [("car", np.array([45.0, -3.0, 0.0]), np.array([-8.0, 0.0, 0.0]))]
    for f, _ in list(drive(objects, 3, 10.0)):
        window.add(f.odometry_pose, found.static(f, window), 10.0 * f.timestamp)
    assert found.flagged == 0 and len(window.confirmed()) == 1 and window.confirmed()[0].settled == 0


def test_a_track_never_judged_settles_nothing() -> None:
    """Two views of a car (a track broken off before it was judged) and a third from a new track: the window object
    holds three views, none settled."""
    found = detector(max_unseen=0.5)
    window = LocalObjectWindow(KeyframeConfig(), marks_provisional=True)
    objects = [("car", np.array([30.0, -4.0, 0.0]), np.zeros(3))]
    frames = [f for f, _ in drive(objects, 8, 10.0)]
    for f in (frames[0], frames[1], frames[7]):  # 0.6 s apart: the track ends (max_unseen 0.5 s)
        window.add(f.odometry_pose, found.static(f, window), 10.0 * f.timestamp)
    assert len(window.confirmed()) == 1 and window.objects[0].settled == 0


def test_settled_views_taken_back_unsettle_their_object() -> None:
    window = LocalObjectWindow(KeyframeConfig(), marks_provisional=True)
    frames = [f for f, _ in drive([("car", np.array([30.0, -4.0, 0.0]), np.zeros(3))], 4, 10.0)]
    for f in frames:
        window.add(f.odometry_pose, f.observations, 10.0 * f.timestamp)
    views = tuple(o for f in frames for o in f.observations)
    window.settle(views[:2])
    window.settle(views[:2])  # settling twice counts once
    assert window.objects[0].settled == 2
    window.retract(views[:2])
    assert window.objects[0].settled == 0 and window.objects[0].observations == 2


def window_views(points, times, robots) -> WindowViews:
    """Views of one keyframe-window object with the window's stereo covariances (depth std grows with depth²)."""
    points, robots = np.asarray(points, float), np.asarray(robots, float)
    rays = points - robots
    depth = np.linalg.norm(rays, axis=1)
    sigma = KeyframeConfig().depth_sigma_at_1m * depth**2
    covariances = view_covariances(rays, sigma / depth, KeyframeConfig().bearing_sigma)
    return WindowViews(points, covariances, np.asarray(times, float), robots)


def test_a_window_object_of_a_passing_cars_first_views_moves() -> None:
    """Four views a tenth of a second apart of a car 12 m off crossing at 8 m/s."""
    times = np.arange(4) * PERIOD
    points = np.column_stack([12.0 + 0 * times, -4.0 + 8.0 * times])
    assert detector(window_scatter=3.0).window_views_move(window_views(points, times, np.zeros((4, 2))))
    assert not detector().window_views_move(window_views(points, times, np.zeros((4, 2))))  # off by default


@pytest.mark.parametrize("seed", range(5))
def test_a_parked_cars_window_object_does_not_move(seed: int) -> None:
    """Views of a car 30 m ahead scattered by the stereo noise they are given, the robot driving on."""
    rng = np.random.default_rng(seed)
    times = np.arange(6) * PERIOD
    robots = np.column_stack([10.0 * times, 0 * times])
    clean = window_views(np.tile([30.0, 3.0], (6, 1)), times, robots)
    noisy = np.array([rng.multivariate_normal(p, c) for p, c in zip(clean.points, clean.covariances, strict=True)])
    assert not detector(window_scatter=3.0).window_views_move(window_views(noisy, times, robots))


def test_views_spread_over_more_than_the_window_span_are_not_judged() -> None:
    times = np.array([0.0, 0.5, 1.0, 1.5])
    points = np.column_stack([12.0 + 0 * times, -4.0 + 1.0 * np.arange(4)])
    views = window_views(points, times, np.zeros((4, 2)))
    assert not detector(window_scatter=3.0).window_views_move(views)
    assert detector(window_scatter=3.0, window_span=2.0).window_views_move(views)
    assert not detector(window_span=2.0, window_scatter=0.0).window_views_move(views)


def test_the_odometrys_error_between_views_is_allowed_for() -> None:
    """A parked car 30 m off whose views the odometry's heading error turned about the robot by 0.03 rad over a
    second: moving for a detector told of `vo`'s noise, not for one told of `heavy`'s."""
    times = np.arange(11) * PERIOD
    heading = 0.03 * np.linspace(0.0, 1.0, 11)
    points = np.column_stack([30.0 * np.cos(heading), 30.0 * np.sin(heading)])
    views = window_views(points, times, np.zeros((11, 2)))
    stated = {"odometry_noise": "stated", "window_span": 2.0, "window_scatter": 3.0}
    assert detector(**stated).window_views_move(views)
    assert not detector(**stated, odometry_heading_noise=0.032).window_views_move(views)
