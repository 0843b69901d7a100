"""Detection profiles: `ideal` is the simulator's defaults byte for byte, `real` follows its tables; occlusion,
objects cut off by the image border, false positives, rows of objects, and the --detector option."""

from __future__ import annotations

import hashlib
from pathlib import Path

import numpy as np
import pytest
import yaml
from pydantic import ValidationError
from typer.testing import CliRunner

from neoslam.cli import app
from neoslam.config import CameraConfig, DetectionNoiseConfig, SimulatorConfig, WorldConfig, load_config
from neoslam.config.calibration import DEFAULT_DETECTION_PROFILE, DETECTION_PROFILES
from neoslam.datasets.simulated import write_dataset
from neoslam.sim.detections import FALSE_POSITIVE, DetectionSimulator
from neoslam.sim.routes import ROUTES, drive_route
from neoslam.sim.simulator import simulate
from neoslam.sim.world import CLASS_SIZES, World, build_world
from neoslam.types import Trajectory

CAMERA = CameraConfig()
# The `ideal` profile's dataset, held byte for byte (route block, first 200 frames, seed 3): its figures stay valid.
OLD_DIGESTS = {
    "detections.csv": "3adc5d9b2882d41d6756e8af3028164a70d2200320ff6766901aa845fa7f02bb",
    "patches.npy": "0380abb430e7d938c90569007a3d757f0e849cbefd202ac4d01e15d95cfa3555",
    "truth/objects.csv": "793491ed31e9a38c01e4ba95fb2fe0a82620fd525e345d675b6034fc1df61134",
    "truth/detections.csv": "3b4b5a3d9d937ba3024469334fa326e0ec55bddac3527a40753f058c75648d39",
}
QUIET = DetectionNoiseConfig(
    miss_rate=0.0, miss_rate_at_max_range=0.0, label_confusion=0.0, false_positives_per_frame=0.0
)
DRAWS = 2000


def _cars(*positions: tuple[float, float]) -> World:
    """Cars along the robot's x axis (robot frame: x forward, y left), centres at camera height."""
    n = len(positions)
    xy = np.array(positions, dtype=float).reshape(-1, 2)
    sizes = np.tile(CLASS_SIZES["car"], (n, 1))
    textures = np.full((n, 16, 16), 120.0)
    return World(
        np.array(["car"] * n), np.column_stack([xy, np.zeros(n)]), sizes, np.zeros(n), np.zeros((n, 3)), textures
    )


def _detected_share(world: World, noise: DetectionNoiseConfig, seed: int = 1) -> np.ndarray:
    """Per object, the share of DRAWS frames (robot at the origin) in which it was detected."""
    detector = DetectionSimulator(world, CAMERA, noise)
    rng = np.random.default_rng(seed)
    counts = np.zeros(len(world))
    for _ in range(DRAWS):
        for d in detector.detect(np.eye(4), 0.0, rng):
            if d.object_id != FALSE_POSITIVE:
                counts[d.object_id] += 1
    return counts / DRAWS


def test_profiles_exist_and_validate() -> None:
    assert {"real", "ideal"} <= set(DETECTION_PROFILES)
    assert DEFAULT_DETECTION_PROFILE == "real"
    default = SimulatorConfig()
    assert default.detection_profile == "real"
    assert default.detection == DETECTION_PROFILES["real"].detection
    assert default.world == DETECTION_PROFILES["real"].world
    ideal = SimulatorConfig(detection_profile="ideal")
    assert ideal.detection == DetectionNoiseConfig() and ideal.world == WorldConfig()
    real = DETECTION_PROFILES["real"].detection
    assert real.detection_probability and real.border_margin is not None and real.occlusion_cover is not None
    with pytest.raises(ValidationError, match="unknown detection profile"):
        SimulatorConfig(detection_profile="bogus")


def test_config_file_picks_a_profile_and_overrides_single_fields(tmp_path: Path) -> None:
    path = tmp_path / "sim.yaml"
    path.write_text(
        yaml.safe_dump({"simulator": {"detection_profile": "ideal", "detection": {"disparity_sigma": 0.7}}})
    )
    config = load_config(path, environ={}).simulator
    assert config.detection.disparity_sigma == 0.7
    assert config.detection.miss_rate == DetectionNoiseConfig().miss_rate  # the rest from the ideal profile
    assert config.world == WorldConfig()


@pytest.mark.parametrize(
    "bad",
    [
        {"detection_probability": ((20.0, 0.5), (10.0, 0.6))},  # depths must increase
        {"detection_probability": ((10.0, 1.5),)},  # a probability above 1
        {"false_positive_depth": (30.0, 10.0)},
        {"occlusion_cover": 0.0},
    ],
)
def test_bad_detection_values_are_refused(bad: dict) -> None:
    with pytest.raises(ValidationError):
        DetectionNoiseConfig(**bad)


def test_bad_rows_are_refused() -> None:
    with pytest.raises(ValidationError, match="objects per 100 m"):
        WorldConfig(rows=((3.0, 50.0, 0.5),))  # more than one object per 7 m slot
    with pytest.raises(ValidationError, match="non-zero offset"):
        WorldConfig(rows=((0.0, 5.0, 0.5),))


def test_ideal_reproduces_the_old_simulator_byte_for_byte(tmp_path: Path) -> None:
    config = SimulatorConfig(seed=3, detection_profile="ideal")
    truth = drive_route(ROUTES["block"], config.frame_period, config.camera.height_above_ground)
    write_dataset(tmp_path, simulate(truth.subset(np.arange(200)), config, "block200", "test"))
    for name, digest in OLD_DIGESTS.items():
        assert hashlib.sha256((tmp_path / name).read_bytes()).hexdigest() == digest, name


@pytest.mark.slow
def test_real_profile_follows_its_depth_table() -> None:
    real = DETECTION_PROFILES["real"].detection
    depths = (12.0, 22.0, 32.0)
    # On the axis, far apart sideways so that none hides another: one car per depth, in separate worlds.
    for depth in depths:
        share = _detected_share(_cars((depth, 0.0)), real)[0]
        keys, values = zip(*real.detection_probability, strict=True)
        expected = np.interp(depth, keys, values)
        if real.column_factor is not None:
            columns, factors = zip(*real.column_factor, strict=True)
            expected *= np.interp(0.0, columns, factors)
        assert share == pytest.approx(expected, abs=4 * np.sqrt(0.25 / DRAWS)), depth


def test_depth_table_and_column_factor_multiply() -> None:
    noise = QUIET.model_copy(
        update={"detection_probability": ((10.0, 0.9), (30.0, 0.3)), "column_factor": ((0.0, 1.0), (1.0, 0.0))}
    )
    # Robot frame: y left. A car 20 m ahead on the axis, and one 20 m ahead whose centre is half-way to the edge.
    half_way = 0.5 * CAMERA.cx / CAMERA.fx * 20.0
    shares = _detected_share(_cars((20.0, 0.0), (20.0, half_way + 30.0)), noise)  # second: far out of view
    assert shares[0] == pytest.approx(0.6, abs=0.05)
    assert shares[1] == 0.0
    shares = _detected_share(_cars((20.0, half_way)), noise)
    assert shares[0] == pytest.approx(0.6 * 0.5, abs=0.05)


def test_a_car_behind_a_nearer_one_is_hidden() -> None:
    world = _cars((10.0, 0.0), (20.0, 0.0), (20.0, -6.0))  # the third stands clear to the right
    seen = DetectionSimulator(world, CAMERA, QUIET.model_copy(update={"occlusion_cover": 0.5}))
    visible = {v.index for v in seen.in_view(np.eye(4), 0.0)}
    assert visible == {0, 2}
    everything = DetectionSimulator(world, CAMERA, QUIET)
    assert {v.index for v in everything.in_view(np.eye(4), 0.0)} == {0, 1, 2}


def test_a_car_cut_by_the_image_border_is_not_placed() -> None:
    world = _cars((6.0, -4.0), (25.0, -4.0))  # a near car at the right border, the same car further ahead
    cut = DetectionSimulator(world, CAMERA, QUIET.model_copy(update={"border_margin": 3.0}))
    assert {v.index for v in cut.in_view(np.eye(4), 0.0)} == {1}
    clipped = DetectionSimulator(world, CAMERA, QUIET)
    assert {v.index for v in clipped.in_view(np.eye(4), 0.0)} == {0, 1}


def test_false_positives_rate_and_depth_range() -> None:
    noise = QUIET.model_copy(update={"false_positives_per_frame": 1.5, "false_positive_depth": (12.0, 18.0)})
    detector = DetectionSimulator(_cars(), CAMERA, noise)
    rng = np.random.default_rng(4)
    frames = [detector.detect(np.eye(4), 0.0, rng) for _ in range(DRAWS)]
    assert np.mean([len(f) for f in frames]) == pytest.approx(1.5, abs=0.1)
    depths = np.array([d.center_camera[2] for f in frames for d in f])
    assert all(d.object_id == FALSE_POSITIVE for f in frames for d in f)
    assert depths.min() >= 12.0 - 1e-9 and depths.max() <= 18.0 + 1e-9


def test_rows_place_objects_at_their_offsets_and_densities() -> None:
    length = 2000.0
    x = np.arange(0.0, length, 1.0)
    poses = np.tile(np.eye(4), (len(x), 1, 1))
    poses[:, 0, 3] = x
    truth = Trajectory(x / 10.0, poses)
    config = WorldConfig(rows=((-3.0, 8.0, 0.1), (15.0, 4.0, 0.1)), class_mix={"car": 1.0}, road_clearance=2.0)
    world = build_world(truth, config, DetectionNoiseConfig(), 1.65, np.random.default_rng(2))
    lateral = world.positions[:, 1]
    right, left = lateral[lateral < 0], lateral[lateral > 0]
    assert np.median(right) == pytest.approx(-3.0, abs=0.1) and np.median(left) == pytest.approx(15.0, abs=0.1)
    assert len(right) == pytest.approx(8.0 * length / 100, rel=0.2)
    assert len(left) == pytest.approx(4.0 * length / 100, rel=0.2)


def test_cli_detector_option(tmp_path: Path) -> None:
    runner = CliRunner()
    straight = "".join(f"{i / 10:.1f} {i:.1f} 0 0 0 0 0 1\n" for i in range(150))  # TUM: 150 m straight ahead
    (tmp_path / "straight.txt").write_text(straight)
    for name in ("ideal", "real"):
        out = tmp_path / name
        args = ["simulate", "--trajectory", str(tmp_path / "straight.txt"), "--detector", name, "--seed", "1"]
        args += ["--out", str(out), "-q"]
        result = runner.invoke(app, args)
        assert result.exit_code == 0, result.output
        meta = yaml.safe_load((out / "dataset.yaml").read_text())["simulator"]
        assert meta["detection_profile"] == name
        assert meta["detection"]["border_margin"] == DETECTION_PROFILES[name].detection.border_margin
    real = (tmp_path / "real" / "detections.csv").read_text().count("\n")
    ideal = (tmp_path / "ideal" / "detections.csv").read_text().count("\n")
    assert real < ideal  # the real front end places far fewer objects
